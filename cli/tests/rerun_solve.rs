//! `volcal solve --rerun`: the recording is verified by the official Rerun CLI of the crate's
//! version (`rerun rrd verify`, from the pinned checker venv) and checked by an independent
//! Python reader (`check_rrd.py`, rerun-sdk) for the entity paths the views rely on.
//! `--rerun-connect` is checked the same way against a real Rerun gRPC receiver on loopback.

mod common;

use volcal::predict::AxisResolution;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn volcal(dir: &Path, args: &[&str]) -> std::process::Output {
    let out = Command::new(env!("CARGO_BIN_EXE_volcal")).current_dir(dir).args(args).output().unwrap();
    assert!(
        out.status.success() || out.status.code() == Some(3),
        "volcal {args:?} failed: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A small simulated campaign (3 stations x 10 beams x 20 points: the recording stays small)
/// in a fresh directory with the demo machine.
fn small_campaign(name: &str) -> PathBuf {
    let dir = volcal_tests::scratch(name);
    std::fs::write(dir.join("machine.yaml"), volcal_formats::machine::DEMO_MACHINE).unwrap();
    std::fs::write(dir.join("plan.yaml"), "directions_per_station: 10\npoints_per_beam: 20\n").unwrap();
    volcal(
        &dir,
        &["simulate", "--machine", "machine.yaml", "--plan", "plan.yaml", "--seed", "3", "--out", "campaign.csv"],
    );
    dir
}

/// Runs `check_rrd.py` on a recording of `dir/campaign.csv`.
fn check_entities(py: &Path, rrd: &Path, dir: &Path) {
    check_entities_of(py, rrd, &dir.join("campaign.csv"), &[]);
}

/// Runs `check_rrd.py` on a recording of `campaign` with extra arguments (`--series ROOT`,
/// `--entity PATH`).
fn check_entities_of(py: &Path, rrd: &Path, campaign: &Path, extra: &[String]) {
    let mut args = vec![rrd.as_os_str(), campaign.as_os_str()];
    args.extend(extra.iter().map(|a| std::ffi::OsStr::new(a)));
    common::rrd::check_entities(py, &args);
}

#[test]
fn solve_recording_verifies_and_has_the_expected_entities() {
    let dir = small_campaign("rerun-solve");
    let solve = ["solve", "campaign.csv", "--machine", "machine.yaml", "--out", "model.json", "--rerun", "solve.rrd"];
    volcal(&dir, &solve);
    let rrd = dir.join("solve.rrd");
    let size = std::fs::metadata(&rrd).expect("no recording written").len();
    assert!(size < 1_000_000, "recording of a 600-reading campaign is {size} bytes");

    let Some(py) = volcal_tests::checker_python() else { return };
    rrd_verify(&py, &rrd);
    check_entities(&py, &rrd, &dir);
}

/// A laser-tracer campaign (11 stops per edge) over a machine whose guideways carry a bump
/// shorter than the step, solved with the two-line machine file: the readings contradict the
/// interpolation between the stops of some axis (issue 12). What the user gets through the
/// commands: the solve says so and what to measure, the map has no number between those stops,
/// the export refuses, and the recording draws that axis's functions without a band between the
/// stops (read back by rerun-sdk).
#[test]
fn a_contradicted_interpolation_is_not_drawn_as_known() {
    let dir = volcal_tests::scratch("rerun-contradicted");
    common::contradicted_tracer_campaign(&dir);
    let solve = ["solve", "campaign.csv", "--machine", "machine.yaml", "--out", "model.json", "--rerun", "solve.rrd"];
    let out = volcal(&dir, &solve);
    let said = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(said.contains("the readings contradict the interpolation"), "{said}");

    let loaded = volcal_formats::model_file::load(&dir.join("model.json")).unwrap();
    let axes: Vec<volcal::Axis> =
        volcal::Axis::ALL.into_iter().filter(|a| loaded.resolution[a.index()].is_contradicted()).collect();
    assert!(!axes.is_empty(), "no axis contradicted in the model file: {:?}", loaded.resolution);

    let out = volcal(&dir, &["map", "model.json", "--step", "0.05", "--out", "map.csv"]);
    let warned = String::from_utf8_lossy(&out.stderr);
    for a in &axes {
        assert!(warned.contains(&format!("measure at more positions along {}", a.letter())), "{warned}");
    }
    let map = std::fs::read_to_string(dir.join("map.csv")).unwrap();
    let determined: Vec<&str> = map.lines().skip(1).map(|l| l.split(',').nth(11).unwrap()).collect();
    let open = determined.iter().filter(|d| **d == "0").count();
    assert!(open > 0 && open < determined.len(), "{open} of {} grid points not determined", determined.len());

    let refused = Command::new(env!("CARGO_BIN_EXE_volcal"))
        .current_dir(&dir)
        .args(["export", "model.json", "--format", "linuxcnc", "--out", "comp"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && text.contains("measure at more positions along"), "{text}");
    assert!(text.contains("--nodes measured"), "the refusal names the tables the data determine: {text}");

    // The tables the data determine: nodes at the contradicted axes' measured positions, every
    // node's error determined, and the README says that between them nothing is.
    let out = volcal(&dir, &["export", "model.json", "--format", "linuxcnc", "--nodes", "measured", "--out", "comp"]);
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{said}");
    let readme = std::fs::read_to_string(dir.join("comp/README.txt")).unwrap();
    for a in &axes {
        let AxisResolution::AtPositions { positions, .. } = &loaded.resolution[a.index()] else { unreachable!() };
        let table =
            std::fs::read_to_string(dir.join(format!("comp/{}.comp", a.letter().to_ascii_lowercase()))).unwrap();
        let nominal: Vec<f64> = table.lines().map(|l| l.split_whitespace().next().unwrap().parse().unwrap()).collect();
        assert_eq!(nominal.len(), positions.len(), "{table}");
        for (n, q) in nominal.iter().zip(positions) {
            assert!((n - q * 1e3).abs() < 1e-6, "node {n} mm, measured position {} mm", q * 1e3);
        }
        assert!(
            readme.contains(&format!("{}: {} nodes at the measured positions", a.letter(), positions.len())),
            "{readme}"
        );
    }
    assert!(readme.contains("NOT DETERMINED by the data"), "{readme}");
    assert!(!said.contains("U95 X inf") && !said.contains(" inf,"), "every node's uncertainty is finite: {said}");
    // A reference point between two stops of a contradicted axis is refused, with where to put it.
    let AxisResolution::AtPositions { positions, .. } = &loaded.resolution[axes[0].index()] else { unreachable!() };
    let mut point = [0.5, 0.4, -0.3];
    point[axes[0].index()] = 0.5 * (positions[4] + positions[5]);
    let point = format!("{},{},{}", point[0], point[1], point[2]);
    let export =
        ["export", "model.json", "--format", "linuxcnc", "--nodes", "measured", "--point", &point, "--out", "off"];
    let refused = Command::new(env!("CARGO_BIN_EXE_volcal")).current_dir(&dir).args(export).output().unwrap();
    let text = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && text.contains("put --point at a measured position"), "{text}");
    let out = volcal(&dir, &["export", "model.json", "--format", "grid", "--nodes", "measured", "--out", "grid"]);
    assert!(out.status.success());
    let grid = std::fs::read_to_string(dir.join("grid/grid.csv")).unwrap();
    let rows: Vec<Vec<f64>> =
        grid.lines().skip(1).map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    assert!(rows.iter().all(|r| r[6].is_finite()), "a grid node without a U95");
    for a in &axes {
        let AxisResolution::AtPositions { positions, .. } = &loaded.resolution[a.index()] else { unreachable!() };
        let mut on: Vec<f64> = rows.iter().map(|r| r[a.index()]).collect();
        on.sort_by(f64::total_cmp);
        on.dedup();
        assert_eq!(on.len(), positions.len(), "grid nodes along {}: {on:?}", a.letter());
    }

    let Some(py) = volcal_tests::checker_python() else { return };
    rrd_verify(&py, &dir.join("solve.rrd"));
    let mut extra = Vec::new();
    for a in &axes {
        extra.push("--band-open".to_string());
        extra.push(format!("functions/{0}/translation/EX{0}", a.letter()));
    }
    check_entities_of(&py, &dir.join("solve.rrd"), &dir.join("campaign.csv"), &extra);
}

/// `rerun rrd verify` of the venv's Rerun CLI (the crate's version) accepts `rrd`.
fn rrd_verify(py: &Path, rrd: &Path) {
    common::rrd::verify(py, rrd);
}

/// `volcal diagnose --rerun` on a concealed-drift campaign: the solved campaign as `solve`
/// records it, plus the residuals before and after, the drift's signature and the report.
#[test]
fn diagnose_recording_shows_before_signature_and_after() {
    let dir = volcal_tests::scratch("rerun-diagnose");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let campaign = root.join("bags/concealed/setup_drift.csv");
    let machine = root.join("launch_configs/machines/diagnosis_cmm.yaml");
    let out = volcal(
        &dir,
        &["diagnose", campaign.to_str().unwrap(), "--machine", machine.to_str().unwrap(), "--rerun", "diagnose.rrd"],
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("1. setup_drift"), "the drift is named first");
    let rrd = dir.join("diagnose.rrd");
    assert!(rrd.exists(), "no recording written");
    let Some(py) = volcal_tests::checker_python() else { return };
    rrd_verify(&py, &rrd);
    let extra: Vec<String> = [
        ("--series", "diagnosis/residuals_before"),
        ("--series", "diagnosis/residuals_after"),
        ("--series", "diagnosis/effects/setup_drift"),
        ("--entity", "diagnosis/report"),
        ("--entity", "diagnosis/residual_rms_before/stations/0"),
        ("--entity", "diagnosis/residual_rms_after/stations/2"),
    ]
    .iter()
    .flat_map(|(f, v)| [f.to_string(), v.to_string()])
    .collect();
    check_entities_of(&py, &rrd, &campaign, &extra);
}

/// The `rerun` executable shipped in the venv's rerun-sdk (`site-packages/rerun_sdk/rerun_cli`).
fn rerun_binary(py: &Path) -> PathBuf {
    let lib = py.parent().unwrap().parent().unwrap().join("lib");
    std::fs::read_dir(&lib)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.path().join("site-packages/rerun_sdk/rerun_cli/rerun"))
        .find(|p| p.exists())
        .unwrap_or_else(|| panic!("no rerun_sdk/rerun_cli/rerun under {}", lib.display()))
}

#[test]
fn solve_streams_to_a_running_viewer() {
    let Some(py) = volcal_tests::checker_python() else { return };
    let dir = small_campaign("rerun-connect");
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    // A Rerun gRPC receiver on loopback that streams what it gets to a file: the viewer binary
    // of the venv itself (its `rerun` entry point would run it as a child process).
    let mut receiver = Command::new(rerun_binary(&py))
        .args(["--bind", "127.0.0.1", "--port", &port.to_string(), "--save", "received.rrd"])
        .current_dir(&dir)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The receiver ignores SIGINT/SIGTERM while saving; a streamed file needs no finishing.
    let stop = |r: &mut std::process::Child| {
        let _ = r.kill();
        let _ = r.wait();
    };
    let start = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        if start.elapsed() > Duration::from_secs(30) {
            stop(&mut receiver);
            panic!("the Rerun receiver did not listen on port {port}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let addr = format!("127.0.0.1:{port}");
    volcal(
        &dir,
        &["solve", "campaign.csv", "--machine", "machine.yaml", "--out", "model.json", "--rerun-connect", &addr],
    );
    // volcal flushes before exiting; wait for the receiver to have written everything.
    let rrd = dir.join("received.rrd");
    let (mut last, mut stable_since) = (0, Instant::now());
    while stable_since.elapsed() < Duration::from_secs(1) && start.elapsed() < Duration::from_secs(60) {
        let size = std::fs::metadata(&rrd).map(|m| m.len()).unwrap_or(0);
        if size != last {
            (last, stable_since) = (size, Instant::now());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    stop(&mut receiver);
    // A streamed file has no footer (rrd verify wants one); its content is what counts.
    check_entities(&py, &rrd, &dir);
}

#[test]
fn bad_rerun_flags_are_refused_before_solving() {
    let dir = volcal_tests::scratch("rerun-flags");
    for (flag, value, says) in
        [("--rerun", "solve.txt", "must end in .rrd"), ("--rerun-connect", "http://", "not a Rerun gRPC address")]
    {
        let out = Command::new(env!("CARGO_BIN_EXE_volcal"))
            .current_dir(&dir)
            .args(["solve", "missing.csv", "--machine", "missing.yaml", "--out", "model.json", flag, value])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.contains(flag) && err.contains(says) && !err.contains("missing.csv"), "{flag} {value}: {err}");
    }
}
