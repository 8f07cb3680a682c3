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
use volcal::flexibility::{AxisKnots, KnotBound};
use volcal::predict::{AxisResolution, Uncertainty, RESOLVED_EVERYWHERE};
use volcal::smoothing::SmoothingReport;
use volcal::{Axis, ErrorFunction, ErrorModel, Gauge, ModelLayout, Representation, Squareness, Topology, Travel};

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
    /// Directions beyond the gauge that the data do not determine; with smoothing, that neither
    /// the readings nor the roughness prior determine (the `undetermined` directions).
    pub extra_null_dim: usize,
    /// Directions the readings alone leave open that the roughness prior determines (0 without
    /// smoothing, and in files written before stop 51, whose `extra_null_dim` counted them).
    #[serde(default)]
    pub prior_determined: usize,
    pub condition_number: f64,
    pub identified_functions: usize,
    pub not_observed: Vec<String>,
    pub combinations: Vec<Vec<String>>,
    pub statements: Vec<String>,
}

/// How the representation was chosen with `representation: auto`: the knots per axis, the
/// smoothing of each function, in numbers and in words.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Default)]
pub struct RepresentationChoice {
    pub knots: Vec<KnotsEntry>,
    pub smoothing: Vec<SmoothingEntry>,
    /// `reml` (estimated) or `fixed`.
    pub method: String,
    pub reml_iterations: usize,
    pub reml_converged: bool,
    /// Effective number of parameters of the whole model.
    pub edf_total: f64,
    /// The readings' noise variance as REML took it, relative to the stated noise: 1, or more
    /// where the smoothed fit leaves a misfit the model cannot absorb (then read as noise, not
    /// as detail). Files written before it was recorded read as 1.
    #[serde(default = "unit")]
    pub noise_scale: f64,
    pub statements: Vec<String>,
}

fn unit() -> f64 {
    1.0
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct KnotsEntry {
    pub axis: String,
    /// Distinct positions of the readings along the axis.
    pub positions: usize,
    pub intervals: usize,
    /// Where `intervals` goes beyond what the positions determine: the intervals they determine
    /// (the roughness prior determines the rest).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub determined: Option<usize>,
    /// `limit` (the most allowed), `positions` (the positions bound the knots: interpolated
    /// between them) or `data` (finer knots would not explain the readings better).
    pub bound: String,
    /// The refinement tests (doubling the knots, score test against the smoothed fit).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tests: Vec<RefinementEntry>,
    /// Where the axis's functions are linear tables instead of cubic B-splines (the readings
    /// show kinks at equally spaced nodes): `volcal::flexibility::TableChoice`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table: Option<TableEntry>,
}

/// Linear tables chosen for an axis by the Akaike criterion.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct TableEntry {
    /// Intervals of the tables, equal over the travel.
    pub intervals: usize,
    /// How much lower the criterion is with the tables on this axis alone (others held).
    pub aic_gain: f64,
    /// How much lower it is for the final fit.
    pub final_gain: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct RefinementEntry {
    pub from: usize,
    pub to: usize,
    pub delta_chi2: f64,
    pub dof: usize,
    pub p_value: f64,
    pub refined: bool,
    /// False: neither the readings' geometry nor the roughness prior determines the finer knots;
    /// the refinement was undone.
    #[serde(default = "yes")]
    pub determined: bool,
}

fn yes() -> bool {
    true
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SmoothingEntry {
    pub name: String,
    /// One smoothing parameter per piece of the travel.
    pub lambda: Vec<f64>,
    /// Effective number of parameters (of `n_coeffs`).
    pub edf: f64,
    pub n_coeffs: usize,
    /// The data show no detail beyond a parabola (the smoothing at its limit: the detail floor,
    /// `volcal::smoothing::DETAIL_FLOOR` parameters of detail, is what remains of it).
    pub smoothest: bool,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub shared_with: Vec<String>,
}

impl RepresentationChoice {
    /// The choice of a solve: its knots (from [`volcal::flexibility::auto_layout`]) and its
    /// smoothing report.
    pub fn new(knots: &[AxisKnots; 3], smoothing: Option<&SmoothingReport>) -> RepresentationChoice {
        let mut statements: Vec<String> = knots.iter().map(|k| k.describe()).collect();
        let mut entries = Vec::new();
        let (mut method, mut iterations, mut converged, mut edf_total) = (String::from("none"), 0, true, 0.0);
        let mut noise_scale = 1.0;
        if let Some(r) = smoothing {
            method = r.method.clone();
            iterations = r.iterations;
            converged = r.converged;
            edf_total = r.edf_total;
            noise_scale = r.noise_scale;
            let smoothest: Vec<String> =
                r.functions.iter().filter(|f| f.smoothest).map(|f| f.function.name()).collect();
            let curved: Vec<String> = r
                .functions
                .iter()
                .filter(|f| !f.smoothest)
                .map(|f| format!("{} {:.1}/{}", f.function.name(), f.edf, f.n_coeffs))
                .collect();
            statements.push(format!(
                "Smoothing by {} ({} iterations{}): effective parameters per function {}.",
                if r.method == "reml" { "restricted maximum likelihood" } else { "fixed parameters" },
                r.iterations,
                if r.converged { "" } else { ", not converged" },
                if curved.is_empty() { "none curved".to_string() } else { curved.join(", ") }
            ));
            if !smoothest.is_empty() {
                statements.push(format!(
                    "The readings show no detail beyond a parabola{} in {}; their uncertainty keeps {} parameters' \
                     worth of detail that the readings could not reveal (a local feature between them is not ruled out).",
                    if knots.iter().any(|k| k.table.is_some()) { " (a straight line for the tables)" } else { "" },
                    smoothest.join(", "),
                    volcal::smoothing::DETAIL_FLOOR
                ));
            }
            if r.noise_scale > 1.0 {
                statements.push(format!(
                    "The readings scatter about the smoothed fit {:.2} times as much as the stated noise (variance \
                     factor {:.2}): the smoothing took that as noise, not as detail, and the uncertainty carries \
                     it. A feature shorter than the readings' spacing, or physics the model leaves out, does \
                     this; `volcal diagnose` locates it.",
                    r.noise_scale.sqrt(),
                    r.noise_scale
                ));
            }
            for f in r.functions.iter().filter(|f| !f.shared_with.is_empty()) {
                statements.push(format!(
                    "{} shares its smoothing with {} (determined only in combination).",
                    f.function.name(),
                    f.shared_with.join(", ")
                ));
            }
            for pair in r.open_alike.iter().filter(|p| r.open_long_waves.iter().any(|w| w.pair == **p)) {
                let raised: Vec<String> = r
                    .open_long_waves
                    .iter()
                    .filter(|w| w.pair == *pair)
                    .map(|w| {
                        format!(
                            "{} {:.2}",
                            match w.degree {
                                3 => "cubic".to_string(),
                                5 => "quintic".to_string(),
                                k => format!("degree {k}"),
                            },
                            w.after / w.before.max(f64::MIN_POSITIVE)
                        )
                    })
                    .collect();
                statements.push(format!(
                    "{} and {}: the odd long waves of their difference, which no reading sees, are stated no smaller \
                     than the long waves of that order the readings measure of the face diagonals' pairs ({} times \
                     what the roughness prior alone stated); measure the straightness of one of them to determine them.",
                    pair[0].name(),
                    pair[1].name(),
                    raised.join(", ")
                ));
            }
            entries = r
                .functions
                .iter()
                .map(|f| SmoothingEntry {
                    name: f.function.name(),
                    lambda: f.lambda.clone(),
                    edf: f.edf,
                    n_coeffs: f.n_coeffs,
                    smoothest: f.smoothest,
                    shared_with: f.shared_with.clone(),
                })
                .collect();
        }
        RepresentationChoice {
            knots: knots
                .iter()
                .map(|k| KnotsEntry {
                    axis: k.axis.letter().to_string(),
                    positions: k.positions,
                    intervals: k.intervals,
                    determined: (k.determined < k.intervals).then_some(k.determined),
                    bound: match k.bound {
                        KnotBound::Limit => "limit".into(),
                        KnotBound::Positions => "positions".into(),
                        KnotBound::Data => "data".into(),
                        KnotBound::FewPositions => "few_positions".into(),
                    },
                    table: k.table.map(|t| TableEntry {
                        intervals: t.intervals,
                        aic_gain: t.aic_gain,
                        final_gain: t.final_gain,
                    }),
                    tests: k
                        .tests
                        .iter()
                        .map(|t| RefinementEntry {
                            from: t.from,
                            to: t.to,
                            delta_chi2: t.delta_chi2,
                            dof: t.dof,
                            p_value: t.p_value,
                            refined: t.refined,
                            determined: t.determined,
                        })
                        .collect(),
                })
                .collect(),
            smoothing: entries,
            method,
            reml_iterations: iterations,
            reml_converged: converged,
            edf_total,
            noise_scale,
            statements,
        }
    }
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

/// What a campaign's fixed beams were taken as aligned with ([`volcal::alignment`]).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct BeamAlignmentEntry {
    /// The alignment of the estimate.
    pub aligned_with: volcal::beam::BeamAlignment,
    /// Whether the machine file stated it; when not, the covariance covers the other alignment
    /// too (when it matters: `separation` above [`volcal::alignment::NEGLIGIBLE_SEPARATION`]).
    pub stated: bool,
    /// [`volcal::alignment::separation`]: how far apart the two alignments' predictions of the
    /// readings lie, in units of their noise, as a whole.
    pub separation: f64,
    /// Largest change of a volumetric error component between the two alignments' models
    /// (metres), where the uncertainty covers it; zero otherwise.
    #[serde(default)]
    pub largest_change_m: f64,
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
    /// With `representation: auto`: how the representation was chosen.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub representation_choice: Option<RepresentationChoice>,
    /// Campaigns with fixed beams: what the beams were taken as aligned with.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beam_alignment: Option<BeamAlignmentEntry>,
    /// Directions of the coefficients the data leave undetermined beyond the gauge (each an
    /// array of `n_params` values; orthonormal). A prediction that depends on them is not
    /// determined by the data ([`volcal::predict::Uncertainty`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub undetermined: Vec<Vec<f64>>,
    /// Axes the readings resolve only at their measured positions (between them the functions
    /// are interpolated): the positions, metres.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub measured_positions: Vec<MeasuredPositions>,
    pub provenance: Provenance,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct MeasuredPositions {
    pub axis: String,
    pub positions_m: Vec<f64>,
    /// Positions whose readings touch the axis's functions without measuring them
    /// (`volcal::interpolation::measured_positions`: a laser tracer's stops between a fixed
    /// beam's points): interpolated between `positions_m`, but given a number where the
    /// interpolation is contradicted. Absent (none) in files from before the distinction.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub touched_positions_m: Vec<f64>,
    /// For each of `touched_positions_m`, the share of its least-pinned function's variance
    /// that its own readings remove: what they add to the interpolation there
    /// (`volcal::predict::with_own_readings`). Absent (none) in files from before it: the
    /// straight-run bound then stands alone.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub touched_shares: Vec<f64>,
    /// The readings contradict the interpolation between the positions
    /// (`volcal::interpolation`): the error between them is not determined. Absent (false) in
    /// files from before the check.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub interpolation_contradicted: bool,
    /// How much larger the variance of the interpolation between the positions is than the
    /// covariance states (what the leave-one-position-out checks show, pooled over the axes
    /// checked, where above 1: `volcal::interpolation::variance_scale`): predictions there have
    /// their covariance scaled by it. Absent (1) in files from before the scale, where the axis
    /// was not checked and where the factor is not above 1.
    #[serde(default = "unit_scale", skip_serializing_if = "is_unit_scale")]
    pub interpolation_variance_scale: f64,
}

fn unit_scale() -> f64 {
    1.0
}

fn is_unit_scale(s: &f64) -> bool {
    *s == 1.0
}

/// A model read back: the error model, its covariance and what the data left undetermined.
pub struct LoadedModel {
    pub file: ModelFile,
    pub model: ErrorModel,
    pub covariance: Mat<f64>,
    /// `n_params x m`, orthonormal columns.
    pub undetermined: Mat<f64>,
    pub resolution: [AxisResolution; 3],
}

impl LoadedModel {
    /// What predictions from this model may say.
    pub fn uncertainty(&self) -> Uncertainty<'_> {
        Uncertainty::new(&self.covariance, &self.undetermined).with_resolution(&self.resolution)
    }
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
                prior_determined: id.prior_determined,
                condition_number: if id.condition_number.is_finite() { id.condition_number } else { -1.0 },
                identified_functions: id.identified_functions,
                not_observed: id.not_observed.clone(),
                combinations: id.combinations.clone(),
                statements: id.statements.clone(),
            },
            warnings: sol.warnings.clone(),
            undetermined: (0..sol.undetermined.ncols())
                .map(|j| (0..sol.undetermined.nrows()).map(|i| sol.undetermined[(i, j)]).collect())
                .collect(),
            measured_positions: Axis::ALL
                .iter()
                .filter_map(|&a| match &sol.resolution[a.index()] {
                    AxisResolution::AtPositions {
                        positions,
                        touched,
                        touched_share,
                        contradicted,
                        interpolation_scale,
                        ..
                    } => Some(MeasuredPositions {
                        axis: a.letter().to_string(),
                        positions_m: positions.clone(),
                        touched_positions_m: touched.clone(),
                        touched_shares: touched_share.clone(),
                        interpolation_contradicted: *contradicted,
                        interpolation_variance_scale: *interpolation_scale,
                    }),
                    AxisResolution::Everywhere => None,
                })
                .collect(),
            ..ModelFile::from_model(m, &sol.covariance, sol.gauge, provenance)
        }
    }

    /// Where the readings resolve each axis, checked.
    pub fn resolution(&self) -> Result<[AxisResolution; 3]> {
        let mut out = RESOLVED_EVERYWHERE;
        for (j, m) in self.measured_positions.iter().enumerate() {
            let a = Axis::ALL
                .iter()
                .find(|a| a.letter().to_string() == m.axis)
                .ok_or_else(|| anyhow::anyhow!("field measured_positions[{j}]: unknown axis {:?}", m.axis))?;
            // Finite and increasing: NaN compares false either way.
            let increasing = |v: &[f64]| v.iter().all(|x| x.is_finite()) && v.windows(2).all(|w| w[0] < w[1]);
            if !increasing(&m.positions_m) {
                bail!("field measured_positions[{j}]: positions must be finite and increasing");
            }
            let t = &m.touched_positions_m;
            if !increasing(t) {
                bail!("field measured_positions[{j}].touched_positions_m: positions must be finite and increasing");
            }
            let shares = &m.touched_shares;
            if !(shares.is_empty() || shares.len() == t.len()) {
                bail!(
                    "field measured_positions[{j}].touched_shares: one per touched position ({}), got {}",
                    t.len(),
                    shares.len()
                );
            }
            if let Some(v) = shares.iter().find(|v| !(v.is_finite() && (0.0..1.0).contains(*v))) {
                bail!("field measured_positions[{j}].touched_shares: each must lie in [0, 1), got {v}");
            }
            let s = m.interpolation_variance_scale;
            if !(s.is_finite() && s > 0.0) {
                bail!("field measured_positions[{j}].interpolation_variance_scale: must be a positive number, got {s}");
            }
            let r = AxisResolution::at(m.positions_m.clone())
                .measured_at(
                    m.positions_m.clone(),
                    t.iter().enumerate().map(|(k, &q)| (q, shares.get(k).copied().unwrap_or(0.0))).collect(),
                )
                .with_interpolation_scale(s);
            out[a.index()] = if m.interpolation_contradicted { r.contradicted() } else { r };
        }
        Ok(out)
    }

    /// The undetermined directions as a matrix (`n_params x m`), checked.
    pub fn undetermined_matrix(&self, n_params: usize) -> Result<Mat<f64>> {
        for (j, v) in self.undetermined.iter().enumerate() {
            if v.len() != n_params {
                bail!("field undetermined[{j}]: {} values for {n_params} parameters", v.len());
            }
            if let Some(k) = v.iter().position(|x| !x.is_finite()) {
                bail!("field undetermined[{j}]: value {k} is not finite");
            }
        }
        Ok(Mat::from_fn(n_params, self.undetermined.len(), |i, j| self.undetermined[j][i]))
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
            representation_choice: None,
            beam_alignment: None,
            undetermined: Vec::new(),
            measured_positions: Vec::new(),
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
    let undetermined =
        file.undetermined_matrix(model.layout.n_params).with_context(|| format!("model {}", path.display()))?;
    let resolution = file.resolution().with_context(|| format!("model {}", path.display()))?;
    Ok(LoadedModel { file, model, covariance, undetermined, resolution })
}

/// SHA-256 of a file's bytes, hex.
pub fn sha256_file(path: &Path) -> Result<String> {
    use sha2::{Digest, Sha256};
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    Ok(format!("{:x}", Sha256::digest(&bytes)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::{Machine, DEMO_MACHINE};

    /// A model file gives back, bit for bit, the coefficients, covariance and interpolation
    /// factors it was written from: replaying a model years later must not move a number by
    /// an ulp (serde_json's `float_roundtrip`; its default parser is best-effort).
    #[test]
    fn a_model_file_gives_back_its_numbers_bit_for_bit() {
        let m = Machine::parse(DEMO_MACHINE).unwrap();
        let cfg = crate::plan::sim_config(&m, volcal_sim::Plan::patent_example(), 7);
        let out = volcal_sim::simulate(&cfg, &[], 7).unwrap();
        let prep = volcal::campaign::prepare(&out.campaign, &m.layout.travel, &m.expansion).unwrap();
        let mut sol = volcal::solve(&m.layout, &prep.obs, &m.solve_options(), &[]).unwrap();
        // A factor with a full 17-digit mantissa, as the interpolation check writes them, and a
        // position the readings touch without measuring it.
        sol.resolution[1] = AxisResolution::at(vec![0.0, 0.1, 0.2, 0.3])
            .measured_at(vec![0.0, 0.2, 0.3], vec![(0.1, 0.3)])
            .with_interpolation_scale(1.935531796686672);
        let path = std::env::temp_dir().join(format!("volcal-roundtrip-{}.json", std::process::id()));
        ModelFile::from_solution(&sol, &prep.obs.groups, Provenance::default()).write(&path).unwrap();
        let back = load(&path);
        std::fs::remove_file(&path).ok();
        let back = back.unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back.model.u), bits(&sol.model.u), "coefficients");
        // The whole matrix: the file keeps the upper triangle, and the solve's is symmetric to the bit.
        let n = sol.covariance.nrows();
        let all = |c: &Mat<f64>| (0..n).flat_map(|i| (0..n).map(move |j| c[(i, j)].to_bits())).collect::<Vec<_>>();
        assert_eq!(all(&back.covariance), all(&sol.covariance), "covariance");
        assert_eq!(back.resolution, sol.resolution, "measured and touched positions, interpolation factors");

        // A file whose touched positions are not increasing is refused, and says which field.
        ModelFile::from_solution(&sol, &prep.obs.groups, Provenance::default()).write(&path).unwrap();
        let mut v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        v["measured_positions"][0]["touched_positions_m"] = serde_json::json!([0.1, 0.05]);
        std::fs::write(&path, v.to_string()).unwrap();
        let err = load(&path).err().map(|e| format!("{e:#}"));
        std::fs::remove_file(&path).ok();
        let err = err.expect("decreasing touched positions refused");
        assert!(err.contains("measured_positions[0].touched_positions_m"), "{err}");

        // Nor a share outside [0, 1), or one too many.
        for bad in [serde_json::json!([1.5]), serde_json::json!([0.3, 0.2])] {
            ModelFile::from_solution(&sol, &prep.obs.groups, Provenance::default()).write(&path).unwrap();
            let mut v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
            v["measured_positions"][0]["touched_shares"] = bad.clone();
            std::fs::write(&path, v.to_string()).unwrap();
            let err = load(&path).err().map(|e| format!("{e:#}"));
            std::fs::remove_file(&path).ok();
            let err = err.unwrap_or_else(|| panic!("touched shares {bad} refused"));
            assert!(err.contains("measured_positions[0].touched_shares"), "{err}");
        }
    }
}
