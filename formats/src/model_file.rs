//! The model file (JSON): the identified error functions with their covariance, the gauge,
//! topology and travel, residual statistics, identifiability, and provenance.
//!
//! Numbers are written in shortest round-trip form, so reading a model back gives bit-identical
//! coefficients; nothing time-dependent is written, so the same input gives the same file.

use anyhow::{bail, Context, Result};
use faer::Mat;
use serde::{Deserialize, Serialize};
use std::path::Path;
use volcal::estimator::Solution;
use volcal::{ErrorFunction, ErrorModel, Gauge, ModelLayout, Representation, Squareness, Topology, Travel};

pub const FORMAT: &str = "volcal-model/1";

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct FunctionEntry {
    pub name: String,
    pub representation: Representation,
    pub coefficients: Vec<f64>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct LineEntry {
    pub kind: String,
    pub station: u32,
    pub line: u32,
    pub segment: u32,
    pub n: usize,
    pub rms_m: f64,
    pub max_abs_m: f64,
    /// Fitted beam direction (zero for tracer paths).
    pub direction: [f64; 3],
    /// Barycentre of the actual points.
    pub centroid_m: [f64; 3],
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ResidualEntry {
    pub n_obs: usize,
    pub rms_m: f64,
    pub chi2: f64,
    pub dof: usize,
    pub variance_factor: f64,
    pub lines: Vec<LineEntry>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct StationEntry {
    pub station: u32,
    pub position_m: [f64; 3],
    pub sigma_m: [f64; 3],
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Default)]
pub struct IdentifiabilityEntry {
    pub rank: usize,
    pub gauge_dim: usize,
    pub extra_null_dim: usize,
    pub condition_number: f64,
    pub identified_functions: usize,
    pub not_observed: Vec<String>,
    pub combinations: Vec<Vec<String>>,
    pub statements: Vec<String>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Default)]
pub struct Provenance {
    /// Input campaign file name (as given).
    pub input: String,
    pub input_sha256: String,
    pub machine: String,
    pub machine_sha256: String,
    pub software: String,
}

/// Symmetric matrix as its packed upper triangle (row-major).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct PackedSym {
    pub n: usize,
    pub upper: Vec<f64>,
}

impl PackedSym {
    pub fn from_mat(m: &Mat<f64>) -> PackedSym {
        let n = m.nrows();
        let mut upper = Vec::with_capacity(n * (n + 1) / 2);
        for i in 0..n {
            for j in i..n {
                upper.push(m[(i, j)]);
            }
        }
        PackedSym { n, upper }
    }

    pub fn to_mat(&self) -> Result<Mat<f64>> {
        let n = self.n;
        if self.upper.len() != n * (n + 1) / 2 {
            bail!("covariance: {} values for a {n} x {n} matrix (expected {})", self.upper.len(), n * (n + 1) / 2);
        }
        let mut m = Mat::<f64>::zeros(n, n);
        let mut k = 0;
        for i in 0..n {
            for j in i..n {
                m[(i, j)] = self.upper[k];
                m[(j, i)] = self.upper[k];
                k += 1;
            }
        }
        Ok(m)
    }
}

/// The model file.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ModelFile {
    pub format: String,
    pub topology: String,
    pub travel: [[f64; 2]; 3],
    pub gauge: Gauge,
    pub functions: Vec<FunctionEntry>,
    pub squareness: Vec<(String, f64)>,
    pub covariance: PackedSym,
    pub residuals: Option<ResidualEntry>,
    #[serde(default)]
    pub stations: Vec<StationEntry>,
    #[serde(default)]
    pub identifiability: IdentifiabilityEntry,
    #[serde(default)]
    pub warnings: Vec<String>,
    pub provenance: Provenance,
}

/// A model read back: the error model and its covariance.
pub struct LoadedModel {
    pub file: ModelFile,
    pub model: ErrorModel,
    pub covariance: Mat<f64>,
}

impl ModelFile {
    /// Builds the file content from a solution.
    pub fn from_solution(
        sol: &Solution,
        obs_groups: &[volcal::campaign::LineGroup],
        provenance: Provenance,
    ) -> ModelFile {
        let m = &sol.model;
        let lines = obs_groups
            .iter()
            .zip(&sol.stats.per_group)
            .map(|(g, s)| LineEntry {
                kind: g.kind.name().to_string(),
                station: g.station,
                line: g.line,
                segment: g.segment,
                n: s.n,
                rms_m: s.rms_m,
                max_abs_m: s.max_abs_m,
                direction: s.direction.into(),
                centroid_m: s.centroid.coords.into(),
            })
            .collect();
        let id = &sol.identifiability;
        ModelFile {
            residuals: Some(ResidualEntry {
                n_obs: sol.stats.n_obs,
                rms_m: sol.stats.rms_m,
                chi2: sol.stats.chi2,
                dof: sol.stats.dof,
                variance_factor: sol.stats.variance_factor,
                lines,
            }),
            stations: sol
                .stations
                .iter()
                .map(|s| StationEntry {
                    station: s.station,
                    position_m: s.position.coords.into(),
                    sigma_m: s.sigma.into(),
                })
                .collect(),
            identifiability: IdentifiabilityEntry {
                rank: id.rank,
                gauge_dim: id.gauge_dim,
                extra_null_dim: id.extra_null_dim,
                condition_number: if id.condition_number.is_finite() { id.condition_number } else { -1.0 },
                identified_functions: id.identified_functions,
                not_observed: id.not_observed.clone(),
                combinations: id.combinations.clone(),
                statements: id.statements.clone(),
            },
            warnings: sol.warnings.clone(),
            ..ModelFile::from_model(m, &sol.covariance, sol.gauge, provenance)
        }
    }

    /// A model file with coefficients and covariance only (e.g. simulated truth).
    pub fn from_model(m: &ErrorModel, cov: &Mat<f64>, gauge: Gauge, provenance: Provenance) -> ModelFile {
        ModelFile {
            format: FORMAT.to_string(),
            topology: m.layout.topology.to_string(),
            travel: m.layout.travel.ranges,
            gauge,
            functions: ErrorFunction::all()
                .iter()
                .map(|&f| FunctionEntry {
                    name: f.name(),
                    representation: m.layout.basis(f).repr,
                    coefficients: m.coeffs(f).to_vec(),
                })
                .collect(),
            squareness: Squareness::ALL.iter().map(|&s| (s.name().to_string(), m.squareness(s))).collect(),
            covariance: PackedSym::from_mat(cov),
            residuals: None,
            stations: Vec::new(),
            identifiability: IdentifiabilityEntry::default(),
            warnings: Vec::new(),
            provenance,
        }
    }

    /// Rebuilds the error model and covariance, checking consistency.
    pub fn to_model(&self) -> Result<(ErrorModel, Mat<f64>)> {
        if self.format != FORMAT {
            bail!("field format: {:?} is not {FORMAT}", self.format);
        }
        let topology = Topology::parse(&self.topology).map_err(|e| anyhow::anyhow!("field topology: {e}"))?;
        let travel = Travel { ranges: self.travel };
        travel.validate().map_err(|e| anyhow::anyhow!("field travel: {e}"))?;
        if self.functions.len() != 18 {
            bail!("field functions: {} entries, expected 18", self.functions.len());
        }
        let mut reprs = [Representation::default(); 18];
        for (i, fe) in self.functions.iter().enumerate() {
            let f = ErrorFunction::from_index(i);
            if fe.name != f.name() {
                bail!("field functions[{i}]: name {:?}, expected {}", fe.name, f.name());
            }
            fe.representation.validate().map_err(|e| anyhow::anyhow!("field functions[{i}] ({}): {e}", fe.name))?;
            reprs[i] = fe.representation;
        }
        let layout = ModelLayout::new(topology, travel, reprs);
        let mut m = ErrorModel::zero(layout);
        for (i, fe) in self.functions.iter().enumerate() {
            let f = ErrorFunction::from_index(i);
            if fe.coefficients.len() != m.layout.basis(f).n_coeffs() {
                bail!(
                    "field functions[{i}] ({}): {} coefficients, the representation has {}",
                    fe.name,
                    fe.coefficients.len(),
                    m.layout.basis(f).n_coeffs()
                );
            }
            if let Some(k) = fe.coefficients.iter().position(|v| !v.is_finite()) {
                bail!("field functions[{i}] ({}): coefficient {k} is not finite", fe.name);
            }
            m.coeffs_mut(f).copy_from_slice(&fe.coefficients);
        }
        for (name, v) in &self.squareness {
            let s = Squareness::parse(name).ok_or_else(|| anyhow::anyhow!("field squareness: unknown {name:?}"))?;
            m.set_squareness(s, *v);
        }
        let cov = self.covariance.to_mat()?;
        if cov.nrows() != m.layout.n_params {
            bail!("field covariance: {} x {} for {} parameters", cov.nrows(), cov.nrows(), m.layout.n_params);
        }
        Ok((m, cov))
    }

    pub fn write(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self)?;
        std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
    }
}

/// Reads a model file.
pub fn load(path: &Path) -> Result<LoadedModel> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read model {}", path.display()))?;
    let file: ModelFile = serde_json::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{} line {}, column {}: {e}", path.display(), e.line(), e.column()))?;
    let (model, covariance) = file.to_model().with_context(|| format!("model {}", path.display()))?;
    Ok(LoadedModel { file, model, covariance })
}

/// SHA-256 of a file's bytes, hex.
pub fn sha256_file(path: &Path) -> Result<String> {
    use sha2::{Digest, Sha256};
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    Ok(format!("{:x}", Sha256::digest(&bytes)))
}
