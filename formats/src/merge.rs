//! `volcal merge`: several campaigns of the same machine in one file, for a joint solve of
//! fixed-beam and tracer readings (or of several sessions of one method).
//!
//! The estimator keys every line by (kind, station, line), so beams of deflector position 0 and
//! ranges of tracer station 0 never mix. Within one kind, station ids that an earlier file
//! already uses are shifted past the largest id used so far; times are shifted so that each
//! campaign starts after the previous one ends. Campaigns must share their metadata
//! (wavelength, compensation, air equation): readings are merged as recorded.

use anyhow::{bail, Result};
use std::collections::BTreeSet;
use volcal::campaign::{Campaign, CampaignMeta, Compensation, ObsKind};

/// Merges campaigns `(name, campaign)` in order. Returns the merged campaign and notes on what
/// was renumbered.
pub fn merge(campaigns: Vec<(String, Campaign)>) -> Result<(Campaign, Vec<String>)> {
    let mut it = campaigns.into_iter();
    let Some((first_name, mut out)) = it.next() else { bail!("nothing to merge: give at least one campaign") };
    let mut notes = Vec::new();
    let mut used: [BTreeSet<u32>; 2] = Default::default();
    let slot = |k: ObsKind| usize::from(k == ObsKind::Range);
    for r in &out.readings {
        used[slot(r.kind)].insert(r.station);
    }
    let mut t_end = out.readings.iter().map(|r| r.t_s).fold(0.0, f64::max);
    for (name, c) in it {
        if c.meta != out.meta {
            bail!(
                "{name}: its metadata ({}) differs from {first_name}'s ({}); convert the readings to the same wavelength and compensation first",
                meta_text(&c.meta),
                meta_text(&out.meta)
            );
        }
        // New id = old id - smallest id of the file + first free id, per kind, on collision.
        let mut shift = [(0u32, 0u32); 2];
        for kind in [ObsKind::Beam, ObsKind::Range] {
            let mine: BTreeSet<u32> = c.readings.iter().filter(|r| r.kind == kind).map(|r| r.station).collect();
            if mine.iter().any(|s| used[slot(kind)].contains(s)) {
                let low = *mine.iter().next().unwrap();
                let high = *mine.iter().next_back().unwrap();
                // The renumbered ids must fit: ids near 2^32 would wrap onto stations in use.
                let free = used[slot(kind)].iter().next_back().map_or(Some(0), |m| m.checked_add(1));
                let Some(free) = free.filter(|f| (high - low).checked_add(*f).is_some()) else {
                    bail!(
                        "{name}: its {} stations {low}..={high} cannot be renumbered after those in use (up to {}): the ids would pass 4294967295; number the stations from 0",
                        kind.name(),
                        used[slot(kind)].iter().next_back().unwrap()
                    );
                };
                shift[slot(kind)] = (low, free);
                notes.push(format!(
                    "{name}: {} stations {}..={} renumbered to start at {free}",
                    kind.name(),
                    low,
                    mine.iter().next_back().unwrap()
                ));
            }
        }
        let t0 = c.readings.iter().map(|r| r.t_s).fold(f64::MAX, f64::min);
        let dt = if t0 <= t_end { t_end + 1.0 - t0 } else { 0.0 };
        for mut r in c.readings {
            let (low, free) = shift[slot(r.kind)];
            r.station = r.station - low + free;
            r.t_s += dt;
            used[slot(r.kind)].insert(r.station);
            t_end = t_end.max(r.t_s);
            out.readings.push(r);
        }
        if dt > 0.0 {
            notes.push(format!("{name}: times shifted by {dt:.1} s to follow the previous campaign"));
        }
    }
    Ok((out, notes))
}

/// A campaign's metadata as a sentence's part: wavelength, compensation, air equation.
fn meta_text(m: &CampaignMeta) -> String {
    let compensation = match m.compensation {
        Compensation::Compensated => "compensated lengths".to_string(),
        Compensation::Uncompensated { assumed_index } => format!("uncompensated, assumed index {assumed_index}"),
    };
    format!("vacuum wavelength {} nm, {compensation}, air equation {:?}", m.wavelength_vac_m * 1e9, m.air_equation)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};
    use volcal::campaign::Reading;

    fn reading(kind: ObsKind, station: u32, t: f64) -> Reading {
        Reading {
            kind,
            station,
            line: 0,
            t_s: t,
            l_m: 0.0,
            x: Point3::origin(),
            p: Vector3::zeros(),
            air: None,
            machine_temp_c: None,
            velocity: None,
            beam_broken: false,
            source_line: 0,
        }
    }

    #[test]
    fn keeps_kinds_apart_and_renumbers_collisions() {
        let a = Campaign {
            readings: vec![reading(ObsKind::Beam, 0, 0.0), reading(ObsKind::Beam, 1, 5.0)],
            ..Default::default()
        };
        let b = Campaign {
            readings: vec![reading(ObsKind::Range, 0, 0.0), reading(ObsKind::Range, 1, 2.0)],
            ..Default::default()
        };
        let c = Campaign { readings: vec![reading(ObsKind::Beam, 1, 0.0)], ..Default::default() };
        let (m, notes) = merge(vec![("a".into(), a), ("b".into(), b), ("c".into(), c)]).unwrap();
        let ids: Vec<(ObsKind, u32)> = m.readings.iter().map(|r| (r.kind, r.station)).collect();
        assert_eq!(
            ids,
            [(ObsKind::Beam, 0), (ObsKind::Beam, 1), (ObsKind::Range, 0), (ObsKind::Range, 1), (ObsKind::Beam, 2)]
        );
        assert!(m.readings.windows(2).all(|w| w[1].t_s > w[0].t_s));
        assert!(notes.iter().any(|n| n.contains("c: beam stations 1..=1 renumbered to start at 2")), "{notes:?}");
        let mut d = Campaign::default();
        d.meta.wavelength_vac_m = 633e-9;
        let e = merge(vec![("a".into(), Campaign::default()), ("d".into(), d)]).unwrap_err().to_string();
        assert!(e.contains("vacuum wavelength 633 nm") && !e.contains("CampaignMeta"), "{e}");
    }

    /// Station ids near 2^32 cannot be renumbered past those in use: an error, not ids that
    /// wrap onto stations already in the file (they merged two campaigns' lines into one).
    #[test]
    fn ids_that_would_wrap_are_refused() {
        let a = Campaign {
            readings: vec![reading(ObsKind::Beam, 0, 0.0), reading(ObsKind::Beam, u32::MAX, 1.0)],
            ..Default::default()
        };
        let b = Campaign { readings: vec![reading(ObsKind::Beam, 0, 0.0)], ..Default::default() };
        let e = merge(vec![("a".into(), a), ("b".into(), b)]).unwrap_err().to_string();
        assert!(e.contains("b: its beam stations 0..=0 cannot be renumbered"), "{e}");
    }
}
