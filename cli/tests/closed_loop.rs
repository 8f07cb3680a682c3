//! The closed loop of a LinuxCNC compensation: measure the simulated CMM, identify it, export the
//! per-joint tables, simulate the same machine under a controller applying them
//! (`volcal simulate --compensation`, new measurement noise), identify it again. The positioning
//! error along the tables' reference lines must fall to at most 10 % of before on every axis.

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

#[test]
fn linuxcnc_compensation_removes_the_positioning_errors() {
    let dir = scratch("closed-loop");
    let machine = repo_root().join("launch_configs/machines/demo_cmm.yaml");
    let travel = [[0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]];
    let point = [0.5, 0.4, -0.3];
    let p = format!("{},{},{}", point[0], point[1], point[2]);
    let (c0, m0, comp) = (dir.join("c0.csv"), dir.join("m0.json"), dir.join("comp"));
    let (c1, m1) = (dir.join("c1.csv"), dir.join("m1.json"));
    let run = |args: &[&dyn AsRef<std::ffi::OsStr>]| {
        let (ok, _, err) = volcal(args);
        assert!(ok, "{err}");
    };
    run(&[&"simulate", &"--machine", &machine, &"--seed", &"5", &"--out", &c0]);
    run(&[&"solve", &c0, &"--machine", &machine, &"--out", &m0]);
    run(&[&"export", &m0, &"--format", &"linuxcnc", &"--out", &comp, &"--step-mm", &"20", &"--point", &p]);
    // The same machine (seed 5), new noise, under the controller's compensation.
    run(&[
        &"simulate",
        &"--machine",
        &machine,
        &"--seed",
        &"5",
        &"--noise-seed",
        &"105",
        &"--out",
        &c1,
        &"--compensation",
        &comp,
    ]);
    run(&[&"solve", &c1, &"--machine", &machine, &"--out", &m1]);
    let before = positioning_ranges(&m0, &dir, point, travel);
    let after = positioning_ranges(&m1, &dir, point, travel);
    for a in 0..3 {
        let ratio = after[a] / before[a];
        eprintln!(
            "axis {}: positioning error along the reference line {:.3} um before, {:.3} um after ({:.1} %)",
            ["X", "Y", "Z"][a],
            before[a] * 1e6,
            after[a] * 1e6,
            ratio * 100.0
        );
        assert!(ratio <= 0.10, "axis {a}: {:.1} % of before", ratio * 100.0);
    }
}
