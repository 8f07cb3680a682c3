//! The node-set subcommands of `volcal`: `launch` and `bag info`.

use crate::bag::Bag;
use crate::launch::{self, LaunchDescription, LaunchOptions};
use anyhow::{anyhow, Result};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::ExitCode;

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
