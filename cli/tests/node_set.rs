//! End to end over DDS on loopback (acceptance 1): a short simulated campaign launched as ROS 2
//! nodes, recorded to a bag, replayed into the solver node, gives the same model as
//! `volcal simulate` + `volcal solve` of the same plan, within the noise; the model is served
//! to a late joiner on `/error_model`.
//!
//! Along the way (acceptance 2 and 3): the fresh bag decodes with `rosbags` and
//! `mcap-ros2-support`, and a CycloneDDS subscriber (Python `cyclonedds`, types declared from the
//! `.msg`, ROS 2's DDS names) receives `/interferometer/abscissa` with the same field values as
//! our recorder.

mod common;

use common::*;
use nalgebra::{Point3, Vector3};
use std::time::{Duration, Instant};
use volcal_cli::commands::{simulate_cmd, solve_cmd};
use volcal_cli::demo_chain::model_difference;
use volcal_formats::machine::Machine;
use volcal_formats::model_file::{self, ModelFile};
use volcal_formats::plan::sim_config;
use volcal_formats::solving::{compare_with_truth, probe_offsets};
use volcal_msgs::msg::ErrorModel as ErrorModelMsg;
use volcal_msgs::topics;
use volcal_nodes::ros::{domain, qos};
use volcal_sim::Plan;

/// Every sample CycloneDDS received equals the message our recorder got for that trigger.
fn check_cyclone_samples(bag: &std::path::Path, samples: &[serde_json::Value]) {
    use volcal_msgs::msg::Abscissa;
    assert!(samples.len() >= 100, "CycloneDDS received only {} samples", samples.len());
    let mut ours = std::collections::HashMap::new();
    volcal_bag::Bag::open(bag)
        .unwrap()
        .read(|m| {
            if m.topic == topics::ABSCISSA {
                let a: Abscissa = m.decode()?;
                ours.insert(a.trigger_id, a);
            }
            Ok(())
        })
        .unwrap();
    for s in samples {
        let id = s["trigger_id"].as_u64().unwrap();
        let a = ours.get(&id).unwrap_or_else(|| panic!("CycloneDDS got trigger {id}, the recorder did not"));
        assert_eq!(s["sec"].as_i64().unwrap(), a.header.stamp.sec as i64);
        assert_eq!(s["nanosec"].as_u64().unwrap(), a.header.stamp.nanosec as u64);
        assert_eq!(s["frame_id"].as_str().unwrap(), a.header.frame_id);
        assert_eq!(s["station"].as_u64().unwrap(), a.station as u64);
        assert_eq!(s["beam"].as_u64().unwrap(), a.beam as u64);
        assert_eq!(s["abscissa_m_bits"].as_u64().unwrap(), a.abscissa_m.to_bits());
        assert_eq!(s["signal_strength_bits"].as_u64().unwrap(), a.signal_strength.to_bits());
        assert_eq!(s["beam_broken"].as_bool().unwrap(), a.beam_broken);
    }
    eprintln!("CycloneDDS received {} abscissae, all equal to the recorded ones", samples.len());
}

#[test]
fn dds_campaign_matches_offline_simulate_and_solve() {
    let lease = domain::lease().unwrap();
    let dir = volcal_tests::scratch("node-set-e2e");
    let bag = dir.join("short");
    let machine_path = repo().join("launch_configs/machines/demo_cmm.yaml");
    let plan_path = repo().join("launch_configs/plans/sim_short.yaml");

    // Record, with a CycloneDDS subscriber listening.
    let cyclone = CycloneSubscriber::start(lease.id, 200, 120.0);
    let started = Instant::now();
    let (st, out) = Launch::start(&launch_config("sim_campaign_short.yaml"), Some(&bag), lease.id, &[])
        .wait(Duration::from_secs(240));
    assert!(st.success(), "launch failed:\n{out}");
    assert!(out.contains("the recorder confirmed all 960 acquired points"), "{out}");
    eprintln!("recorded in {:.1} s", started.elapsed().as_secs_f64());
    // A fresh recording also opens in the independent readers (the sample bags are checked by
    // independent_readers.rs).
    check_with_independent_readers(std::slice::from_ref(&bag));
    if let Some(c) = cyclone {
        check_cyclone_samples(&bag, &c.samples());
    }

    // Replay into the solver node; a subscriber joining after the model was published gets it.
    let model_path = dir.join("model_dds.json");
    let out_arg = format!("out:={}", model_path.display());
    let mut replay = Launch::start(&launch_config("replay.yaml"), Some(&bag), lease.id, &[&out_arg, "linger_s:=60"]);
    replay.wait_for("the solver publishing the model", Duration::from_secs(120), |l| {
        l.contains("published the model on /error_model")
    });
    let mut late = test_node("late_joiner", lease.id);
    let mut sub = late.subscription::<ErrorModelMsg>(topics::ERROR_MODEL, qos::latched()).unwrap();
    let t = Instant::now();
    let msg = loop {
        late.wait(Duration::from_millis(50));
        if let Some(m) = sub.next() {
            break m;
        }
        assert!(t.elapsed() < Duration::from_secs(30), "no model on /error_model for a late joiner");
    };
    replay.interrupt();
    let (st, out) = replay.wait(Duration::from_secs(30));
    assert!(st.success(), "replay failed:\n{out}");
    let file_dds = model_file::load(&model_path).unwrap().file;
    let from_msg: ModelFile = serde_json::from_str(&msg.model_json).unwrap();
    assert_eq!(from_msg, file_dds, "the published model is the written one");
    assert_eq!(msg.functions.len(), 18);
    assert_eq!(msg.covariance_upper.len(), file_dds.covariance.upper.len());

    // The same plan offline.
    let csv = dir.join("short.csv");
    let model_off_path = dir.join("model_offline.json");
    simulate_cmd(&machine_path, Some(&plan_path), 1, &csv, None, &Default::default()).unwrap();
    let (solved_off, _) = solve_cmd(&csv, &machine_path, &model_off_path).unwrap();

    let dds = model_file::load(&model_path).unwrap();
    let off = (&solved_off.solution.model, solved_off.solution.uncertainty());
    let machine = Machine::load(&machine_path).unwrap();
    let plan: Plan = volcal_formats::plan::load_plan(Some(&plan_path)).unwrap();
    let truth = sim_config(&machine, plan, 1).machine.truth;
    let campaign = volcal_bag::campaign::load_campaign(&bag).unwrap();
    assert_eq!(campaign.readings.len(), 960);
    let offsets = probe_offsets(&campaign);
    assert_eq!(offsets.len(), 3);
    for (name, m, c) in [("DDS chain", &dds.model, dds.uncertainty()), ("offline", off.0, off.1)] {
        let cmp = compare_with_truth(m, &c, &truth, machine.gauge, &offsets, 0.1);
        eprintln!(
            "{name} vs truth: RMS {:.3} um, max {:.3} um, predicted sigma RMS {:.3} um",
            cmp.rms_m * 1e6,
            cmp.max_m * 1e6,
            cmp.predicted_rms_m * 1e6
        );
        assert!(
            cmp.rms_m < 2.0 * cmp.predicted_rms_m,
            "{name}: error {} vs predicted {}",
            cmp.rms_m,
            cmp.predicted_rms_m
        );
    }
    let (d, s) = model_difference(&dds.model, &dds.covariance, off.0, off.1.covariance, &offsets, 0.1);
    eprintln!("DDS chain vs offline: RMS difference {:.3} um, predicted {:.3} um", d * 1e6, s * 1e6);
    assert!(d < 2.0 * s, "models differ by {d} m RMS, more than twice the predicted {s} m");
    assert!(dds.file.identifiability.extra_null_dim == 0, "all 21 functions identified");
    // Mispaired points would show as residuals far beyond the instruments' noise.
    let r = dds.file.residuals.as_ref().unwrap();
    eprintln!("DDS chain residuals: RMS {:.4} um, chi2/dof {:.3}", r.rms_m * 1e6, r.variance_factor);
    assert!(r.variance_factor < 1.5, "chi2/dof {} of the DDS campaign", r.variance_factor);
}

#[test]
fn tracer_campaign_over_dds_records_ranges_that_solve_like_offline() {
    let lease = domain::lease().unwrap();
    let dir = volcal_tests::scratch("node-set-tracer");
    let bag = dir.join("tracer");
    let machine_path = repo().join("launch_configs/machines/demo_cmm.yaml");
    let plan_path = repo().join("launch_configs/plans/tracer_short.yaml");
    let (st, out) = Launch::start(&launch_config("sim_tracer_short.yaml"), Some(&bag), lease.id, &[])
        .wait(Duration::from_secs(240));
    assert!(st.success(), "launch failed:\n{out}");
    assert!(out.contains("the recorder confirmed all 432 acquired points"), "{out}");
    let campaign = volcal_bag::campaign::load_campaign(&bag).unwrap();
    assert_eq!(campaign.readings.len(), 432);
    assert!(campaign.readings.iter().all(|r| r.kind == volcal::campaign::ObsKind::Range));
    let (dds, _) = solve_cmd(&bag, &machine_path, &dir.join("model_dds.json")).unwrap();
    let csv = dir.join("tracer.csv");
    simulate_cmd(&machine_path, Some(&plan_path), 1, &csv, None, &Default::default()).unwrap();
    let (off, _) = solve_cmd(&csv, &machine_path, &dir.join("model_offline.json")).unwrap();
    let (rd, ro) = (dds.file.residuals.unwrap(), off.file.residuals.unwrap());
    eprintln!(
        "tracer over DDS: RMS {:.4} um, chi2/dof {:.3}; offline: RMS {:.4} um, chi2/dof {:.3}",
        rd.rms_m * 1e6,
        rd.variance_factor,
        ro.rms_m * 1e6,
        ro.variance_factor
    );
    assert!(rd.variance_factor < 1.5, "chi2/dof {} of the tracer campaign over DDS", rd.variance_factor);
    // The same plan identifies the same functions, whichever way it was acquired.
    assert_eq!(dds.file.identifiability.identified_functions, off.file.identifiability.identified_functions);
    assert_eq!(dds.file.stations.len(), 4);
}

#[test]
fn on_the_fly_pairs_match_the_simulated_truth_at_their_stamps() {
    // Instruments sampling freely at 1 kHz (batches of 10) while the machine runs along the
    // beams; the recorder pairs by timestamp interpolation. With the simulation truth recorded,
    // each pair's reading must equal the true length along the true beam at the recorded
    // coordinates, up to a constant per beam (the counter's zero) and the interferometer noise:
    // a timing error of dt would show as speed * dt.
    let lease = domain::lease().unwrap();
    let dir = volcal_tests::scratch("node-set-otf");
    let bag = dir.join("otf");
    let plan = format!("plan:={}", repo().join("launch_configs/plans/otf_sample.yaml").display());
    let args = [
        plan.as_str(),
        "speed_mps:=1.0",
        "sample_rate_hz:=1000",
        "machine_rate_hz:=1000",
        "batch:=10",
        "record_truth:=true",
    ];
    let (st, out) = Launch::start(&launch_config("sim_campaign_short.yaml"), Some(&bag), lease.id, &args)
        .wait(Duration::from_secs(240));
    assert!(st.success(), "launch failed:\n{out}");
    assert!(out.contains("the recorder confirmed all 4 on-the-fly segments"), "{out}");
    let machine = Machine::load(&repo().join("launch_configs/machines/demo_cmm.yaml")).unwrap();
    let truth = sim_config(&machine, Plan::default(), 1).machine.truth;
    let mut beams = std::collections::HashMap::new();
    let mut pairs = Vec::new();
    volcal_bag::Bag::open(&bag)
        .unwrap()
        .read(|m| {
            if m.topic == topics::TRUTH_BEAM {
                let b: volcal_msgs::msg::BeamState = m.decode()?;
                beams.insert(b.beam, (Point3::from(b.origin_m), Vector3::from(b.direction)));
            } else if m.topic == topics::PAIRS {
                pairs.push(m.decode::<volcal_msgs::msg::SyncedPair>()?);
            }
            Ok(())
        })
        .unwrap();
    assert!(pairs.len() > 2000, "{} pairs\n{out}", pairs.len());
    let mut by_line: std::collections::BTreeMap<u32, Vec<f64>> = Default::default();
    for p in &pairs {
        assert_eq!(p.pairing, volcal_msgs::msg::SyncedPair::PAIRING_INTERPOLATED);
        assert_ne!(p.trigger_id, 0, "an interpolated pair names the trigger that ended its segment");
        let (o, d) = beams[&p.line];
        let actual = truth.exact_position(&Point3::from(p.position_m), &Vector3::from(p.probe_offset_m));
        by_line.entry(p.line).or_default().push(p.l_m - d.dot(&(actual - o)));
    }
    for (line, r) in &by_line {
        let mean = r.iter().sum::<f64>() / r.len() as f64;
        let sd = (r.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / r.len() as f64).sqrt();
        eprintln!("beam {line}: {} pairs, reading minus true length: sd {:.4} um", r.len(), sd * 1e6);
        // Interferometer noise 0.05 um, resolution 1 nm; at 1 m/s a 1 us timing error is 1 um.
        assert!(sd < 0.1e-6, "beam {line}: sd {sd} m");
    }
}
