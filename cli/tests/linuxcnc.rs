//! The real controller: LinuxCNC 2.9 (Debian `linuxcnc-uspace`, headless sim from
//! `shared/tools/linuxcnc-sim`) loads the `x.comp` that `volcal export --format linuxcnc` wrote
//! and moves X on and between the nodes, up and down; its HAL pins
//! (`joint.0.motor-pos-cmd - joint.0.pos-cmd`) must show the correction the model asks for
//! (`tests/py/linuxcnc_applies_comp.py`), for COMP_FILE_TYPE 0 and 1, with the backlash of
//! a diagnosis in the forward/reverse columns, and with X's nodes at a laser tracer's stops
//! (`--nodes measured`, where the readings contradict the interpolation between them).
//!
//! Skipped with a message where LinuxCNC or the sim recipe is absent, unless
//! `VOLCAL_REQUIRE_LINUXCNC=1` (which `.ci/run` sets after installing it).

mod common;

use common::run_volcal as volcal;
use std::path::{Path, PathBuf};
use std::process::Command;
use volcal_tests::{repo_root, scratch};

fn sim_dir() -> Option<PathBuf> {
    let required = std::env::var("VOLCAL_REQUIRE_LINUXCNC").is_ok_and(|v| v == "1");
    let dir = repo_root().join("../shared/tools/linuxcnc-sim");
    let missing = if !Path::new("/usr/bin/linuxcnc").exists() {
        Some("LinuxCNC is not installed (apt-get install linuxcnc-uspace)".to_string())
    } else if !dir.join("lcnc_sim.py").exists() {
        Some(format!("the sim recipe {} is absent", dir.display()))
    } else {
        None
    };
    match missing {
        Some(why) if required => panic!("VOLCAL_REQUIRE_LINUXCNC=1 but {why}"),
        Some(why) => {
            eprintln!("skipped: {why}");
            None
        }
        None => Some(dir),
    }
}

#[test]
fn linuxcnc_applies_the_exported_tables_as_the_model_asks() {
    let Some(sim) = sim_dir() else { return };
    let dir = scratch("linuxcnc");
    let diagnosis_cmm = repo_root().join("launch_configs/machines/diagnosis_cmm.yaml");
    let tracer = dir.join("tracer");
    std::fs::create_dir_all(&tracer).unwrap();
    common::contradicted_tracer_campaign(&tracer);
    // (campaign, COMP_FILE_TYPE, with its diagnosis): the clean campaign in both types; the
    // campaign with a concealed 1.5 um X backlash, whose diagnosed reversal splits the columns;
    // the tracer campaign whose X interpolation is contradicted, X's nodes at its 11 stops.
    for (name, comp_type, with_diagnosis) in
        [("clean", "1", false), ("clean", "0", false), ("reversal", "1", true), ("tracer", "1", false)]
    {
        let at_stops = name == "tracer";
        let (campaign, machine, point) = if at_stops {
            (tracer.join("campaign.csv"), tracer.join("machine.yaml"), [0.5, 0.4, -0.3])
        } else {
            (repo_root().join(format!("bags/concealed/{name}.csv")), diagnosis_cmm.clone(), [0.3, 0.2, -0.2])
        };
        let model = dir.join(format!("{name}.model.json"));
        let solve = Command::new(common::volcal())
            .args([&"solve" as &dyn AsRef<std::ffi::OsStr>, &campaign, &"--machine", &machine, &"--out", &model])
            .output()
            .unwrap();
        // Exit 3: solved, part of the model left to what the data determine (the tracer's one
        // probe offset does not see every rotation).
        let solved = solve.status.success() || (at_stops && solve.status.code() == Some(3));
        assert!(solved, "{}", String::from_utf8_lossy(&solve.stderr));
        let diag = dir.join(format!("{name}.diagnosis.json"));
        if with_diagnosis {
            let (ok, _, out) = volcal(&[&"diagnose", &campaign, &"--machine", &machine, &"--json", &diag]);
            assert!(ok, "{out}");
        }
        let tables = dir.join(format!("{name}_type{comp_type}"));
        let p = format!("{},{},{}", point[0], point[1], point[2]);
        let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![
            &"export",
            &model,
            &"--format",
            &"linuxcnc",
            &"--out",
            &tables,
            &"--step-mm",
            &"20",
            &"--point",
            &p,
            &"--comp-type",
            &comp_type,
        ];
        if with_diagnosis {
            args.extend([&"--diagnosis" as &dyn AsRef<std::ffi::OsStr>, &diag]);
        }
        if at_stops {
            args.extend([&"--nodes" as &dyn AsRef<std::ffi::OsStr>, &"measured"]);
        }
        let (ok, said, out) = volcal(&args);
        assert!(ok, "{out}");
        if at_stops {
            let stops: Vec<String> = (0..=10).map(|i| format!("{:.6}", 100.0 * i as f64)).collect();
            let text = std::fs::read_to_string(tables.join("x.comp")).unwrap();
            let nominal: Vec<&str> = text.lines().map(|l| l.split_whitespace().next().unwrap()).collect();
            assert_eq!(nominal, stops, "x.comp's nodes are the tracer's stops along X");
        }
        // The nodes of x.comp, with Y and Z at the tables' reference point, for `volcal predict`.
        let text = std::fs::read_to_string(tables.join("x.comp")).unwrap();
        let mut pts = String::from("x_m,y_m,z_m\n");
        for l in text.lines() {
            let nominal_mm: f64 = l.split_whitespace().next().unwrap().parse().unwrap();
            pts.push_str(&format!("{},{},{}\n", nominal_mm * 1e-3, point[1], point[2]));
        }
        let (points, pred) = (dir.join("x_nodes.csv"), dir.join(format!("{name}_pred{comp_type}.csv")));
        std::fs::write(&points, pts).unwrap();
        let (ok, _, out) = volcal(&[&"predict", &model, &points, &"--out", &pred]);
        assert!(ok, "{out}");
        let mut cmd = Command::new("/usr/bin/python3");
        cmd.arg(repo_root().join("tests/py/linuxcnc_applies_comp.py"))
            .args([sim.as_os_str(), tables.as_os_str()])
            .arg(comp_type)
            .arg(&pred)
            .env("LINUXCNC_SIM_WORKDIR", dir.join(format!("lcnc_{name}{comp_type}")));
        if with_diagnosis {
            cmd.arg(&diag);
        }
        let run = cmd.output().unwrap();
        let text = format!("{}{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
        eprintln!("{name}, COMP_FILE_TYPE {comp_type}:\n{said}{}", String::from_utf8_lossy(&run.stdout));
        assert!(run.status.success(), "LinuxCNC, {name}, COMP_FILE_TYPE {comp_type}:\n{text}");
    }
}
