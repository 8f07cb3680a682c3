//! Issue 2, acceptance 4: what cannot be identified is named, and the identifiable combination
//! is still returned.

use nalgebra::Vector3;
use volcal::campaign::prepare;
use volcal::solve;
use volcal_formats::machine::{Machine, DEMO_MACHINE};
use volcal_formats::plan::sim_config;
use volcal_sim::{simulate, Plan};

#[test]
fn single_probe_offset_along_the_last_axis() {
    let m = Machine::parse(DEMO_MACHINE).unwrap();
    let plan = Plan { probe_offsets: vec![[0.0, 0.0, -0.15]], ..Plan::patent_example() };
    let mut cfg = sim_config(&m, plan, 5);
    cfg.machine.repeatability_m = 0.0;
    cfg.machine.centring_m = 0.0;
    cfg.interferometer.noise_m = 0.0;
    cfg.interferometer.resolution_m = 0.0;
    let out = simulate(&cfg, &[], 9).unwrap();
    let prep = prepare(&out.campaign, &m.layout.travel, &m.expansion).unwrap();
    let sol = solve(&m.layout, &prep.obs, &m.solve_options(), &[]).unwrap();
    let id = &sol.identifiability;
    for s in &id.statements {
        eprintln!("{s}");
    }
    assert!(id.extra_null_dim > 0);
    // The roll of Z acts only on a probe offset perpendicular to Z; the yaw of Y (which
    // carries Z) has the lever arm (0, 0, z) + p, parallel to its axis.
    assert_eq!(id.not_observed, vec!["ECY".to_string(), "ECZ".to_string()]);
    // Pitch and yaw of Z act through the offset exactly like straightness of Z.
    let has = |a: &str, b: &str| id.combinations.iter().any(|g| g.iter().any(|x| x == a) && g.iter().any(|x| x == b));
    assert!(has("EXZ", "EBZ"), "{:?}", id.combinations);
    assert!(has("EYZ", "EAZ"), "{:?}", id.combinations);
    assert_eq!(id.identified_functions, 17);
    assert!(id.statements.iter().any(|s| s.contains("ECZ") && s.contains("perpendicular")), "{:?}", id.statements);
    assert!(id.statements.iter().any(|s| s.contains("two different lengths along Z")), "{:?}", id.statements);
    // The solve still returns the identifiable combination: the volumetric error for the probe
    // offset that was measured is recovered.
    let p = Vector3::new(0.0, 0.0, -0.15);
    let (max, rms) = volcal_tests::gauge_distance(&sol.model, &cfg.machine.truth, m.gauge, &[p], 0.1);
    eprintln!("volumetric error at the measured offset: max {max:.3e} m, RMS {rms:.3e} m after removing the gauge");
    assert!(max < 1e-9, "{max}");
}

#[test]
fn beams_all_along_x_leave_most_functions_undetermined() {
    // A degenerate campaign: every beam parallel to X. Only the X components of the errors are
    // seen; the report must say which functions are missing instead of inventing them.
    use rand::SeedableRng;
    use volcal::campaign::{Campaign, CampaignMeta, ObsKind, Reading};
    let m = Machine::parse(DEMO_MACHINE).unwrap();
    let cfg = sim_config(&m, Plan::short(), 5);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mut readings = Vec::new();
    let n = Vector3::x();
    let p = Vector3::new(0.0, 0.0, -0.1);
    for (line, (y, z)) in
        [(0.1, -0.5), (0.4, -0.3), (0.7, -0.1), (0.2, -0.05), (0.6, -0.55), (0.35, -0.4)].into_iter().enumerate()
    {
        let origin = nalgebra::Point3::new(-0.2, y, z - 0.1);
        for k in 0..40 {
            let s = 0.21 + 0.95 * k as f64 / 39.0;
            let x = cfg.machine.indicated_for(&(origin + n * s), &p, &n, &mut rng);
            let actual = cfg.machine.actual(&x, &p, &mut rng);
            let l = cfg.interferometer.read(
                n.dot(&(actual - origin)),
                0.0,
                &volcal::environment::Air::standard(),
                &mut rng,
            );
            readings.push(Reading {
                kind: ObsKind::Beam,
                station: 0,
                line: line as u32,
                t_s: k as f64,
                l_m: l,
                x,
                p,
                air: None,
                machine_temp_c: None,
                velocity: None,
                beam_broken: false,
                source_line: 0,
            });
        }
    }
    let campaign = Campaign { meta: CampaignMeta::default(), readings };
    let prep = prepare(&campaign, &m.layout.travel, &m.expansion).unwrap();
    let sol = solve(&m.layout, &prep.obs, &m.solve_options(), &[]).unwrap();
    let id = &sol.identifiability;
    for s in &id.statements {
        eprintln!("{s}");
    }
    // Straightness of X in Y and Z and the roll of X have no component along X: not observed.
    for f in ["EYX", "EZX", "EAX"] {
        assert!(id.not_observed.iter().any(|x| x == f), "{f} should be reported: {:?}", id.not_observed);
    }
    assert!(id.identified_functions < 10, "{}", id.identified_functions);
    assert!(id.statements[0].contains("identified individually"));
}
