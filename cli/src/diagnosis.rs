//! `volcal diagnose`: reads a campaign (CSV or bag), runs
//! [`volcal_formats::diagnosing::diagnose_campaign`] on it (what the replay node runs too) and
//! writes the report as JSON ([`volcal_formats::diagnosis_file`], `volcal-diagnosis v1`).

use anyhow::Result;
use std::path::Path;
use volcal_bag::campaign::{load_campaign_noted, provenance};
use volcal_formats::machine::Machine;

pub use volcal_formats::diagnosing::Diagnosed;
pub use volcal_formats::diagnosis_file::{
    text_report, CandidateEntry, DiagnosisFile, EffectEntry, LocationEntry, FORMAT,
};

/// `volcal diagnose`: diagnoses a campaign (also written to `json` if given).
pub fn diagnose_cmd(campaign_path: &Path, machine_path: &Path, json: Option<&Path>) -> Result<Diagnosed> {
    let machine = Machine::load(machine_path)?;
    // A bag may be damaged or incomplete: the diagnosis runs on what was read and says what
    // was missing.
    let (campaign, input) = load_campaign_noted(campaign_path)?;
    let source = campaign_path.display().to_string();
    let d = volcal_formats::diagnosing::diagnose_campaign(
        &campaign,
        &machine,
        &source,
        provenance(campaign_path, machine_path)?,
    )?
    .with_input_notes(input);
    if let Some(p) = json {
        d.file.write(p)?;
    }
    Ok(d)
}
