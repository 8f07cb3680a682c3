//! The real controller: LinuxCNC 2.9 (Debian `linuxcnc-uspace`, headless sim from
//! `shared/tools/linuxcnc-sim`) loads the `x.comp` that `volcal export --format linuxcnc` wrote
//! and moves X on and between the nodes, up and down; its HAL pins
//! (`joint.0.motor-pos-cmd - joint.0.pos-cmd`) must show the correction the model asks for
//! (`tests/py/linuxcnc_applies_comp.py`), for COMP_FILE_TYPE 0 and 1, and with the backlash of
//! a diagnosis in the forward/reverse columns.
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
    let machine = repo_root().join("launch_configs/machines/diagnosis_cmm.yaml");
    let point = [0.3, 0.2, -0.2];
    // (campaign, COMP_FILE_TYPE, with its diagnosis): the clean campaign in both types; the
    // campaign with a concealed 1.5 um X backlash, whose diagnosed reversal splits the columns.
    for (name, comp_type, with_diagnosis) in [("clean", "1", false), ("clean", "0", false), ("reversal", "1", true)] {
        let campaign = repo_root().join(format!("bags/concealed/{name}.csv"));
        let model = dir.join(format!("{name}.model.json"));
        let (ok, _, out) = volcal(&[&"solve", &campaign, &"--machine", &machine, &"--out", &model]);
        assert!(ok, "{out}");
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
        let (ok, said, out) = volcal(&args);
        assert!(ok, "{out}");
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
