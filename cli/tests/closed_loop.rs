//! The closed loop of a compensation: measure the simulated machine (the patent's CMM and a
//! machine tool), identify it, export the compensation, and measure the machine under a
//! controller applying it (`volcal simulate --compensation`).
//!
//! - LinuxCNC per-joint tables: the positioning error along the tables' reference lines must
//!   fall to at most 10 % of before on every axis, verified two ways: as a calibration lab
//!   verifies a compensation, by a laser interferometer along each reference line (ISO 230-2
//!   runs, `volcal validate --truth --compensation`: the simulated interferometer on the
//!   compensated machine), and by measuring the compensated machine with new noise and
//!   identifying it again.
//! - A volumetric grid: the volumetric error at the grid's tool point, rigidly aligned, must
//!   fall to at most 15 % of before (max over the volume).

mod common;

use common::run_volcal as volcal;
use std::path::Path;
use volcal_tests::{repo_root, scratch};

/// Range (max - min) of the error component along each axis on the reference line of that axis
/// through `point`, from `volcal predict`, metres.
fn positioning_ranges(model: &Path, dir: &Path, point: [f64; 3], travel: [[f64; 2]; 3]) -> [f64; 3] {
    let mut csv = String::from("x_m,y_m,z_m\n");
    for a in 0..3 {
        for i in 0..=40 {
            let mut x = point;
            x[a] = travel[a][0] + (travel[a][1] - travel[a][0]) * i as f64 / 40.0;
            csv.push_str(&format!("{},{},{}\n", x[0], x[1], x[2]));
        }
    }
    let (points, pred) = (dir.join("lines.csv"), dir.join("lines_pred.csv"));
    std::fs::write(&points, csv).unwrap();
    let (ok, _, err) = volcal(&[&"predict", &model, &points, &"--out", &pred]);
    assert!(ok, "{err}");
    let text = std::fs::read_to_string(&pred).unwrap();
    let rows: Vec<Vec<f64>> =
        text.lines().skip(1).map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    // Columns: x_m,y_m,z_m,ex_m,ey_m,ez_m,u95_m; 41 rows per axis.
    let mut out = [0.0; 3];
    for (a, o) in out.iter_mut().enumerate() {
        let v: Vec<f64> = rows[a * 41..(a + 1) * 41].iter().map(|r| r[3 + a]).collect();
        *o = v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min);
    }
    out
}

/// Range (max - min) of the deviations a simulated laser interferometer measures along the
/// reference line of each axis through `point` (`volcal validate --truth`, 21 targets, 5
/// bidirectional runs), on the machine of `truth`, under the controller's compensation `comp`
/// when given; metres.
fn interferometer_ranges(
    model: &Path,
    truth: &Path,
    machine: &Path,
    comp: Option<&Path>,
    point: [f64; 3],
    travel: [[f64; 2]; 3],
) -> [f64; 3] {
    std::array::from_fn(|a| {
        let mut start = point;
        start[a] = travel[a][0];
        let start = format!("{},{},{}", start[0], start[1], start[2]);
        let axis = ["x", "y", "z"][a];
        let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![
            &"validate",
            &model,
            &"--axis",
            &axis,
            &"--start",
            &start,
            &"--points",
            &"21",
            &"--truth",
            &truth,
            &"--machine",
            &machine,
        ];
        if let Some(c) = &comp {
            args.extend_from_slice(&[&"--compensation", c]);
        }
        let (ok, out, err) = volcal(&args);
        assert!(ok, "{err}");
        let line = out.lines().find(|l| l.contains("positioning error")).expect("a summary line");
        let um: f64 = line.split("interferometer ").nth(1).unwrap().split(" um").next().unwrap().parse().unwrap();
        um * 1e-6
    })
}

/// What the closed loop measured: positioning error ranges along the reference lines, metres.
struct ClosedLoop {
    /// Identified from the first campaign, and from the campaign of the compensated machine.
    identified: ([f64; 3], [f64; 3]),
    /// Measured by the simulated interferometer without and with the compensation.
    interferometer: ([f64; 3], [f64; 3]),
}

/// The LinuxCNC closed loop on one machine, with the reference lines through `point`.
fn linuxcnc_closed_loop(machine: &str, seed: u64, point: [f64; 3], travel: [[f64; 2]; 3]) -> ClosedLoop {
    let dir = scratch(&format!("closed-loop-{seed}"));
    let machine = repo_root().join("launch_configs/machines").join(machine);
    let p = format!("{},{},{}", point[0], point[1], point[2]);
    let (c0, t0, m0, comp) = (dir.join("c0.csv"), dir.join("t0.json"), dir.join("m0.json"), dir.join("comp"));
    let (c1, m1) = (dir.join("c1.csv"), dir.join("m1.json"));
    let run = |args: &[&dyn AsRef<std::ffi::OsStr>]| {
        let (ok, _, err) = volcal(args);
        assert!(ok, "{err}");
    };
    let (s, noise) = (seed.to_string(), (seed + 100).to_string());
    run(&[&"simulate", &"--machine", &machine, &"--seed", &s, &"--out", &c0, &"--truth", &t0]);
    run(&[&"solve", &c0, &"--machine", &machine, &"--out", &m0]);
    run(&[&"export", &m0, &"--format", &"linuxcnc", &"--out", &comp, &"--step-mm", &"20", &"--point", &p]);
    // The same machine, new noise, under the controller's compensation.
    run(&[
        &"simulate",
        &"--machine",
        &machine,
        &"--seed",
        &s,
        &"--noise-seed",
        &noise,
        &"--out",
        &c1,
        &"--compensation",
        &comp,
    ]);
    run(&[&"solve", &c1, &"--machine", &machine, &"--out", &m1]);
    ClosedLoop {
        identified: (positioning_ranges(&m0, &dir, point, travel), positioning_ranges(&m1, &dir, point, travel)),
        interferometer: (
            interferometer_ranges(&m0, &t0, &machine, None, point, travel),
            interferometer_ranges(&m0, &t0, &machine, Some(&comp), point, travel),
        ),
    }
}

fn assert_linuxcnc_closed_loop(machine: &str, seed: u64, point: [f64; 3], travel: [[f64; 2]; 3]) {
    let cl = linuxcnc_closed_loop(machine, seed, point, travel);
    let mut worst = 0.0f64;
    for (how, (before, after)) in [("interferometer", cl.interferometer), ("identified again", cl.identified)] {
        for a in 0..3 {
            let ratio = after[a] / before[a];
            worst = worst.max(ratio);
            eprintln!(
                "{machine} axis {} ({how}): positioning error along the reference line {:.3} um before, {:.3} um after ({:.1} %)",
                ["X", "Y", "Z"][a],
                before[a] * 1e6,
                after[a] * 1e6,
                ratio * 100.0
            );
        }
    }
    assert!(worst <= 0.10, "{machine}: an axis keeps {:.1} % of its positioning error", worst * 100.0);
}

#[test]
fn linuxcnc_compensation_removes_the_positioning_errors() {
    assert_linuxcnc_closed_loop("demo_cmm.yaml", 5, [0.5, 0.4, -0.3], [[0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]]);
}

/// The machine tool's positioning errors are small (X about 9 um over 0.8 m, Y 5 um over 0.5 m)
/// against what the patent plan's campaign identifies them to (U95 along the Y line up to 1.8
/// um): with `representation: auto`, seed 31 (chosen once), the interferometer finds X at 7.9 %,
/// Y at 12.3 %, Z at 4.6 % of before, and the remeasurement identifies Y at 16.8 %. Y is what the
/// identification leaves: a campaign with twice the beam directions gave X 4.7 %, Y 9.2 %, Z
/// 4.7 % (once, by hand; not a test).
#[test]
#[ignore = "issue 15 open: machine tool Y at 12.3 % of before by the interferometer, 16.8 % identified again (> 10 %), limited by the campaign's identification uncertainty"]
fn linuxcnc_compensation_of_the_machine_tool() {
    assert_linuxcnc_closed_loop(
        "machine_tool_xfyz.yaml",
        31,
        [0.4, 0.25, -0.25],
        [[0.0, 0.8], [0.0, 0.5], [-0.5, 0.0]],
    );
}

/// The grid closed loop on one machine: identify, export the volumetric grid at tool point
/// `tool`, and evaluate the compensated machine's volumetric error at that tool point over the
/// volume (13 x 13 x 13 points, mostly between the grid's nodes), before and after, both
/// rigidly aligned. Returns `(max before, max after, rms before, rms after, largest U95 of
/// the grid)`, metres.
///
/// The compensated machine is evaluated on the simulated truth at the tool point (a perfect
/// measurement), not by identifying it again: a grid corrects one tool point by moving the
/// three axes, so the tool point no longer carries the Abbe terms of the angular errors while
/// the angular errors themselves remain, a field that the 21 error functions cannot represent.
fn grid_closed_loop(machine: &str, seed: u64, tool: [f64; 3]) -> (f64, f64, f64, f64, f64) {
    use nalgebra::{Point3, Vector3};
    let dir = scratch(&format!("closed-loop-grid-{seed}"));
    let machine = repo_root().join("launch_configs/machines").join(machine);
    let (c0, t0, m0, comp) = (dir.join("c0.csv"), dir.join("t0.json"), dir.join("m0.json"), dir.join("grid"));
    let run = |args: &[&dyn AsRef<std::ffi::OsStr>]| {
        let (ok, _, err) = volcal(args);
        assert!(ok, "{err}");
    };
    let s = seed.to_string();
    let p = format!("{},{},{}", tool[0], tool[1], tool[2]);
    run(&[&"simulate", &"--machine", &machine, &"--seed", &s, &"--out", &c0, &"--truth", &t0]);
    run(&[&"solve", &c0, &"--machine", &machine, &"--out", &m0]);
    run(&[&"export", &m0, &"--format", &"grid", &"--out", &comp, &"--step-mm", &"50", &"--probe", &p]);
    let truth = volcal_formats::truth_file::TruthFile::load(&t0).unwrap().model.to_model().unwrap().0;
    let grid = volcal_formats::compensation_grid::read_grid(&comp.join("grid.csv")).unwrap();
    let u95 = std::fs::read_to_string(comp.join("grid.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.rsplit(',').next().unwrap().parse::<f64>().unwrap() * 1e-6)
        .fold(0.0, f64::max);
    let travel = truth.layout.travel;
    let probe = Vector3::from(tool);
    let n = 12;
    let mut points = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            for k in 0..=n {
                let f = |a: volcal::Axis, t: usize| {
                    let [lo, hi] = travel.range(a);
                    lo + (hi - lo) * t as f64 / n as f64
                };
                points.push(Point3::new(f(volcal::Axis::X, i), f(volcal::Axis::Y, j), f(volcal::Axis::Z, k)));
            }
        }
    }
    let before: Vec<Vector3<f64>> = points.iter().map(|x| truth.error(x, &probe)).collect();
    // The controller adds the grid's correction to the command (volcal_sim::controller).
    let after: Vec<Vector3<f64>> = points.iter().zip(&before).map(|(x, e)| e + Vector3::from(grid.at(x))).collect();
    let (b, a) = (volcal_tests::rigid_aligned(&points, &before), volcal_tests::rigid_aligned(&points, &after));
    (b.0, a.0, b.1, a.1, u95)
}

#[test]
fn grid_compensation_removes_the_volumetric_error() {
    // The patent's CMM (X carries Y carries Z) and a machine tool with the table on X; tool
    // points as a probe or a tool would stand. Seeds chosen once, never tuned.
    for (machine, seed, tool) in
        [("demo_cmm.yaml", 11, [0.0, 0.0, -0.25]), ("machine_tool_xfyz.yaml", 23, [0.0, 0.0, -0.15])]
    {
        let (mb, ma, rb, ra, u95) = grid_closed_loop(machine, seed, tool);
        eprintln!(
            "{machine}: volumetric error at the tool point, rigidly aligned: max {:.2} um before, {:.2} um after ({:.1} %); RMS {:.2} um before, {:.2} um after ({:.1} %); largest U95 of the grid {:.2} um",
            mb * 1e6,
            ma * 1e6,
            ma / mb * 100.0,
            rb * 1e6,
            ra * 1e6,
            ra / rb * 100.0,
            u95 * 1e6
        );
        assert!(ma <= 0.15 * mb, "{machine}: max after {:.1} % of before", ma / mb * 100.0);
    }
}
