//! Simulation truth (JSON): the true error model, stations, beams and injected effects. Written
//! by `volcal simulate --truth`; read only by tests, benchmarks and the demo's comparison,
//! never by the solver.

use crate::model_file::{ModelFile, Provenance};
use anyhow::{Context, Result};
use faer::Mat;
use serde::{Deserialize, Serialize};
use std::path::Path;
use volcal_sim::simulate::{InjectedTruth, TruthBeam};
use volcal_sim::Truth;

pub const FORMAT: &str = "volcal-truth/1";

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TruthFile {
    pub format: String,
    pub seed: u64,
    pub model: ModelFile,
    pub stations: Vec<(u32, [f64; 3])>,
    pub beams: Vec<TruthBeam>,
    pub tracer_dead_path_m: f64,
    pub injected: Vec<InjectedTruth>,
    /// For a campaign recorded by the sim node set: seconds of the campaign's clock (on which
    /// drifts and the air run) per second of the recording's stamps. A drift of `v` per second
    /// of the campaign appears in the recording as `v * campaign_time_scale` per second.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub campaign_time_scale: Option<f64>,
}

impl TruthFile {
    pub fn new(t: &Truth, seed: u64, gauge: volcal::Gauge) -> TruthFile {
        let n = t.model.layout.n_params;
        TruthFile {
            format: FORMAT.into(),
            seed,
            model: ModelFile::from_model(
                &t.model,
                &Mat::zeros(n, n),
                gauge,
                Provenance { software: crate::software_version(), ..Default::default() },
            ),
            stations: t.stations.iter().map(|(s, p)| (*s, p.coords.into())).collect(),
            beams: t.beams.clone(),
            tracer_dead_path_m: t.tracer_dead_path_m,
            injected: t.injected.clone(),
            campaign_time_scale: None,
        }
    }

    pub fn write(&self, path: &Path) -> Result<()> {
        std::fs::write(path, serde_json::to_string_pretty(self)?)
            .with_context(|| format!("cannot write {}", path.display()))
    }

    pub fn load(path: &Path) -> Result<TruthFile> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read truth {}", path.display()))?;
        serde_json::from_str(&text).map_err(|e| anyhow::anyhow!("{} line {}: {e}", path.display(), e.line()))
    }
}
