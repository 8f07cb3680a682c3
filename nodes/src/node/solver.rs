//! The solver node (offline replay): reads a bag, identifies the error model from its
//! synchronised pairs, writes the model JSON and publishes it on `/error_model` with
//! transient-local durability, so that a node joining later still receives it.
//!
//! With `diagnose: true` it runs the diagnosis `volcal diagnose` runs
//! ([`volcal_formats::diagnosing::diagnose_campaign`], the same code) instead of the plain
//! solve: the model written and published is the refit (the rigid-body model fitted together
//! with the named effects), and the diagnosis goes out on `/diagnosis` (transient-local too),
//! saying which model `/error_model` carries.
//!
//! Parameters: `bag` (required: a bag, or a campaign CSV as `volcal solve` and `volcal
//! diagnose` accept), `machine` (default: the built-in demo machine), `out` (model JSON;
//! default `model.json` inside the bag directory), `diagnose` (default false), `linger_s` (how
//! long to keep serving the model; negative: until stopped, the default).
//!
//! With `live: true` it reads no bag: it diagnoses a recording while it runs, from the pairs
//! the recorder publishes ([`super::live_diagnosis`]).

use super::live_diagnosis::MachineSource;
use super::runtime::secs;
use crate::ros::{now_ns, qos, shutdown, RosNode};
use anyhow::{anyhow, Result};
use ros2_client::Publisher;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::time::Instant;
use volcal_bag::campaign::{self, input_sha256};
use volcal_bag::convert::{diagnosis_msg, error_model_msg};
use volcal_formats::diagnosing::diagnose_campaign;
use volcal_formats::machine::{Machine, DEMO_MACHINE};
use volcal_formats::model_file::{sha256_file, ModelFile, Provenance};
use volcal_formats::solving::{probe_offsets, solve_campaign, summary};
use volcal_msgs::msg::{Diagnosis, ErrorModel};
use volcal_msgs::topics;

pub fn run(node: &mut RosNode) -> Result<()> {
    let machine_path = node.args.path("machine")?;
    let linger: f64 = node.args.get_or("linger_s", -1.0)?;
    let (machine, machine_name, machine_sha) = match &machine_path {
        Some(p) => (Machine::load(p)?, p.display().to_string(), sha256_file(p)?),
        None => (
            Machine::parse(DEMO_MACHINE)?,
            "built-in demo machine".to_string(),
            format!("{:x}", Sha256::digest(DEMO_MACHINE.as_bytes())),
        ),
    };
    if node.args.get_or("live", false)? {
        let out = node.args.path("out")?;
        let source = MachineSource { machine, name: machine_name, sha256: machine_sha };
        return super::live_diagnosis::run(node, source, out, linger);
    }
    let bag: PathBuf = node
        .args
        .require::<String>("bag")
        .map_err(|e| anyhow!("{e:#} (or live: true to diagnose a recording while it runs)"))?
        .into();
    let out = match node.args.path("out")? {
        Some(p) => p,
        None if bag.is_dir() => bag.join("model.json"),
        None => bag.with_extension("model.json"),
    };
    let diagnose: bool = node.args.get_or("diagnose", false)?;
    node.warn_unused_parameters();
    let started = Instant::now();
    let (campaign, input_notes) = campaign::load_campaign_noted(&bag)?;
    log::info!("replaying {} pairs from {}", campaign.readings.len(), bag.display());
    let provenance = Provenance {
        input: bag.display().to_string(),
        input_sha256: input_sha256(&bag)?,
        machine: machine_name,
        machine_sha256: machine_sha,
        software: volcal_formats::software_version(),
    };
    let source = bag.display().to_string();
    let (model, diagnosis) = if diagnose {
        let d = diagnose_campaign(&campaign, &machine, &source, provenance.clone())?.with_input_notes(input_notes);
        print!("{}", d.report);
        let model = d.refit_model(provenance);
        let which = which_model(&d.file.effects.iter().map(|e| e.id.as_str()).collect::<Vec<_>>(), &out);
        (model, Some(diagnosis_msg(&d.file, &which, false, now_ns())?))
    } else {
        for n in &input_notes {
            log::warn!("{n}");
        }
        let solved = solve_campaign(&campaign, machine, &source, provenance)?;
        print!(
            "{}",
            summary(&solved.solution.model, &solved.solution.uncertainty(), &solved.file, &probe_offsets(&campaign))
        );
        (solved.file, None)
    };
    model.write(&out)?;
    log::info!("solved in {:.1} s; wrote model to {}", started.elapsed().as_secs_f64(), out.display());
    // Held until the node ends: the latched samples live as long as their writers.
    let _publishers = publish(node, &model, diagnosis)?;
    let until = (linger >= 0.0).then(|| Instant::now() + secs(linger));
    while !shutdown::requested() && until.is_none_or(|u| Instant::now() < u) {
        node.wait(secs(0.05));
    }
    Ok(())
}

/// What the Diagnosis message says of the model on `/error_model`.
fn which_model(effects: &[&str], out: &Path) -> String {
    if effects.is_empty() {
        format!("the rigid-body fit (nothing named, so no refit), as written to {}", out.display())
    } else {
        format!(
            "the refit: the rigid-body model fitted together with the named effects ({}), as written to {}",
            effects.join(", "),
            out.display()
        )
    }
}

/// The latched publishers of the model and of the diagnosis.
type Publishers = (Publisher<ErrorModel>, Option<Publisher<Diagnosis>>);

/// Publishes the model (and the diagnosis, if any) latched: late joiners receive them as long
/// as the returned publishers live.
fn publish(node: &mut RosNode, model: &ModelFile, diagnosis: Option<Diagnosis>) -> Result<Publishers> {
    // The diagnosis first: a subscriber that sees the refit model finds the diagnosis already
    // there.
    let diagnosis_publisher = match diagnosis {
        Some(d) => {
            let publisher = node.publisher::<Diagnosis>(topics::DIAGNOSIS, qos::latched())?;
            let verdict = match d.verdict {
                Diagnosis::CLEAN => "clean".to_string(),
                Diagnosis::EFFECTS_NAMED => {
                    format!("named {}", d.effects.iter().map(|e| e.id.as_str()).collect::<Vec<_>>().join(", "))
                }
                _ => "an excess no catalogue effect explains".to_string(),
            };
            publisher.publish(d).map_err(|e| anyhow!("publish {}: {e:?}", topics::DIAGNOSIS))?;
            log::info!("published the diagnosis on {} (transient-local): {verdict}", node.resolve(topics::DIAGNOSIS));
            Some(publisher)
        }
        None => None,
    };
    let publisher = node.publisher::<ErrorModel>(topics::ERROR_MODEL, qos::latched())?;
    publisher
        .publish(error_model_msg(model, now_ns())?)
        .map_err(|e| anyhow!("publish {}: {e:?}", topics::ERROR_MODEL))?;
    log::info!("published the model on {} (transient-local)", node.resolve(topics::ERROR_MODEL));
    Ok((publisher, diagnosis_publisher))
}
