//! Issue 6 acceptance: the diagnosis on campaigns hiding one catalogue effect at a
//! signal-to-noise ratio of 3 (see `volcal_tests::diagnosis` for the definition), over 20 seeds
//! each; clean campaigns; two effects combined; an effect outside the catalogue.
//!
//! Per effect: named first in at least 19 of 20 seeds; its primary parameters within two
//! standard uncertainties of the truth in at least 90 % of the cases, with a mean squared
//! standardised error at most 2 (the uncertainties are honest); the hyper-parameters found from
//! the data (period, place of a beam break) right in at least 19 seeds; after the refit the
//! residual RMS within 10 % of the clean campaign's (the noise floor) in at least 19 seeds; and
//! the identified error map closer to the truth over the seeds (or unchanged, to 1 %, for the
//! effects the rigid-body model does not absorb).

use volcal_tests::diagnosis::{self, Scenario};

const SEEDS: u64 = 20;

fn scenario(id: &str) -> Scenario {
    diagnosis::scenarios().into_iter().find(|s| s.id == id).unwrap()
}

fn catalogue_effect(id: &str) {
    let sc = scenario(id);
    let (a, snr_min) = diagnosis::strength_for_snr3(&sc, 0..SEEDS);
    let (mut first, mut located, mut floor, mut closer) = (0, 0, 0, 0);
    let (mut z_in, mut z_n, mut z2) = (0, 0, 0.0);
    let (mut map_before, mut map_after) = (0.0, 0.0);
    for seed in 0..SEEDS {
        let r = diagnosis::run(&sc, a, seed);
        let c = diagnosis::check(&sc, &r);
        let names: Vec<&str> = r.diagnosis.effects.iter().map(|e| e.id.as_str()).collect();
        eprintln!(
            "{id} seed {seed}: found {names:?}, z {:?}, rms {:.4} -> {:.4} um (clean {:.4}), map error {:.4} -> {:.4} um",
            c.z.iter().map(|z| format!("{z:.2}")).collect::<Vec<_>>(),
            r.diagnosis.rms_before_m * 1e6,
            r.diagnosis.rms_after_m * 1e6,
            r.rms_clean_m * 1e6,
            r.map_error_before * 1e6,
            r.map_error_after * 1e6
        );
        first += c.named_first as usize;
        located += c.located as usize;
        floor += c.rms_at_floor as usize;
        closer += c.map_closer as usize;
        for z in &c.z {
            z_n += 1;
            z_in += (z.abs() <= 2.0) as usize;
            z2 += z * z;
        }
        map_before += r.map_error_before.powi(2);
        map_after += r.map_error_after.powi(2);
    }
    let (map_before, map_after) = ((map_before / SEEDS as f64).sqrt(), (map_after / SEEDS as f64).sqrt());
    let mean_z2 = z2 / z_n.max(1) as f64;
    eprintln!(
        "{id} at strength {a:.4e} (SNR >= {snr_min:.2} in every seed): named first {first}/{SEEDS}, parameters within 2 sigma {z_in}/{z_n} (mean z^2 {mean_z2:.2}), hyper-parameters {located}/{SEEDS}, RMS at the floor {floor}/{SEEDS}, map closer {closer}/{SEEDS}, RMS map error {:.4} -> {:.4} um",
        map_before * 1e6,
        map_after * 1e6
    );
    assert!(first >= 19, "{id}: named first in {first} of {SEEDS} seeds");
    assert!(z_n > 0 && z_in as f64 >= 0.9 * z_n as f64, "{id}: {z_in} of {z_n} parameters within 2 sigma");
    assert!(mean_z2 <= 2.0, "{id}: mean squared standardised error {mean_z2:.2}");
    assert!(located >= 19, "{id}: hyper-parameters right in {located} of {SEEDS} seeds");
    assert!(floor >= 19, "{id}: residual RMS at the noise floor in {floor} of {SEEDS} seeds");
    assert!(
        map_after < map_before || (map_after - map_before).abs() <= 0.01 * map_before,
        "{id}: RMS map error over the seeds {:.4} -> {:.4} um",
        map_before * 1e6,
        map_after * 1e6
    );
}

#[test]
fn air_refraction() {
    catalogue_effect("air_refraction");
}

#[test]
fn material_expansion() {
    catalogue_effect("material_expansion");
}

#[test]
fn setup_drift() {
    catalogue_effect("setup_drift");
}

#[test]
fn latency() {
    catalogue_effect("latency");
}

#[test]
fn reversal() {
    catalogue_effect("reversal");
}

#[test]
fn periodic_pitch() {
    catalogue_effect("periodic_pitch");
}

#[test]
fn nonrigid() {
    catalogue_effect("nonrigid");
}

#[test]
fn probe_offset() {
    catalogue_effect("probe_offset");
}

#[test]
fn beam_break() {
    catalogue_effect("beam_break");
}

#[test]
fn cyclic_nonlinearity() {
    catalogue_effect("cyclic_nonlinearity");
}

/// Clean campaigns, standard and precision setups: nothing reported in at least 19 of 20.
#[test]
fn clean_campaigns_raise_no_alarm() {
    for precision in [false, true] {
        let sc = Scenario { precision, ..scenario("latency") };
        let mut quiet = 0;
        for seed in 0..SEEDS {
            let r = diagnosis::run(&sc, 0.0, seed);
            let names: Vec<&str> = r.diagnosis.effects.iter().map(|e| e.id.as_str()).collect();
            eprintln!(
                "clean (precision {precision}) seed {seed}: found {names:?}, chi2/dof {:.3}{}",
                r.diagnosis.before.stats.variance_factor,
                if r.diagnosis.unexplained.is_some() { ", unexplained excess" } else { "" }
            );
            quiet += r.diagnosis.effects.is_empty() as usize;
        }
        eprintln!("clean (precision {precision}): nothing reported in {quiet}/{SEEDS}");
        assert!(quiet >= 19, "clean (precision {precision}): nothing reported in only {quiet} of {SEEDS}");
    }
}

/// Setup drift and air refraction together, each at its SNR-3 strength: both found.
#[test]
fn two_effects_combined_are_both_found() {
    let drift = scenario("setup_drift");
    let air = scenario("air_refraction");
    let (ad, aa) = (diagnosis::strength_for_snr3(&drift, 0..SEEDS).0, diagnosis::strength_for_snr3(&air, 0..SEEDS).0);
    let spec: &'static str =
        Box::leak(format!("{}+air_refraction", drift.spec.replace("{a}", &ad.to_string())).into_boxed_str());
    let sc = Scenario { air_rate_per_unit: aa, ..Scenario::new("setup_drift+air_refraction", spec, 1.0) };
    let mut both = 0;
    let mut floor = 0;
    for seed in 0..SEEDS {
        let r = diagnosis::run(&sc, 1.0, seed);
        let names: Vec<&str> = r.diagnosis.effects.iter().map(|e| e.id.as_str()).collect();
        eprintln!(
            "combined seed {seed}: found {names:?}, rms {:.4} -> {:.4} um (clean {:.4})",
            r.diagnosis.rms_before_m * 1e6,
            r.diagnosis.rms_after_m * 1e6,
            r.rms_clean_m * 1e6
        );
        both += (names.contains(&"setup_drift") && names.contains(&"air_refraction")) as usize;
        floor += (r.diagnosis.rms_after_m <= 1.1 * r.rms_clean_m) as usize;
    }
    eprintln!("combined: both found in {both}/{SEEDS}, RMS at the floor in {floor}/{SEEDS}");
    assert!(both >= 19, "both effects found in only {both} of {SEEDS}");
    assert!(floor >= 19, "RMS at the floor in only {floor} of {SEEDS}");
}

/// A dent in a guideway (outside the catalogue) at SNR 3: no catalogue name is forced on it;
/// the report says the residual is unexplained and that it is concentrated in the cell of the
/// volume that holds the dent.
#[test]
fn an_effect_outside_the_catalogue_is_reported_unexplained_where_it_is() {
    let sc = diagnosis::unmodelled();
    let (a, _) = diagnosis::strength_for_snr3(&sc, 0..SEEDS);
    let cell = "X high third, Y low third, Z high third";
    let (mut unnamed, mut located) = (0, 0);
    for seed in 0..SEEDS {
        let r = diagnosis::run(&sc, a, seed);
        let d = &r.diagnosis;
        let names: Vec<&str> = d.effects.iter().map(|e| e.id.as_str()).collect();
        let top = d.remaining.iter().find(|l| l.kind == "volume").map(|l| l.label.clone()).unwrap_or_default();
        eprintln!("bump seed {seed}: found {names:?}, most concentrated cell {top:?}; {:?}", d.unexplained);
        unnamed += (names.is_empty() && d.unexplained.is_some()) as usize;
        located += d.unexplained.as_ref().is_some_and(|u| u.contains(cell)) as usize;
    }
    eprintln!(
        "bump at amplitude {a:.3e} m: unexplained and unnamed in {unnamed}/{SEEDS}, located in {located}/{SEEDS}"
    );
    assert!(unnamed >= 19, "unexplained without a catalogue name in only {unnamed} of {SEEDS}");
    assert!(located >= 19, "the report points at the dent's cell in only {located} of {SEEDS}");
}
