//! The node-set half of `volcal demo`: the demo's campaign run again as ROS 2 nodes over DDS
//! on this host (its own leased `ROS_DOMAIN_ID`, loopback only), recorded to a bag, replayed
//! into the solver node, and the resulting model compared with the simulation truth and with
//! the offline solve. The launch descriptions are the repository's, built into the binary.

use anyhow::{bail, Result};
use nalgebra::Vector3;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;
use volcal::{predict, ErrorModel};
use volcal_formats::model_file;
use volcal_formats::solving::{compare_with_truth, Solved};
use volcal_nodes::launch::{self, LaunchDescription, LaunchOptions};
use volcal_nodes::ros::domain;

/// `launch_configs/sim_campaign.yaml`, built in.
pub const SIM_CAMPAIGN: &str = include_str!("../../launch_configs/sim_campaign.yaml");
/// `launch_configs/replay.yaml`, built in.
pub const REPLAY: &str = include_str!("../../launch_configs/replay.yaml");

/// A directory name under `dir` that does not exist yet.
fn fresh(dir: &Path, stem: &str) -> PathBuf {
    (1..)
        .map(|k| dir.join(if k == 1 { stem.to_string() } else { format!("{stem}_{k}") }))
        .find(|p| !p.exists())
        .unwrap()
}

fn run_launch(text: &str, name: &str, dir: &Path, args: &[(&str, String)], domain: u16) -> Result<()> {
    let overrides: BTreeMap<String, String> = args.iter().map(|(k, v)| (k.to_string(), v.clone())).collect();
    let d = LaunchDescription::parse(text, name, &dir.display().to_string(), &overrides)?;
    let outcome = launch::run(&d, &LaunchOptions { domain: Some(domain), ..LaunchOptions::default() })?;
    if outcome.interrupted {
        bail!("{name}: interrupted");
    }
    if !outcome.failed.is_empty() {
        bail!("{name}: node(s) failed: {}", outcome.failed.join(", "));
    }
    Ok(())
}

/// RMS over a grid of the difference of two independent estimates, and its predicted RMS.
pub fn model_difference(
    a: &ErrorModel,
    ca: &faer::Mat<f64>,
    b: &ErrorModel,
    cb: &faer::Mat<f64>,
    offsets: &[Vector3<f64>],
    step: f64,
) -> (f64, f64) {
    let (mut d2, mut v2, mut n) = (0.0, 0.0, 0usize);
    for x in predict::grid(&a.layout.travel, step) {
        for p in offsets {
            d2 += (a.error(&x, p) - b.error(&x, p)).norm_squared();
            v2 += predict::predict(a, &predict::Uncertainty::determined(ca), &x, p).cov.trace()
                + predict::predict(b, &predict::Uncertainty::determined(cb), &x, p).cov.trace();
            n += 1;
        }
    }
    ((d2 / n as f64).sqrt(), (v2 / n as f64).sqrt())
}

/// Runs the chain and prints the comparisons. `offline` is the demo's offline solve of the same
/// plan and seed; `truth` the simulation truth.
pub fn run(
    dir: &Path,
    seed: u64,
    machine_path: &Path,
    offline: &Solved,
    truth: &ErrorModel,
    offsets: &[Vector3<f64>],
) -> Result<()> {
    let lease = domain::lease()?;
    let bag = fresh(dir, "campaign_bag");
    let model = dir.join(format!("model_{}.json", bag.file_name().unwrap().to_string_lossy()));
    println!(
        "\nThe same campaign over ROS 2: simulated deflector, interferometer, machine and environment nodes, the sequencer and the recorder, over DDS on this host (ROS_DOMAIN_ID {}, loopback only), recorded to {}; then the bag replayed into the solver node.\n",
        lease.id,
        bag.display()
    );
    let started = Instant::now();
    let machine = machine_path.display().to_string();
    run_launch(
        SIM_CAMPAIGN,
        "sim_campaign.yaml (built in)",
        dir,
        &[("bag", bag.display().to_string()), ("machine", machine.clone()), ("seed", seed.to_string())],
        lease.id,
    )?;
    let recorded = started.elapsed().as_secs_f64();
    run_launch(
        REPLAY,
        "replay.yaml (built in)",
        dir,
        &[
            ("bag", bag.display().to_string()),
            ("machine", machine),
            ("out", model.display().to_string()),
            ("linger_s", "0".into()),
        ],
        lease.id,
    )?;
    let m = model_file::load(&model)?;
    let g = offline.machine.gauge;
    let chain = compare_with_truth(&m.model, &m.uncertainty(), truth, g, offsets, 0.1);
    let off = compare_with_truth(&offline.solution.model, &offline.solution.uncertainty(), truth, g, offsets, 0.1);
    let (d, s) =
        model_difference(&m.model, &m.covariance, &offline.solution.model, &offline.solution.covariance, offsets, 0.1);
    println!(
        "\nNode-set chain: recorded in {recorded:.1} s, replayed and solved in {:.1} s.",
        started.elapsed().as_secs_f64() - recorded
    );
    println!(
        "Against the simulation truth (gauge-aligned, 0.1 m grid): node-set model RMS {:.4} um, max {:.4} um; offline model RMS {:.4} um, max {:.4} um; predicted standard uncertainty RMS {:.4} um",
        chain.rms_m * 1e6,
        chain.max_m * 1e6,
        off.rms_m * 1e6,
        off.max_m * 1e6,
        chain.predicted_rms_m * 1e6
    );
    println!(
        "Node-set model vs offline model: RMS difference {:.4} um (two independent noise realisations; predicted {:.4} um)",
        d * 1e6,
        s * 1e6
    );
    Ok(())
}
