//! The `volcal` command line: contract, bad input (issue 2, acceptance 6) and determinism.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn volcal(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_volcal")).args(args).output().expect("volcal runs")
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("volcal-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn machine() -> String {
    repo().join("launch_configs/machines/demo_cmm.yaml").display().to_string()
}

/// The patent's example campaign (3 x 25 beams x 100 points), simulated.
fn campaign(dir: &Path) -> PathBuf {
    let out = dir.join("campaign.csv");
    let plan = repo().join("launch_configs/plans/patent_example.yaml");
    let o = volcal(&[
        "simulate",
        "--machine",
        &machine(),
        "--plan",
        plan.to_str().unwrap(),
        "--seed",
        "4",
        "--out",
        out.to_str().unwrap(),
        "--truth",
        dir.join("truth.json").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    out
}

/// Runs `volcal solve` on a campaign text and returns (exit code, output).
fn solve_text(dir: &Path, name: &str, csv: &str) -> (i32, String) {
    let path = dir.join(name);
    std::fs::write(&path, csv).unwrap();
    let o = volcal(&[
        "solve",
        path.to_str().unwrap(),
        "--machine",
        &machine(),
        "--out",
        dir.join("m.json").to_str().unwrap(),
    ]);
    let t = text(&o);
    assert!(!t.contains("panicked"), "volcal panicked: {t}");
    (o.status.code().unwrap_or(-1), t)
}

#[test]
fn every_subcommand_has_an_example() {
    for sub in ["simulate", "solve", "predict", "map", "report", "demo"] {
        let o = volcal(&[sub, "--help"]);
        assert!(o.status.success());
        assert!(text(&o).contains("Example"), "{sub} --help has no example");
    }
}

#[test]
fn solve_predict_map_report_and_determinism() {
    let d = scratch("chain");
    let c = campaign(&d);
    let m1 = d.join("model1.json");
    let m2 = d.join("model2.json");
    let mut bands = Vec::new();
    for m in [&m1, &m2] {
        let o = volcal(&["solve", c.to_str().unwrap(), "--machine", &machine(), "--out", m.to_str().unwrap()]);
        assert!(o.status.success(), "{}", text(&o));
        let t = text(&o);
        assert!(t.contains("EXX") && t.contains("Max volumetric error") && t.contains("um"), "{t}");
        // The map's simultaneous band, and the largest error's uncertainty over the whole map.
        assert!(t.contains("over the map as a whole"), "{t}");
        bands.push(t.lines().find(|l| l.starts_with("The map as a whole")).expect("the band's line").to_string());
    }
    // The band is drawn with a fixed seed: the same model gives the same statement.
    assert_eq!(bands[0], bands[1]);
    // The same input gives a bit-identical model.
    assert_eq!(std::fs::read(&m1).unwrap(), std::fs::read(&m2).unwrap());

    let pts = d.join("points.csv");
    // The third point lies 0.5 m beyond the travel's X end: no reading says anything there.
    std::fs::write(
        &pts,
        "x_m,y_m,z_m,px_m,py_m,pz_m\n0.5,0.4,-0.3,0,0,-0.1\n0.1,0.7,-0.5,0.12,0,-0.1\n1.5,0.4,-0.3,0,0,0\n",
    )
    .unwrap();
    let out = d.join("errors.csv");
    let o = volcal(&["predict", m1.to_str().unwrap(), pts.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let said = text(&o);
    assert!(said.contains("1 of 3 point(s) lie outside the calibrated travel (x 0 to 1 m"), "{said}");
    let e = std::fs::read_to_string(&out).unwrap();
    let rows: Vec<&str> = e.lines().collect();
    assert_eq!(rows[0], "x_m,y_m,z_m,px_m,py_m,pz_m,ex_m,ey_m,ez_m,u95_m,determined,interpolated", "{e}");
    assert_eq!(rows.len(), 4);
    assert!(rows[1].ends_with(",1,0") && rows[2].ends_with(",1,0"), "{e}");
    assert_eq!(rows[3], "1.5,0.4,-0.3,0,0,0,,,,,0,0", "outside the travel: no value");

    let map = d.join("map.csv");
    let o =
        volcal(&["map", m1.to_str().unwrap(), "--step", "0.2", "--out", map.to_str().unwrap(), "--probe", "0,0,-0.1"]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(std::fs::read_to_string(&map).unwrap().lines().count(), 1 + 6 * 5 * 4);

    let comp = d.join("comp");
    let o = volcal(&["report", m1.to_str().unwrap(), "--compensation-dir", comp.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    for a in ["x", "y", "z"] {
        let t = std::fs::read_to_string(comp.join(format!("compensation_{a}.csv"))).unwrap();
        assert!(t.lines().count() > 50, "{t}");
    }
}

#[test]
fn bad_input_is_reported_with_file_line_and_field() {
    let d = scratch("bad");
    let good = std::fs::read_to_string(campaign(&d)).unwrap();
    let lines: Vec<&str> = good.lines().collect();
    let header_at = lines.iter().position(|l| l.starts_with("kind,")).unwrap();

    // A malformed row: too few fields.
    let mut bad = lines.clone();
    bad[header_at + 5] = "beam,0,1,0.5";
    let (code, t) = solve_text(&d, "short_row.csv", &(bad.join("\n") + "\n"));
    assert_ne!(code, 0);
    assert!(
        t.contains("short_row.csv line") && t.contains(&format!("line {}", header_at + 6)) && t.contains("fields"),
        "{t}"
    );

    // A number that is not a number.
    let mut bad = lines.clone();
    let row = lines[header_at + 7].replacen(",", ",", 1);
    let mut f: Vec<&str> = row.split(',').collect();
    f[4] = "0.12x";
    let row = f.join(",");
    bad[header_at + 7] = &row;
    let (code, t) = solve_text(&d, "nan_text.csv", &(bad.join("\n") + "\n"));
    assert_ne!(code, 0);
    assert!(t.contains(&format!("line {}", header_at + 8)) && t.contains("l_m"), "{t}");

    // NaN and inf.
    for v in ["NaN", "inf", "-inf"] {
        let mut bad = lines.clone();
        let mut f: Vec<&str> = lines[header_at + 3].split(',').collect();
        f[6] = v;
        let row = f.join(",");
        bad[header_at + 3] = &row;
        let (code, t) = solve_text(&d, "nan.csv", &(bad.join("\n") + "\n"));
        assert_ne!(code, 0, "{v}");
        assert!(
            t.contains(&format!("line {}", header_at + 4)) && t.contains("y_m") && t.contains("finite"),
            "{v}: {t}"
        );
    }

    // Finite but no machine's: a coordinate of 1e300 m (squared and summed it overflowed into a
    // diagnosis of NaN).
    let mut bad = lines.clone();
    let mut f: Vec<&str> = lines[header_at + 3].split(',').collect();
    f[6] = "1e300";
    let row = f.join(",");
    bad[header_at + 3] = &row;
    let (code, t) = solve_text(&d, "huge.csv", &(bad.join("\n") + "\n"));
    assert_ne!(code, 0);
    assert!(t.contains(&format!("line {}", header_at + 4)) && t.contains("y_m") && t.contains("beyond"), "{t}");

    // An empty file, a header-only file.
    let (code, t) = solve_text(&d, "empty.csv", "");
    assert_ne!(code, 0);
    assert!(t.contains("no header"), "{t}");
    let (code, t) = solve_text(&d, "header.csv", &(lines[..=header_at].join("\n") + "\n"));
    assert_ne!(code, 0);
    assert!(t.contains("no readings"), "{t}");

    // Coordinates in millimetres.
    let mm: Vec<String> = lines
        .iter()
        .enumerate()
        .map(|(i, l)| {
            if i <= header_at {
                return l.to_string();
            }
            let mut f: Vec<String> = l.split(',').map(String::from).collect();
            for k in 5..8 {
                f[k] = (f[k].parse::<f64>().unwrap() * 1000.0).to_string();
            }
            f.join(",")
        })
        .collect();
    let (code, t) = solve_text(&d, "mm.csv", &(mm.join("\n") + "\n"));
    assert_ne!(code, 0);
    assert!(t.contains("millimetres") && t.contains("x_m/y_m/z_m"), "{t}");

    // Abscissae in millimetres.
    let mm: Vec<String> = lines
        .iter()
        .enumerate()
        .map(|(i, l)| {
            if i <= header_at {
                return l.to_string();
            }
            let mut f: Vec<String> = l.split(',').map(String::from).collect();
            f[4] = (f[4].parse::<f64>().unwrap() * 1000.0).to_string();
            f.join(",")
        })
        .collect();
    let (code, t) = solve_text(&d, "lmm.csv", &(mm.join("\n") + "\n"));
    assert_ne!(code, 0);
    assert!(t.contains("millimetres") && t.contains("l_m"), "{t}");

    // Too-short beams are skipped with a warning naming them; the rest still solves.
    let mut short: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
    short.push("beam,7,99,0,0,0.5,0.4,-0.3,0,0,-0.1".into());
    short.push("beam,7,99,1,0.01,0.51,0.4,-0.3,0,0,-0.1".into());
    let (code, t) = solve_text(&d, "shortbeam.csv", &(short.join("\n") + "\n"));
    assert_eq!(code, 0, "{t}");
    assert!(t.contains("station 7 beam 99 has 2 point(s)"), "{t}");

    // A machine file that is wrong: the error names the file, the line and what was expected.
    let bad_machine = d.join("bad_machine.yaml");
    let solve_with_machine = |yaml: &str| {
        std::fs::write(&bad_machine, yaml).unwrap();
        let o = volcal(&[
            "solve",
            d.join("campaign.csv").to_str().unwrap(),
            "--machine",
            bad_machine.to_str().unwrap(),
            "--out",
            d.join("x.json").to_str().unwrap(),
        ]);
        let t = text(&o);
        assert!(!o.status.success() && t.contains("bad_machine.yaml") && !t.contains("panicked"), "{t}");
        t
    };
    // Unknown topology.
    let t = solve_with_machine("topology: FXQZ\ntravel: {x: [0, 1], y: [0, 0.8], z: [-0.6, 0]}\n");
    assert!(t.contains("topology") && t.contains("FXQZ"), "{t}");
    // A travel of the wrong shape: the error says the shape expected.
    let t = solve_with_machine("topology: FXYZ\ntravel: [1.0, 0.8, 0.6]\n");
    assert!(t.contains("line 2") && t.contains("{x: [lo, hi], y: [lo, hi], z: [lo, hi]}"), "{t}");

    // An option's point with two numbers: the error names the option.
    let model = d.join("model.json");
    let o = volcal(&[
        "solve",
        d.join("campaign.csv").to_str().unwrap(),
        "--machine",
        &machine(),
        "--out",
        model.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let map = d.join("map.csv");
    let o = volcal(&["map", model.to_str().unwrap(), "--probe", "0,-0.1", "--out", map.to_str().unwrap()]);
    let t = text(&o);
    assert!(!o.status.success() && t.contains("--probe") && t.contains("three"), "{t}");
}

/// A line whose count was re-established at its second point with nothing flagged (the CI
/// failure that the pairing's carry-over of probe count losses removed) leaves a misfit no
/// geometry explains: the solve says so and names the line.
#[test]
fn a_line_off_its_origin_is_named_by_the_solve() {
    let d = scratch("off-origin");
    let c = d.join("c.csv");
    let plan = repo().join("launch_configs/plans/sim_short.yaml");
    let o =
        volcal(&["simulate", "--machine", &machine(), "--plan", plan.to_str().unwrap(), "--out", c.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    // Station 1 beam 4 re-zeroed at its second point: every later reading one step short.
    let csv = std::fs::read_to_string(&c).unwrap();
    let header: Vec<&str> = csv.lines().find(|l| !l.starts_with('#')).unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (st, beam, l) = (col("station"), col("beam"), col("l_m"));
    let (mut n, mut zero) = (0, 0.0);
    let mut out = String::new();
    for line in csv.lines() {
        let mut f: Vec<String> = line.split(',').map(str::to_string).collect();
        if !line.starts_with('#') && f.len() > l && f[st] == "1" && f[beam] == "4" {
            let v: f64 = f[l].parse().unwrap();
            if n == 1 {
                zero = v;
            }
            if n >= 1 {
                f[l] = format!("{:.12}", v - zero);
            }
            n += 1;
        }
        out.push_str(&f.join(","));
        out.push('\n');
    }
    assert_eq!(n, 20);
    let bad = d.join("bad.csv");
    std::fs::write(&bad, out).unwrap();
    let o =
        volcal(&["solve", bad.to_str().unwrap(), "--machine", &machine(), "--out", d.join("m.json").to_str().unwrap()]);
    let t = text(&o);
    assert!(t.contains("warning: the readings do not fit the model"), "{t}");
    assert!(t.contains("Most of the misfit is in station 1 beam 4 (RMS"), "{t}");
    // The unmodified campaign says nothing of the kind.
    let o =
        volcal(&["solve", c.to_str().unwrap(), "--machine", &machine(), "--out", d.join("m0.json").to_str().unwrap()]);
    assert!(!text(&o).contains("do not fit the model"), "{}", text(&o));
}

#[test]
fn rank_deficient_campaign_warns_and_exits_3() {
    // Only beams of one station with a single probe offset along Z: some functions cannot be
    // identified. The model is written, the report names them, and the exit status says so.
    let d = scratch("rank");
    let plan = d.join("plan.yaml");
    std::fs::write(&plan, "probe_offsets: [[0, 0, -0.15]]\n").unwrap();
    let c = d.join("c.csv");
    let o =
        volcal(&["simulate", "--machine", &machine(), "--plan", plan.to_str().unwrap(), "--out", c.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let o =
        volcal(&["solve", c.to_str().unwrap(), "--machine", &machine(), "--out", d.join("m.json").to_str().unwrap()]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(3), "{t}");
    assert!(t.contains("ECZ") && t.contains("cannot be identified"), "{t}");
    assert!(d.join("m.json").exists());
    let m = d.join("m.json");

    // What the data do not determine is written as no value, never as a minimum-norm value
    // beside an infinite uncertainty: the compensation tables leave ECZ's cells empty...
    let comp = d.join("comp");
    let o = volcal(&["report", m.to_str().unwrap(), "--compensation-dir", comp.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let z = std::fs::read_to_string(comp.join("compensation_z.csv")).unwrap();
    let head: Vec<&str> = z.lines().nth(1).unwrap().split(',').collect();
    let (ecz, u_ecz) =
        (head.iter().position(|c| *c == "ecz_rad").unwrap(), head.iter().position(|c| *c == "u_ecz_rad").unwrap());
    for row in z.lines().skip(2) {
        let f: Vec<&str> = row.split(',').collect();
        assert_eq!((f[ecz], f[u_ecz]), ("", ""), "{row}");
    }
    assert!(!z.contains("inf") && !z.contains("NaN"), "{z}");

    // ... and the validation lines' summary is over the targets the data determine, its CSV
    // leaving the others' prediction empty (a body diagonal crosses every axis, so ECZ's lever
    // arms reach it).
    let lines = d.join("lines.csv");
    let o = volcal(&["validate", m.to_str().unwrap(), "--diagonals", "--out", lines.to_str().unwrap()]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let csv = std::fs::read_to_string(&lines).unwrap();
    assert!(!csv.contains("inf") && !csv.contains("NaN"), "{csv}");
    for row in csv.lines().skip(1) {
        let f: Vec<&str> = row.split(',').collect();
        assert_eq!(f[5].is_empty(), f[6].is_empty(), "a prediction and its uncertainty come together: {row}");
    }

    // A step that would ask for more grid points than memory holds (millimetres taken as
    // metres) is refused before anything is built.
    let o = volcal(&["map", m.to_str().unwrap(), "--step", "1e-9", "--out", d.join("map.csv").to_str().unwrap()]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains("grid points") && t.contains("coarser step") && !t.contains("panicked"), "{t}");
}

/// A campaign of ISO 230-2 lines alone (no stations: one beam along each axis through a point,
/// five runs each, each pointed anew by the deflector) fits to its noise with an explicit
/// representation. The beams are tilted from the axes by the deflector's pointing (tens of
/// microradians), so the readings see each line's straightness only through that tilt's
/// cosine: the solve says so and leaves it undetermined. Before stop 81 the minimum-norm
/// choice put metres of straightness where micrometres of positioning fit, and the solve
/// ended 9 to 18 times the noise off (chi2/dof 83 to 309 on seeds 1-10; 154 and not
/// converged on this one).
///
/// Machine-tool machine, seed 7: not one of the seeds the fix was developed on (1, the single
/// lines of seed 1), nor one it was measured on first (2-10 after; all fit at chi2/dof 0.94 to
/// 1.06).
#[test]
fn reference_lines_alone_fit_to_their_noise() {
    let d = scratch("lines-alone");
    let plan = d.join("plan.yaml");
    std::fs::write(
        &plan,
        "n_stations: 0\npoints_per_beam: 50\nprobe_offsets: [[0, 0, 0]]\nreference_lines:\n\
         \x20 - {axis: x, through: [0.4, 0.25, -0.25], runs: 5}\n\
         \x20 - {axis: y, through: [0.4, 0.25, -0.25], runs: 5}\n\
         \x20 - {axis: z, through: [0.4, 0.25, -0.25], runs: 5}\n",
    )
    .unwrap();
    let tool = repo().join("launch_configs/machines/machine_tool_xfyz.yaml");
    let c = d.join("c.csv");
    let o = volcal(&[
        "simulate",
        "--machine",
        tool.to_str().unwrap(),
        "--plan",
        plan.to_str().unwrap(),
        "--seed",
        "7",
        "--out",
        c.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let explicit = d.join("machine.yaml");
    std::fs::write(
        &explicit,
        "topology: XFYZ\ntravel: {x: [0.0, 0.8], y: [0.0, 0.5], z: [-0.5, 0.0]}\n\
         representation: {kind: bspline, intervals: 12}\n",
    )
    .unwrap();
    let o = volcal(&[
        "solve",
        c.to_str().unwrap(),
        "--machine",
        explicit.to_str().unwrap(),
        "--out",
        d.join("m.json").to_str().unwrap(),
    ]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(3), "{t}");
    assert!(!t.contains("did not converge"), "{t}");
    let chi2: f64 = t
        .split("chi2/dof ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no chi2/dof in {t}"));
    assert!(chi2 < 1.3, "the lines do not fit their noise (chi2/dof {chi2}): {t}");
    assert!(t.contains("informed by the readings only through second-order effects"), "{t}");
    // Z is the last axis and the line is at the tool point: its positioning is what the Z
    // line measures, alone.
    let ezz = t.lines().find(|l| l.contains("EZZ")).unwrap_or("");
    assert!(ezz.contains("um") && !ezz.contains("EZZ    not determined"), "{t}");
}

/// `{kind: auto, tables: true}`: over the paper's linear tables (11 nodes per function), measured
/// densely by beams, `volcal solve` takes linear tables of 10 intervals on every axis, says so
/// and why, and the model file keeps the choice with its layout; without the option (the
/// two-line machine file) the functions stay cubic B-splines.
#[test]
fn tables_where_the_readings_show_kinks_at_equal_spacing() {
    let dir = scratch("tables");
    let csv = dir.join("beams.csv");
    let paper = repo().join("launch_configs/machines/paper_cmm.yaml");
    let plan = repo().join("launch_configs/plans/patent_example.yaml");
    let o = volcal(&[
        "simulate",
        "--machine",
        paper.to_str().unwrap(),
        "--plan",
        plan.to_str().unwrap(),
        "--seed",
        "11",
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let head = "topology: FYXZ\ntravel: {x: [0, 0.7], y: [-0.5, 0], z: [-0.7, 0]}\n";
    let solve = |name: &str, extra: &str| -> (String, serde_json::Value) {
        let m = dir.join(format!("{name}.yaml"));
        std::fs::write(&m, format!("{head}{extra}")).unwrap();
        let model = dir.join(format!("{name}.json"));
        let o = volcal(&[
            "solve",
            csv.to_str().unwrap(),
            "--machine",
            m.to_str().unwrap(),
            "--out",
            model.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        (text(&o), serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap())
    };
    let (t, model) = solve("tables", "representation: {kind: auto, tables: true}\n");
    for axis in ["X", "Y", "Z"] {
        assert!(t.contains(&format!("  {axis}: linear tables of 10 intervals")), "{t}");
    }
    let knots = model["representation_choice"]["knots"].as_array().expect("knots");
    assert_eq!(knots.len(), 3);
    assert!(
        knots.iter().all(|k| k["table"]["intervals"] == 10 && k["table"]["final_gain"].as_f64() > Some(0.0)),
        "{knots:?}"
    );
    let (t, model) = solve("splines", "");
    assert!(!t.contains("linear tables"), "{t}");
    let knots = model["representation_choice"]["knots"].as_array().expect("knots");
    assert!(knots.iter().all(|k| k.get("table").is_none()), "{knots:?}");
}

/// The beams' alignment (`volcal::alignment`): the patent's campaign, whose simulated beams
/// follow the reflector's motion at a CMM's usual errors, leaves nothing to cover (the two
/// alignments' readings differ by far less than their noise, and the model is the one a
/// statement of either gives); the model file records what was assumed and whether it was
/// stated; a value that is neither is an error that names the field.
#[test]
fn the_beams_alignment_is_recorded_and_covered_only_where_it_matters() {
    let d = scratch("alignment");
    let c = campaign(&d);
    let head = std::fs::read_to_string(machine()).unwrap();
    let solve = |name: &str, extra: &str| -> (Output, PathBuf) {
        let m = d.join(format!("{name}.yaml"));
        std::fs::write(&m, format!("{head}\n{extra}")).unwrap();
        let model = d.join(format!("{name}.json"));
        let o =
            volcal(&["solve", c.to_str().unwrap(), "--machine", m.to_str().unwrap(), "--out", model.to_str().unwrap()]);
        (o, model)
    };
    let read = |p: &Path| -> serde_json::Value { serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap() };
    let (o, unstated) = solve("unstated", "");
    assert!(o.status.success(), "{}", text(&o));
    assert!(!text(&o).contains("aligned with"), "{}", text(&o));
    let a = read(&unstated)["beam_alignment"].clone();
    assert_eq!(a["aligned_with"], "motion", "{a}");
    assert_eq!(a["stated"], false, "{a}");
    let sep = a["separation"].as_f64().unwrap();
    assert!(sep > 0.0 && sep < volcal::alignment::NEGLIGIBLE_SEPARATION, "{a}");
    let (o, motion) = solve("motion", "beam_alignment: motion\n");
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(read(&motion)["beam_alignment"]["stated"], true);
    // Nothing covered: the same coefficients and covariance as when stated.
    for key in ["functions", "squareness", "covariance"] {
        assert_eq!(read(&unstated)[key], read(&motion)[key], "{key}");
    }
    let (o, commanded) = solve("commanded", "beam_alignment: commanded\n");
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(read(&commanded)["beam_alignment"]["aligned_with"], "commanded");
    let (o, _) = solve("bad", "beam_alignment: sideways\n");
    assert!(!o.status.success());
    let t = text(&o);
    assert!(t.contains("beam_alignment") && t.contains("sideways") && !t.contains("panicked"), "{t}");
}
