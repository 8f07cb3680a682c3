//! The node-set subcommands of `volcal`: `launch` and `bag info`.

use anyhow::{anyhow, Result};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::ExitCode;
use volcal_bag::Bag;
use volcal_nodes::launch::{self, LaunchDescription, LaunchOptions};

/// `volcal launch FILE [--bag PATH] [--domain N] [name:=value ...]`.
pub fn launch_cmd(file: &Path, bag: Option<&Path>, domain: Option<u16>, args: &[String]) -> Result<ExitCode> {
    let mut overrides = BTreeMap::new();
    for a in args {
        let (k, v) =
            a.split_once(":=").ok_or_else(|| anyhow!("launch argument {a:?} is not of the form name:=value"))?;
        overrides.insert(k.to_string(), v.to_string());
    }
    if let Some(b) = bag {
        overrides.insert("bag".to_string(), b.display().to_string());
    }
    if let Some(d) = domain {
        if d > 232 {
            return Err(anyhow!("--domain {d}: ROS domain ids go from 0 to 232"));
        }
    }
    let d = LaunchDescription::load(file, &overrides)?;
    let outcome = launch::run(&d, &LaunchOptions { domain, ..LaunchOptions::default() })?;
    if outcome.failed.is_empty() {
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!("error: node(s) failed: {}", outcome.failed.join(", "));
        Ok(ExitCode::FAILURE)
    }
}

/// `volcal bag info BAG`.
pub fn bag_info(path: &Path) -> Result<String> {
    let bag = Bag::open(path)?;
    let s = bag.count()?;
    let mut out = format!("bag {}: {} messages", path.display(), s.messages);
    if let (Some(a), Some(b)) = (s.first_ns, s.last_ns) {
        out.push_str(&format!(" over {:.3} s", (b - a) as f64 * 1e-9));
    }
    out.push('\n');
    let width = s.per_topic.keys().map(|t| t.len()).max().unwrap_or(0);
    for (t, c) in &s.per_topic {
        out.push_str(&format!("  {t:<width$}  {:>9}  {}\n", c.count, c.type_name));
    }
    if let Some(n) = s.recovery_note(path) {
        out.push_str(&format!("note: {n}\n"));
    }
    if let Some(m) = s.metadata_count {
        out.push_str(&format!("note: metadata.yaml counts {m} messages (written at the last flush)\n"));
    }
    Ok(out)
}

/// Whether a path is a bag (a directory with `metadata.yaml` or `.mcap` files, or an `.mcap`
/// file) rather than a campaign CSV or a model JSON.
pub fn is_bag(path: &Path) -> bool {
    let mcap = |p: &Path| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("mcap"));
    if path.is_dir() {
        path.join(volcal_bag::metadata::FILE_NAME).exists()
            || std::fs::read_dir(path).is_ok_and(|d| d.filter_map(|e| e.ok()).any(|e| mcap(&e.path())))
    } else {
        mcap(path)
    }
}

/// `volcal report BAG`: what was recorded and how the pairs were formed; and the model's report
/// when the solver node left `model.json` in the bag directory.
pub fn bag_report(path: &Path, compensation_dir: Option<&Path>, points: usize) -> Result<String> {
    use volcal_msgs::msg::SyncedPair;
    let mut out = bag_info(path)?;
    let bag = Bag::open(path)?;
    let (mut n, mut beam, mut range, mut trig, mut interp, mut broken, mut air, mut temp) = (0, 0, 0, 0, 0, 0, 0, 0);
    let (mut gap_t, mut gap_i) = (0.0f64, 0.0f64);
    let mut lines = std::collections::BTreeSet::new();
    let mut offsets = std::collections::BTreeSet::new();
    let mut t = (f64::INFINITY, f64::NEG_INFINITY);
    bag.read(|m| {
        if m.type_name != <SyncedPair as volcal_msgs::RosMessage>::TYPE_NAME {
            return Ok(());
        }
        let p: SyncedPair = m.decode()?;
        n += 1;
        if p.kind == SyncedPair::KIND_BEAM {
            beam += 1
        } else {
            range += 1
        }
        if p.pairing == SyncedPair::PAIRING_TRIGGER {
            trig += 1;
            gap_t = gap_t.max(p.pairing_gap_s);
        } else {
            interp += 1;
            gap_i = gap_i.max(p.pairing_gap_s);
        }
        broken += p.beam_broken as usize;
        air += p.air_valid as usize;
        temp += p.machine_temp_valid as usize;
        lines.insert((p.kind, p.station, p.line));
        offsets.insert(p.probe_offset_m.map(|v| (v * 1e9).round() as i64));
        t = (t.0.min(p.t_s), t.1.max(p.t_s));
        Ok(())
    })?;
    if n == 0 {
        out.push_str("\nno synchronised pairs in this bag\n");
        return Ok(out);
    }
    let stations: std::collections::BTreeSet<u32> = lines.iter().map(|l| l.1).collect();
    out.push_str(&format!(
        "\ncampaign: {n} synchronised pairs ({beam} beam, {range} range) on {} lines from {} stations, {} probe offsets, over {:.1} s\n",
        lines.len(),
        stations.len(),
        offsets.len(),
        t.1 - t.0
    ));
    out.push_str(&format!(
        "  paired by trigger: {trig} (largest reading-to-coordinates gap {:.3} ms); by interpolation: {interp} (largest bracketing interval {:.3} ms)\n",
        gap_t * 1e3,
        gap_i * 1e3
    ));
    out.push_str(&format!("  beam breaks: {broken}; air recorded with {air} pairs, machine temperature with {temp}\n"));
    let model = if path.is_dir() { path.join("model.json") } else { path.with_extension("model.json") };
    if model.exists() {
        out.push_str(&format!("\nmodel {} (written by the solver node):\n", model.display()));
        out.push_str(&crate::commands::report_cmd(&model, compensation_dir, points)?);
    }
    Ok(out)
}
