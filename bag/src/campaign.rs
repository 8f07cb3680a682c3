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

/// Reads the synchronised pairs of a bag as a campaign; a recovery note goes to stderr.
pub fn read(path: &Path) -> Result<Campaign> {
    let b = read_bag(path)?;
    if let Some(n) = &b.recovery_note {
        eprintln!("note: {n}");
    }
    Ok(b.campaign)
}

/// Reads a campaign from CSV, or from a bag (a directory with `metadata.yaml`, or an `.mcap`
/// file) recorded by the node set.
pub fn load_campaign(path: &Path) -> Result<Campaign> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if ext == "mcap" || path.is_dir() {
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
