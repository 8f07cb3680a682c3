//! The solver node (offline replay): reads a bag, identifies the error model from its
//! synchronised pairs, writes the model JSON and publishes it on `/error_model` with
//! transient-local durability, so that a node joining later still receives it.
//!
//! Parameters: `bag` (required), `machine` (default: the built-in demo machine), `out` (model
//! JSON; default `model.json` inside the bag directory), `linger_s` (how long to keep serving
//! the model; negative: until stopped, the default).

use super::runtime::secs;
use crate::ros::{now_ns, qos, shutdown, RosNode};
use anyhow::{anyhow, Result};
use sha2::{Digest, Sha256};
use std::path::PathBuf;
use std::time::Instant;
use volcal_bag::campaign::{self, input_sha256};
use volcal_bag::convert::error_model_msg;
use volcal_formats::machine::{Machine, DEMO_MACHINE};
use volcal_formats::model_file::{sha256_file, Provenance};
use volcal_formats::solving::{probe_offsets, solve_campaign, summary};
use volcal_msgs::msg::ErrorModel;
use volcal_msgs::topics;

pub fn run(node: &mut RosNode) -> Result<()> {
    let bag: PathBuf = node.args.require::<String>("bag")?.into();
    let machine_path = node.args.path("machine")?;
    let out = match node.args.path("out")? {
        Some(p) => p,
        None if bag.is_dir() => bag.join("model.json"),
        None => bag.with_extension("model.json"),
    };
    let linger: f64 = node.args.get_or("linger_s", -1.0)?;
    node.warn_unused_parameters();
    let (machine, machine_name, machine_sha) = match &machine_path {
        Some(p) => (Machine::load(p)?, p.display().to_string(), sha256_file(p)?),
        None => (
            Machine::parse(DEMO_MACHINE)?,
            "built-in demo machine".to_string(),
            format!("{:x}", Sha256::digest(DEMO_MACHINE.as_bytes())),
        ),
    };
    let started = Instant::now();
    let campaign = campaign::read(&bag)?;
    log::info!("replaying {} pairs from {}", campaign.readings.len(), bag.display());
    let provenance = Provenance {
        input: bag.display().to_string(),
        input_sha256: input_sha256(&bag)?,
        machine: machine_name,
        machine_sha256: machine_sha,
        software: volcal_formats::software_version(),
    };
    let solved = solve_campaign(&campaign, machine, &bag.display().to_string(), provenance)?;
    solved.file.write(&out)?;
    print!("{}", summary(&solved.solution.model, &solved.solution.covariance, &solved.file, &probe_offsets(&campaign)));
    log::info!("solved in {:.1} s; wrote model to {}", started.elapsed().as_secs_f64(), out.display());
    let publisher = node.publisher::<ErrorModel>(topics::ERROR_MODEL, qos::latched())?;
    publisher
        .publish(error_model_msg(&solved.file, now_ns())?)
        .map_err(|e| anyhow!("publish {}: {e:?}", topics::ERROR_MODEL))?;
    log::info!("published the model on {} (transient-local)", node.resolve(topics::ERROR_MODEL));
    let until = (linger >= 0.0).then(|| Instant::now() + secs(linger));
    while !shutdown::requested() && until.is_none_or(|u| Instant::now() < u) {
        node.wait(secs(0.05));
    }
    Ok(())
}
