//! An independent check: the SciPy implementation of the patent's reduced least squares
//! (benches/peer/reduced_lsq.py) solves the same campaign and agrees with volcal.

use volcal::campaign::prepare;
use volcal_formats::machine::{Machine, DEMO_MACHINE};
use volcal_formats::model_file::{ModelFile, Provenance};
use volcal_formats::plan::sim_config;
use volcal_sim::{simulate, Plan};

#[test]
fn scipy_peer_agrees_with_volcal() {
    let Some(py) = volcal_tests::checker_python() else { return };
    let dir = volcal_tests::scratch("peer");
    let m = Machine::parse(DEMO_MACHINE).unwrap();
    let cfg = sim_config(&m, Plan::patent_example(), 1);
    let out = simulate(&cfg, &[], 1).unwrap();
    let csv = dir.join("patent.csv");
    volcal_formats::campaign_csv::write(&csv, &out.campaign).unwrap();
    let prep = prepare(&out.campaign, &m.layout.travel, &m.expansion).unwrap();
    let sol = volcal::solve(&m.layout, &prep.obs, &m.solve_options(), &[]).unwrap();
    let model = dir.join("model.json");
    ModelFile::from_solution(&sol, &prep.obs.groups, Provenance::default()).write(&model).unwrap();
    let result = dir.join("peer.json");
    let o = std::process::Command::new(py)
        .arg(volcal_tests::repo_root().join("benches/peer/reduced_lsq.py"))
        .args([
            csv.to_str().unwrap(),
            "--intervals",
            "12",
            "--compare",
            model.to_str().unwrap(),
            "--json",
            result.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    eprintln!("{}", String::from_utf8_lossy(&o.stdout));
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(&result).unwrap()).unwrap();
    let max = r["max_volumetric_difference_m"].as_f64().unwrap();
    // The peer uses the small-angle model; volcal the exact chain: they differ at second order.
    assert!(max < 10e-9, "volcal and the SciPy peer differ by {max} m");
}
