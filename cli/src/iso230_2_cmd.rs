//! `volcal iso230-2`: a bidirectional positioning test (one row per approach) evaluated to
//! ISO 230-2:2014; prints the per-target table and the figures, optionally writes them as JSON
//! and draws the deviations as a PNG. The evaluation is `volcal_formats::iso230_2`'s.

use anyhow::Result;
use std::path::Path;
use volcal_formats::iso230_2::{self, csv, report};

/// Reads and evaluates `runs`, writes the JSON and the plot if asked; returns the printed report
/// and the lines saying what was written (for stderr).
pub fn iso230_2_cmd(runs: &Path, json: Option<&Path>, plot: Option<&Path>) -> Result<(String, Vec<String>)> {
    let read = csv::read(runs)?;
    let evaluation = iso230_2::evaluate(&read)?;
    let mut wrote = Vec::new();
    if let Some(j) = json {
        report::write_json(j, &evaluation)?;
        wrote.push(format!("wrote the figures to {}", j.display()));
    }
    if let Some(p) = plot {
        crate::iso230_2_plot::plot(&evaluation, &read, p)?;
        wrote.push(format!("wrote the plot to {}", p.display()));
    }
    Ok((report::text(&evaluation), wrote))
}
