//! Issue 13 item 7: effects whose signatures look alike, told apart head to head, on the
//! diagnosis plan measured on the fly and at rest, over seeds that no threshold or strength
//! here was tuned on (`SEEDS`, disjoint from the 0..20 of `diagnose_catalogue`).
//!
//! - latency against reversal: a latency scales with the speed and vanishes at rest; a
//!   backlash follows the sign of the motion at any speed;
//! - air refraction against setup drift: the air error follows the recorded air (here an
//!   air-conditioning cycle, or a steady rise), a drift follows the time at each station;
//! - a 0.1 mm change of the reflector offset, which shows only through the lever arms of the
//!   angular errors.
//!
//! The signal-to-noise ratio of each run is measured as in `diagnose_catalogue` (the largest
//! per-line RMS of the residual change a rigid-body fit leaves, over the reading uncertainty).
//! A run whose SNR is at least 3 must be named correctly (the effect first); one below 1
//! carries no signature in any single line and must name nothing else (the effect itself may
//! still be found from all lines together); in between the data decide neither way, and the
//! run is only reported. The competing effect must never be named first. Per case at
//! least 4 of the 5 seeds must be right (the catalogue's 19 of 20, on fewer seeds).
//!
//! `cargo test --release -p volcal_tests --test diagnose_head_to_head -- --nocapture` prints
//! README's table.

use volcal_tests::diagnosis::{self, Scenario};

/// Never tuned against: the strengths below come from the catalogue's SNR-3 calibration on
/// seeds 0..20 or from the issue's own cases.
const SEEDS: std::ops::Range<u64> = 500..505;

struct Case {
    label: &'static str,
    sc: Scenario,
    strength: f64,
    /// The effect the data could be mistaken for.
    competitor: &'static str,
}

fn cases(at_rest: bool) -> Vec<Case> {
    let s = |id, spec| Scenario { at_rest, ..Scenario::new(id, spec, 1.0) };
    let std_machine = |label, id, spec, strength, competitor| Case { label, sc: s(id, spec), strength, competitor };
    vec![
        std_machine("latency 20 us", "latency", "latency:latency_s={a}", 20e-6, "reversal"),
        std_machine("latency 6.3 us", "latency", "latency:latency_s={a}", 6.27e-6, "reversal"),
        std_machine(
            "reversal 1.5 um (X)",
            "reversal",
            "reversal:backlash_x_m={a},backlash_y_m=0,backlash_z_m=0",
            1.5e-6,
            "latency",
        ),
        Case {
            label: "air cycle +-0.5 K / 30 min, uncompensated",
            sc: Scenario { air_cycle_per_unit: 1.0, ..s("air_refraction", "air_refraction") },
            strength: 0.5,
            competitor: "setup_drift",
        },
        Case {
            label: "air rising 30 K/h, uncompensated",
            sc: Scenario { air_rate_per_unit: 1.0, ..s("air_refraction", "air_refraction") },
            strength: 30.0,
            competitor: "setup_drift",
        },
        std_machine(
            "setup drift 17.4 nm/s (X, Z)",
            "setup_drift",
            "setup_drift:vx_m_per_s={a},vy_m_per_s=0,vz_m_per_s={a}",
            17.4e-9,
            "air_refraction",
        ),
        Case {
            label: "probe offset change 0.1 mm (Z, precision)",
            sc: Scenario { precision: true, ..s("probe_offset", "probe_offset:dx_m=0,dy_m=0,dz_m={a}") },
            strength: -1e-4,
            competitor: "-",
        },
    ]
}

/// What one case gave over the seeds.
struct Tally {
    row: String,
    failures: Vec<String>,
}

fn judge(case: &Case) -> Tally {
    let acq = if case.sc.at_rest { "at rest" } else { "on the fly" };
    let (mut right, mut judged, mut competitor_first, mut floor) = (0, 0, 0, 0);
    let (mut snr_min, mut snr_max) = (f64::INFINITY, 0.0f64);
    let mut named = Vec::new();
    let (mut map_with, mut map_clean) = (0.0, 0.0);
    for seed in SEEDS {
        let snr = diagnosis::snr(&case.sc, case.strength, seed);
        snr_min = snr_min.min(snr);
        snr_max = snr_max.max(snr);
        let r = diagnosis::run(&case.sc, case.strength, seed);
        let ids: Vec<&str> = r.diagnosis.effects.iter().map(|e| e.id.as_str()).collect();
        let first = ids.first().copied();
        let verdict = if snr >= 3.0 {
            judged += 1;
            first == Some(case.sc.id)
        } else if snr < 1.0 {
            // No per-line signature: a false alarm if anything else is named. (The effect
            // itself can still be found from many lines together: an air cycle is.)
            judged += 1;
            first.is_none() || first == Some(case.sc.id)
        } else {
            false
        };
        right += verdict as usize;
        competitor_first += (first == Some(case.competitor)) as usize;
        floor += (r.diagnosis.rms_after_m <= 1.1 * r.rms_clean_m) as usize;
        // What ignoring the effect costs: the map of the plain fit against the truth, with and
        // without the effect in the same readings.
        let clean = diagnosis::run(&case.sc, 0.0, seed);
        map_with += r.map_error_before.powi(2);
        map_clean += clean.map_error_before.powi(2);
        eprintln!(
            "{} ({acq}) seed {seed}: SNR {snr:.2}, named {ids:?}, RMS {:.4} -> {:.4} um (clean {:.4}), map error {:.4} um (clean {:.4})",
            case.label,
            r.diagnosis.rms_before_m * 1e6,
            r.diagnosis.rms_after_m * 1e6,
            r.rms_clean_m * 1e6,
            r.map_error_before * 1e6,
            clean.map_error_before * 1e6
        );
        named.push(if ids.is_empty() { "nothing".to_string() } else { ids.join("+") });
    }
    let n = SEEDS.end - SEEDS.start;
    let mut names: Vec<(String, usize)> = Vec::new();
    for x in named {
        match names.iter_mut().find(|(y, _)| *y == x) {
            Some(e) => e.1 += 1,
            None => names.push((x, 1)),
        }
    }
    let names: Vec<String> = names.iter().map(|(x, k)| format!("{x} {k}/{n}")).collect();
    let (map_with, map_clean) = ((map_with / n as f64).sqrt(), (map_clean / n as f64).sqrt());
    let expected = if snr_min >= 3.0 {
        case.sc.id
    } else if snr_max < 1.0 {
        "nothing, or the effect (no line signature)"
    } else {
        "either (SNR 1 to 3)"
    };
    let row = format!(
        "| {acq} | {} | {snr_min:.2} to {snr_max:.2} | {expected} | {} | {right}/{judged} | {competitor_first}/{n} | {floor}/{n} | {:.3} (clean {:.3}) |",
        case.label,
        names.join(", "),
        map_with * 1e6,
        map_clean * 1e6
    );
    let mut failures = Vec::new();
    if competitor_first > 0 {
        failures.push(format!("{} ({acq}): {} named first in {competitor_first} seeds", case.label, case.competitor));
    }
    if judged - right > 1 {
        failures.push(format!("{} ({acq}): right in {right} of {judged} judged seeds", case.label));
    }
    Tally { row, failures }
}

fn head_to_head(at_rest: bool) {
    let (mut rows, mut failures) = (Vec::new(), Vec::new());
    for case in cases(at_rest) {
        let t = judge(&case);
        eprintln!("{}", t.row);
        rows.push(t.row);
        failures.extend(t.failures);
    }
    eprintln!(
        "| acquisition | injected | SNR over the seeds | expected | named first (seeds) | right | competitor first | RMS at floor | map error RMS, um |"
    );
    for r in &rows {
        eprintln!("{r}");
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn look_alikes_on_the_fly() {
    head_to_head(false);
}

#[test]
fn look_alikes_at_rest() {
    head_to_head(true);
}
