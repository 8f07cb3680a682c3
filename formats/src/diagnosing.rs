//! A loaded campaign diagnosed for a machine file: what `volcal diagnose` and the replay node
//! (`volcal_solver` with `diagnose: true`) both run, so that they give the same diagnosis of
//! the same readings. Reading the campaign (CSV or bag) is the caller's: bags are above this
//! crate.

use crate::diagnosis_file::{text_report, DiagnosisFile};
use crate::machine::Machine;
use crate::model_file::{ModelFile, Provenance};
use crate::solving::prepare_campaign;
use anyhow::Result;
use volcal::campaign::{Campaign, Observations};
use volcal::diagnose::{diagnose, geometry::Optics, DiagnoseOptions, Diagnosis};

/// A diagnosed campaign: the file written by `--json`, the printed report, and what the
/// Rerun view and the refit model need.
pub struct Diagnosed {
    pub file: DiagnosisFile,
    pub report: String,
    pub diagnosis: Diagnosis,
    pub obs: Observations,
}

impl Diagnosed {
    /// Adds what reading the input found missing or damaged (`volcal_bag::campaign::
    /// load_campaign_noted`) to the file and at the head of the report.
    pub fn with_input_notes(mut self, notes: Vec<String>) -> Diagnosed {
        if !notes.is_empty() {
            let head: String = notes.iter().map(|n| format!("Input: {n}\n")).collect();
            self.report = head + "\n" + &self.report;
            self.file.input = notes;
        }
        self
    }

    /// The refit model (the rigid-body model fitted together with the named effects) as a
    /// model file; with nothing named it is the plain fit. Its warnings name the effects that
    /// were modelled, since the model file has no place for their parameters.
    pub fn refit_model(&self, provenance: Provenance) -> ModelFile {
        let mut f = ModelFile::from_solution(&self.diagnosis.after, &self.obs.groups, provenance);
        if !self.file.effects.is_empty() {
            let ids: Vec<&str> = self.file.effects.iter().map(|e| e.id.as_str()).collect();
            f.warnings.push(format!(
                "refit by the diagnosis with these effects modelled beside the rigid-body model: {} (their parameters are in the diagnosis)",
                ids.join(", ")
            ));
        }
        f
    }
}

/// Prepares and diagnoses `campaign` for `machine`. `source` names the input in warnings and
/// errors (a solve that cannot run is an error naming it, never a panic).
pub fn diagnose_campaign(
    campaign: &Campaign,
    machine: &Machine,
    source: &str,
    provenance: Provenance,
) -> Result<Diagnosed> {
    let prepared = prepare_campaign(campaign, machine, source)?;
    // With `representation: auto` the knots and the smoothing are chosen once, on the plain
    // fit, and held for every fit of the diagnosis: its candidates, folds and refits then differ
    // only by what they add, and an effect cannot be absorbed into a re-estimated smoothness.
    let setup = machine.setup_for(&prepared.obs).map_err(|e| anyhow::anyhow!("{source}: {e}"))?;
    let opts = DiagnoseOptions::new(
        setup.options,
        Optics { wavelength_vac_m: campaign.meta.wavelength_vac_m, air_equation: campaign.meta.air_equation },
    );
    let d = diagnose(&setup.layout, &prepared.obs, &opts).map_err(|e| anyhow::anyhow!("{source}: {e}"))?;
    let n = prepared.obs.len();
    let file = DiagnosisFile::new(&d, &prepared.obs, provenance);
    Ok(Diagnosed { file, report: text_report(&d, source, n), diagnosis: d, obs: prepared.obs })
}
