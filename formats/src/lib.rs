//! # volcal_formats: every file volcal reads or writes, other than a bag
//!
//! The machine file (YAML), campaign plans, the campaign CSV, the model and truth JSON, the text
//! reports and the merging of campaigns, plus what every reader of those files shares: solving a
//! loaded campaign for a machine file and comparing a model with a simulation truth.
//!
//! - [`machine`]: the machine file; [`plan`]: campaign plans and the simulator set-up.
//! - [`campaign_csv`]: the campaign interchange format; [`merge`]: joining campaigns.
//! - [`model_file`], [`truth_file`]: model and simulation-truth JSON.
//! - [`compensation`]: compensation tables for controllers (LinuxCNC, a volumetric grid) and what
//!   every per-axis export shares (nodes, reference lines, the residual); [`isg`]: the ISG
//!   kernel's (TwinCAT TF5280) volumetric tables; [`sinumerik`]: SINUMERIK EEC and CEC tables.
//! - [`iso230_2`]: a bidirectional positioning test (runs CSV) evaluated to ISO 230-2:2014.
//! - [`report`]: text tables; [`solving`]: a campaign solved for a machine file, its summary.
//! - [`diagnosing`]: a campaign diagnosed for a machine file (`volcal diagnose`, the replay
//!   node); [`diagnosis_file`]: the diagnosis JSON and the printed report.
//! - [`instrument`]: what the instruments report, shared by the node backends and the bag's
//!   message conversions.
//!
//! It sits above the core ([`volcal`]) and the simulator ([`volcal_sim`]) and below everything
//! that knows bags, DDS or Rerun: it must never depend on those.

pub mod campaign_csv;
pub mod compensation;
pub mod compensation_grid;
pub mod diagnosing;
pub mod diagnosis_file;
pub mod instrument;
pub mod isg;
pub mod iso230_2;
pub mod machine;
pub mod merge;
pub mod model_file;
pub mod plan;
pub mod report;
pub mod sinumerik;
pub mod solving;
pub mod truth_file;

/// `volcal <version>` for provenance records.
pub fn software_version() -> String {
    format!("volcal {}", env!("CARGO_PKG_VERSION"))
}
