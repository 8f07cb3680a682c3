//! Faults (acceptance 5): the recorder killed with SIGKILL, an instrument node killed and
//! restarted mid-campaign, a topic that never appears, duplicated and out-of-order messages.
//! Each test runs the real node binaries over DDS on loopback, on its own ROS domain.

mod common;

use common::*;
use std::time::{Duration, Instant};
use volcal_bag::campaign;
use volcal_msgs::msg::{MachinePosition, SyncedPair, Trigger};
use volcal_msgs::std_msgs::msg::Header;
use volcal_msgs::{msg::Abscissa, topics};
use volcal_nodes::ros::{domain, now_ns, qos};

#[test]
fn recorder_killed_leaves_a_bag_readable_to_its_last_chunk() {
    let lease = domain::lease().unwrap();
    let dir = volcal_tests::scratch("fault-kill-recorder");
    let bag = dir.join("killed");
    let mut l = Launch::start(&launch_config("sim_campaign_short.yaml"), Some(&bag), lease.id, &[]);
    l.wait_for("the recorder to start", Duration::from_secs(60), |s| s.contains("[recorder] info: recording to"));
    l.wait_for("the campaign to start", Duration::from_secs(60), |s| s.contains("[sequencer] info: plan"));
    std::thread::sleep(Duration::from_secs(3));
    let pid = l.pid_of("recorder").unwrap();
    let killed_ns = now_ns();
    signal(pid, libc::SIGKILL);
    l.wait_for("the recorder's death", Duration::from_secs(10), |s| s.contains("recorder was killed by a signal"));
    l.interrupt();
    let (_, out) = l.wait(Duration::from_secs(60));

    let b = campaign::read_bag(&bag).unwrap_or_else(|e| panic!("{e:#}\n{out}"));
    let note = b.recovery_note.clone().expect("a killed recorder leaves an unclosed bag");
    assert!(note.contains("recovered") && note.contains("last complete chunk"), "{note}");
    assert!(!b.campaign.readings.is_empty(), "no pairs recovered: {note}");
    let last_ns = b.summary.last_ns.unwrap();
    let lost_s = (killed_ns - last_ns) as f64 * 1e-9;
    eprintln!("{note}\nlast recovered message {lost_s:.3} s before the kill");
    assert!(lost_s <= 1.0, "{lost_s} s of recording lost (the recorder flushes every 0.5 s)");
    // The command line says the same.
    let info = std::process::Command::new(volcal()).args(["bag", "info"]).arg(&bag).output().unwrap();
    let info = String::from_utf8_lossy(&info.stdout);
    assert!(info.contains("recovered") && info.contains("/campaign/pairs"), "{info}");
}

#[test]
fn instrument_restarted_mid_campaign_is_picked_up_again() {
    let lease = domain::lease().unwrap();
    let dir = volcal_tests::scratch("fault-restart");
    let bag = dir.join("restarted");
    let mut l =
        Launch::start(&launch_config("sim_campaign_short.yaml"), Some(&bag), lease.id, &["respawn_instruments:=true"]);
    let mut node = test_node("restart_watch", lease.id);
    let mut pairs = node.subscription::<SyncedPair>(topics::PAIRS, qos::data()).unwrap();
    l.wait_for("the campaign to start", Duration::from_secs(60), |s| s.contains("[sequencer] info: plan"));
    // Killed in the middle of a line, once its point 0 is paired: the respawned instrument
    // re-establishes its count at what it is asked next, the centring probe of point 1, which
    // is not recorded (before the pairing carried the loss over, the whole line then hung one
    // step off its origin with nothing flagged, chi2/dof 3e7: seen once in CI and once in 40 runs).
    let t = Instant::now();
    let (station, line) = 'watch: loop {
        node.wait(Duration::from_millis(1));
        while let Some(p) = pairs.next() {
            if p.station == 1 && p.point == 0 {
                break 'watch (p.station, p.line);
            }
        }
        assert!(t.elapsed() < Duration::from_secs(120), "no pair of station 1's point 0 within 120 s");
    };
    signal(l.pid_of("interferometer").unwrap(), libc::SIGKILL);
    l.wait_for("the respawn", Duration::from_secs(20), |s| s.contains("[launch] respawned interferometer"));
    let (st, out) = l.wait(Duration::from_secs(240));
    assert!(st.success(), "{out}");
    assert!(out.contains("the recorder confirmed all 960 acquired points"), "{out}");
    let b = campaign::read_bag(&bag).unwrap();
    assert!(b.recovery_note.is_none());
    assert_eq!(b.campaign.readings.len(), 960);
    let broken: Vec<(u32, u32)> =
        b.campaign.readings.iter().filter(|r| r.beam_broken).map(|r| (r.station, r.line)).collect();
    eprintln!("killed after station {station} beam {line} point 0; readings flagged beam_broken on lines {broken:?}");
    // The count restarted within that line (or at the start of the next, if the sequencer had
    // moved on to it), and the bag says so.
    assert!(
        broken.iter().any(|&(s, b)| s == station && (b == line || b == line + 1)),
        "the count restarted after station {station} beam {line} point 0 with no reading flagged there: {broken:?}\n{out}"
    );
    // The data are consistent: the solve fits to the instruments' noise.
    let (solved, _) = volcal_cli::commands::solve_cmd(
        &bag,
        &repo().join("launch_configs/machines/demo_cmm.yaml"),
        &dir.join("model.json"),
    )
    .unwrap();
    let r = solved.file.residuals.unwrap();
    if r.variance_factor >= 1.5 {
        // What a failure needs to be understood: the worst line's readings as recorded, and what
        // the nodes said (retries, the respawn's timing).
        let worst = r.lines.iter().max_by(|a, b| a.rms_m.total_cmp(&b.rms_m)).unwrap();
        eprintln!("worst line {worst:?}; its readings (t_s, l_m, x, beam_broken, source_line):");
        for x in b.campaign.readings.iter().filter(|x| (x.station, x.line) == (worst.station, worst.line)) {
            eprintln!("  {:.4} {:.9} {:?} {} {}", x.t_s, x.l_m, x.x, x.beam_broken, x.source_line);
        }
        eprintln!("launch output:\n{out}");
    }
    assert!(r.variance_factor < 1.5, "chi2/dof {} after the restart", r.variance_factor);
}

#[test]
fn a_topic_that_never_appears_is_reported_by_name() {
    let lease = domain::lease().unwrap();
    let dir = volcal_tests::scratch("fault-missing-topic");
    // The short campaign without its machine node.
    let cfg = repo().join("launch_configs");
    let yaml = format!(
        r#"
launch:
  - set_env: {{name: ROS_LOCALHOST_ONLY, value: "1"}}
  - node: {{exec: volcal_deflector, name: deflector, param: [{{name: machine, value: "{m}"}}]}}
  - node: {{exec: volcal_interferometer, name: interferometer, param: [{{name: machine, value: "{m}"}}]}}
  - node: {{exec: volcal_recorder, name: recorder, param: [{{name: bag, value: "{bag}"}}]}}
  - node:
      exec: volcal_sequencer
      name: sequencer
      on_exit: shutdown
      param:
        - {{name: machine, value: "{m}"}}
        - {{name: plan, value: "{p}"}}
        - {{name: topic_timeout_s, value: 3}}
"#,
        m = cfg.join("machines/demo_cmm.yaml").display(),
        p = cfg.join("plans/sim_short.yaml").display(),
        bag = dir.join("bag").display()
    );
    let file = dir.join("no_machine.yaml");
    std::fs::write(&file, yaml).unwrap();
    let t = Instant::now();
    let (st, out) = Launch::start(&file, None, lease.id, &[]).wait(Duration::from_secs(60));
    assert!(!st.success(), "{out}");
    assert!(out.contains("no publisher on topic /machine/position after 3.0 s"), "{out}");
    assert!(t.elapsed() < Duration::from_secs(30));
}

#[test]
fn duplicated_and_out_of_order_messages_do_not_corrupt_the_pairing() {
    use rand::seq::SliceRandom;
    use rand::SeedableRng;
    let lease = domain::lease().unwrap();
    let dir = volcal_tests::scratch("fault-duplicates");
    let bag = dir.join("dups");
    let yaml = "launch:\n  - arg: {name: bag}\n  - set_env: {name: ROS_LOCALHOST_ONLY, value: \"1\"}\n  - node: {exec: volcal_recorder, name: recorder, on_exit: shutdown, param: [{name: bag, value: \"$(var bag)\"}]}\n";
    let file = dir.join("recorder.yaml");
    std::fs::write(&file, yaml).unwrap();
    let mut l = Launch::start(&file, Some(&bag), lease.id, &[]);
    l.wait_for("the recorder", Duration::from_secs(60), |s| s.contains("recording to"));

    let mut node = test_node("fake_instruments", lease.id);
    let trig = node.publisher::<Trigger>(topics::TRIGGER, qos::commands()).unwrap();
    let abs = node.publisher::<Abscissa>(topics::ABSCISSA, qos::data()).unwrap();
    let pos = node.publisher::<MachinePosition>(topics::MACHINE_POSITION, qos::data()).unwrap();
    let mut pairs_sub = node.subscription::<SyncedPair>(topics::PAIRS, qos::data()).unwrap();
    node.wait_for_publishers(&[topics::PAIRS], Duration::from_secs(20)).unwrap();
    // Give the recorder's subscriptions time to match ours.
    let t = Instant::now();
    while t.elapsed() < Duration::from_secs(2) {
        node.wait(Duration::from_millis(50));
    }

    // 60 static points: a probe and a point trigger each, with the instrument and machine
    // answers; a fifth of all messages sent twice; everything shuffled across the topics.
    enum M {
        T(Trigger),
        A(Abscissa),
        P(MachinePosition),
    }
    let t0 = now_ns();
    let mut msgs = Vec::new();
    for i in 0..60u64 {
        for (id, ty) in [(1000 + 2 * i, Trigger::PROBE), (1001 + 2 * i, Trigger::POINT)] {
            let stamp = t0 + (i as i64) * 10_000_000 + if ty == Trigger::POINT { 1_000_000 } else { 0 };
            msgs.push(M::T(Trigger {
                header: Header::at(stamp, "machine"),
                trigger_id: id,
                trigger_type: ty,
                kind: Trigger::KIND_BEAM,
                station: 0,
                line: (i / 20) as u32,
                point: (i % 20) as u32,
                position_id: i,
            }));
            msgs.push(M::A(Abscissa {
                header: Header::at(stamp + 100_000, "deflector/0"),
                station: 0,
                beam: (i / 20) as u32,
                abscissa_m: i as f64 * 1e-2 + if ty == Trigger::PROBE { 7.0 } else { 0.0 },
                signal_strength: 1.0,
                beam_broken: false,
                trigger_id: id,
            }));
            msgs.push(M::P(MachinePosition {
                header: Header::at(stamp + 200_000, "machine"),
                x_m: i as f64,
                y_m: 0.5,
                z_m: -0.1,
                in_position: true,
                position_id: i,
                trigger_id: id,
                ..Default::default()
            }));
        }
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let n = msgs.len();
    let dups: Vec<usize> = (0..n).filter(|k| k % 5 == 0).collect();
    let mut order: Vec<usize> = (0..n).chain(dups.iter().cloned()).collect();
    order.shuffle(&mut rng);
    for k in order {
        match &msgs[k] {
            M::T(m) => trig.publish(m.clone()).unwrap(),
            M::A(m) => abs.publish(m.clone()).unwrap(),
            M::P(m) => pos.publish(m.clone()).unwrap(),
        }
    }
    // Wait for the 60 pairs to come back on /campaign/pairs, then stop the recorder.
    let mut got = 0;
    let t = Instant::now();
    while got < 60 && t.elapsed() < Duration::from_secs(30) {
        node.wait(Duration::from_millis(50));
        while pairs_sub.next().is_some() {
            got += 1;
        }
    }
    l.interrupt();
    let (_, out) = l.wait(Duration::from_secs(30));
    let b = campaign::read_bag(&bag).unwrap_or_else(|e| panic!("{e:#}\n{out}"));
    let r = &b.campaign.readings;
    assert_eq!(r.len(), 60, "{out}");
    for (i, p) in r.iter().enumerate() {
        // In acquisition order, each point paired with its own coordinates, no probe reading.
        assert_eq!(p.x.x, i as f64, "{out}");
        assert!((p.l_m - i as f64 * 1e-2).abs() < 1e-15, "a probe reading or a wrong partner: {p:?}");
        assert_eq!(p.line, (i / 20) as u32);
    }
    assert!(out.contains("duplicated"), "{out}");
    assert!(!out.contains(" 0 duplicated"), "the recorder did not see the duplicates:\n{out}");
}

/// A message on `/deflector/command` under the right type name that does not decode (a
/// publisher with another layout): the deflector reports it with topic and reason, skips it,
/// and still serves the valid command behind it.
#[test]
fn an_undecodable_message_is_reported_and_the_node_keeps_going() {
    use serde::{Deserialize, Serialize};
    use volcal_msgs::msg::{BeamCommand, BeamState};
    use volcal_msgs::RosMessage;

    /// One byte where a `BeamCommand` has a header, two ids and five numbers.
    #[derive(Serialize, Deserialize, Clone, Default, Debug)]
    struct Malformed {
        tag: u8,
    }
    impl RosMessage for Malformed {
        const PACKAGE: &'static str = BeamCommand::PACKAGE;
        const NAME: &'static str = BeamCommand::NAME;
        const TYPE_NAME: &'static str = BeamCommand::TYPE_NAME;
        const DEFINITION: &'static str = "uint8 tag\n";
        const SCHEMA: &'static str = "uint8 tag\n";
    }

    let lease = domain::lease().unwrap();
    let dir = volcal_tests::scratch("fault-undecodable");
    let yaml = "launch:\n  - set_env: {name: ROS_LOCALHOST_ONLY, value: \"1\"}\n  - node: {exec: volcal_deflector, name: deflector}\n";
    let file = dir.join("deflector.yaml");
    std::fs::write(&file, yaml).unwrap();
    let mut l = Launch::start(&file, None, lease.id, &[]);
    l.wait_for("the deflector", Duration::from_secs(60), |s| s.contains("node deflector on ROS_DOMAIN_ID"));

    let mut node = test_node("bad_commander", lease.id);
    let bad = node.publisher::<Malformed>(topics::DEFLECTOR_COMMAND, qos::commands()).unwrap();
    let good = node.publisher::<BeamCommand>(topics::DEFLECTOR_COMMAND, qos::commands()).unwrap();
    let mut states = node.subscription::<BeamState>(topics::DEFLECTOR_STATE, qos::latched()).unwrap();
    node.wait_for_publishers(&[topics::DEFLECTOR_STATE], Duration::from_secs(20)).unwrap();
    // Malformed and valid commands interleaved until the valid one is served (the first ones
    // may go out before the deflector's subscription has matched the publishers).
    let cmd = BeamCommand { station: 7, beam: 11, azimuth_rad: 0.1, elevation_rad: -0.05, ..Default::default() };
    let t = Instant::now();
    let mut sent_bad = 0u8;
    let settled = loop {
        bad.publish(Malformed { tag: sent_bad }).unwrap();
        sent_bad += 1;
        good.publish(cmd.clone()).unwrap();
        node.wait(Duration::from_millis(200));
        if let Some(s) = std::iter::from_fn(|| states.next()).find(|s| s.station == 7 && s.beam == 11 && s.settled) {
            break s;
        }
        assert!(t.elapsed() < Duration::from_secs(30), "no settled state for the valid command:\n{}", l.output());
    };
    assert!((settled.azimuth_rad - 0.1).abs() < 1e-3, "{settled:?}");
    let out = l.wait_for("the report of the undecodable messages", Duration::from_secs(10), |s| {
        s.contains("topic /deflector/command: message does not decode as volcal_msgs/msg/BeamCommand")
    });
    l.interrupt();
    let (_, out2) = l.wait(Duration::from_secs(30));
    let warned = out2.matches("message does not decode as volcal_msgs/msg/BeamCommand").count();
    assert!(warned >= 1, "no malformed message reported:\n{out}\n{out2}");
    assert!(out2.contains("message(s) did not decode as volcal_msgs/msg/BeamCommand"), "no count at the end:\n{out2}");
    eprintln!(
        "deflector: {warned} malformed command(s) of {sent_bad} sent reported and skipped, the valid command served"
    );
}
