//! Campaign plans (YAML) and the simulator set-up of a machine file: what `volcal simulate`,
//! the simulated nodes and the tests load before they simulate.

use crate::machine::Machine;
use anyhow::{Context, Result};
use rand::SeedableRng;
use std::path::Path;
use volcal_sim::{random_truth, Plan, SimConfig, VirtualMachine};

/// Reads a campaign plan (YAML); `None` gives the patent's example plan.
pub fn load_plan(path: Option<&Path>) -> Result<Plan> {
    let Some(path) = path else { return Ok(Plan::patent_example()) };
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read plan {}", path.display()))?;
    let plan: Plan = serde_yaml::from_str(&text).map_err(|e| {
        let at = e.location().map(|l| format!("line {}, column {}: ", l.line(), l.column())).unwrap_or_default();
        anyhow::anyhow!("plan {}: {at}{e}", path.display())
    })?;
    plan.validate().map_err(|e| anyhow::anyhow!("plan {}: {e}", path.display()))?;
    Ok(plan)
}

/// The simulator configuration for a machine, with a truth drawn from `seed`.
pub fn sim_config(machine: &Machine, plan: Plan, seed: u64) -> SimConfig {
    let s = &machine.file.simulation;
    // The truth has its own random stream so that changing the noise does not change it.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x5452_5554_485f_5345);
    let truth = match s.truth_preset {
        // Validated by the machine file: the only preset is the paper's machine.
        Some(_) => volcal_sim::paper::truth(),
        None => random_truth(machine.truth_layout(), &s.truth, &mut rng),
    };
    SimConfig {
        machine: VirtualMachine { truth, repeatability_m: s.repeatability_m, centring_m: s.centring_m },
        interferometer: s.interferometer.clone(),
        deflector: s.deflector.clone(),
        tracer: s.tracer.clone(),
        environment: s.environment.clone(),
        plan,
    }
}
