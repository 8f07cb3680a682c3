//! Reading a campaign from a bag recorded by the node set: the synchronised pairs
//! (`volcal_msgs/msg/SyncedPair`, topic `/campaign/pairs`) in acquisition order, with the
//! interferometer's air compensation from `/interferometer/info`. Raw topics are not needed; the
//! simulation truth topics, if a bag has them, are never read.
//!
//! Also what every reader of a campaign needs whatever its file: [`load_campaign`] (CSV or
//! bag) and the [`provenance`] of a solve (the input's SHA-256 covers a bag's MCAP files).

use crate::convert;
use crate::reader::{Bag, ReadSummary};
use anyhow::{anyhow, bail, Result};
use sha2::{Digest, Sha256};
use std::path::Path;
use volcal::campaign::{Campaign, CampaignMeta};
use volcal_formats::campaign_csv;
use volcal_formats::model_file::{self, sha256_file, Provenance};
use volcal_msgs::msg::{InterferometerInfo, SyncedPair};
use volcal_msgs::{topics, RosMessage};

/// A campaign read from a bag, with what the reader found.
pub struct BagCampaign {
    pub campaign: Campaign,
    pub summary: ReadSummary,
    /// Set when the bag was not closed: what was recovered.
    pub recovery_note: Option<String>,
}

/// Reads the pairs of a bag (directory or `.mcap` file).
pub fn read_bag(path: &Path) -> Result<BagCampaign> {
    let bag = Bag::open(path)?;
    let mut pairs: Vec<(i64, SyncedPair, usize)> = Vec::new();
    let mut info: Option<InterferometerInfo> = None;
    let pair_type = SyncedPair::TYPE_NAME;
    let info_type = InterferometerInfo::TYPE_NAME;
    let summary = bag.read(|m| {
        if m.topic.starts_with(topics::TRUTH_PREFIX) {
            return Ok(());
        }
        if m.type_name == pair_type {
            let p: SyncedPair = m.decode()?;
            pairs.push((p.header.stamp.to_nanos(), p, m.index as usize + 1));
        } else if m.type_name == info_type {
            info = Some(m.decode()?);
        }
        Ok(())
    })?;
    let note = summary.recovery_note(path);
    if pairs.is_empty() {
        let topics: Vec<String> =
            summary.per_topic.iter().map(|(t, c)| format!("{t} ({}, {} messages)", c.type_name, c.count)).collect();
        bail!(
            "{}: no {} messages ({pair_type}) among {} messages{}{}; was the recorder pairing (is the sequencer running)?",
            path.display(),
            topics::PAIRS,
            summary.messages,
            if topics.is_empty() { String::new() } else { format!(" on {}", topics.join(", ")) },
            note.as_ref().map(|n| format!(" ({n})")).unwrap_or_default()
        );
    }
    // Acquisition order: the recorder writes pairs as they complete, which out-of-order
    // delivery can permute.
    pairs.sort_by_key(|(stamp, p, _)| (*stamp, p.trigger_id));
    let readings = pairs
        .iter()
        .map(|(_, p, idx)| {
            convert::pair_to_reading(p, *idx)
                .map_err(|e| anyhow::anyhow!("{}: message #{} on {}: {e}", path.display(), idx - 1, topics::PAIRS))
        })
        .collect::<Result<Vec<_>>>()?;
    let meta = match &info {
        Some(i) => convert::meta_from_info(i).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?,
        None => CampaignMeta::default(),
    };
    Ok(BagCampaign { campaign: Campaign { meta, readings }, summary, recovery_note: note })
}

impl BagCampaign {
    /// What the read found missing or damaged, in sentences for a report: the recovery note of
    /// a bag that was not closed, and messages that `metadata.yaml` counts but the file does
    /// not hold. Empty for a complete bag.
    pub fn damage_notes(&self, path: &Path) -> Vec<String> {
        let mut notes: Vec<String> = self.recovery_note.iter().cloned().collect();
        if let (None, Some(listed)) = (&self.recovery_note, self.summary.metadata_count) {
            notes.push(format!(
                "{}: metadata.yaml lists {listed} messages, the file holds {}",
                path.display(),
                self.summary.messages
            ));
        }
        notes
    }
}

/// Reads the synchronised pairs of a bag as a campaign; a recovery note goes to stderr.
pub fn read(path: &Path) -> Result<Campaign> {
    let b = read_bag(path)?;
    if let Some(n) = &b.recovery_note {
        eprintln!("note: {n}");
    }
    Ok(b.campaign)
}

/// Reads a campaign (CSV or bag) with what the read found missing or damaged, in sentences:
/// a bag's [`BagCampaign::damage_notes`], and readings without environment records (they
/// cannot be compensated for the air or the machine temperature, whose effects then show up as
/// `air_refraction` or `material_expansion`).
pub fn load_campaign_noted(path: &Path) -> Result<(Campaign, Vec<String>)> {
    let (campaign, mut notes) = if is_bag(path) {
        let b = read_bag(path)?;
        let notes = b.damage_notes(path);
        (b.campaign, notes)
    } else {
        (load_campaign(path)?, Vec::new())
    };
    let n = campaign.readings.len();
    let air = campaign.readings.iter().filter(|r| r.air.is_some()).count();
    let temp = campaign.readings.iter().filter(|r| r.machine_temp_c.is_some()).count();
    match (air, temp) {
        (0, 0) => notes.push(
            "no environment records with the readings (no air, no machine temperatures): they are taken as the interferometer reported them".into(),
        ),
        (a, _) if a < n => notes.push(format!("{} of {n} readings have no air record", n - a)),
        _ => {}
    }
    Ok((campaign, notes))
}

/// Whether `path` names a bag (a directory, or an `.mcap` file) rather than a campaign CSV.
pub fn is_bag(path: &Path) -> bool {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    ext == "mcap" || path.is_dir()
}

/// Reads a campaign from CSV, or from a bag (a directory with `metadata.yaml`, or an `.mcap`
/// file) recorded by the node set.
pub fn load_campaign(path: &Path) -> Result<Campaign> {
    if is_bag(path) {
        return read(path);
    }
    let r = campaign_csv::read(path)?;
    if !r.ignored_columns.is_empty() {
        eprintln!("note: {}: ignored unknown column(s) {}", path.display(), r.ignored_columns.join(", "));
    }
    Ok(r.campaign)
}

/// Provenance of a solve.
pub fn provenance(campaign: &Path, machine: &Path) -> Result<Provenance> {
    Ok(Provenance {
        input: campaign.display().to_string(),
        input_sha256: input_sha256(campaign)?,
        machine: machine.display().to_string(),
        machine_sha256: model_file::sha256_file(machine)?,
        software: volcal_formats::software_version(),
    })
}

/// SHA-256 of a campaign input: a file, or the MCAP files of a bag directory in order.
pub fn input_sha256(path: &Path) -> Result<String> {
    if path.is_dir() {
        let bag = Bag::open(path)?;
        let mut h = Sha256::new();
        for f in &bag.files {
            h.update(std::fs::read(f).map_err(|e| anyhow!("cannot read {}: {e}", f.display()))?);
        }
        Ok(format!("{:x}", h.finalize()))
    } else {
        sha256_file(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Readings without environment records are named, whatever the input's format.
    #[test]
    fn readings_without_air_are_noted() {
        let dir = std::env::temp_dir().join(format!("volcal-bag-noted-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let head = "# volcal campaign v1\n# wavelength_vac_m: 0.00000063299121258\n# readings: compensated\n";
        let rows = |air: &dyn Fn(usize) -> String| -> String {
            (0..4).map(|k| format!("beam,0,0,{k},{}e-3,{}e-2,0.2,-0.3,0,0,-0.1{}\n", k, k, air(k))).collect()
        };
        let none = dir.join("none.csv");
        std::fs::write(
            &none,
            format!("{head}kind,station,beam,t_s,l_m,x_m,y_m,z_m,px_m,py_m,pz_m\n{}", rows(&|_| String::new())),
        )
        .unwrap();
        let (c, notes) = load_campaign_noted(&none).unwrap();
        assert_eq!(c.readings.len(), 4);
        assert!(notes.len() == 1 && notes[0].starts_with("no environment records"), "{notes:?}");
        let some = dir.join("some.csv");
        let air = |k: usize| if k < 3 { ",20,101325,50".to_string() } else { ",,,".to_string() };
        std::fs::write(
            &some,
            format!(
                "{head}kind,station,beam,t_s,l_m,x_m,y_m,z_m,px_m,py_m,pz_m,air_temp_c,air_pressure_pa,air_rh_pct\n{}",
                rows(&air)
            ),
        )
        .unwrap();
        let (_, notes) = load_campaign_noted(&some).unwrap();
        assert_eq!(notes, vec!["1 of 4 readings have no air record".to_string()]);
        std::fs::remove_dir_all(&dir).ok();
    }
}
