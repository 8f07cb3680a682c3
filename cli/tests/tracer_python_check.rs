//! An independent client checks a tracer solve: a Python script (standard library only) reads
//! the campaign CSV and the model JSON, evaluates the error model with its own code and
//! recomputes every range from the model's stations. Its residual RMS per station must equal the
//! one the model file reports, and the truth file must explain the readings to noise level.

use std::process::Command;
use volcal_cli::commands;

#[test]
fn python_recomputes_the_tracer_residuals() {
    let Some(py) = volcal_tests::checker_python() else { return };
    let root = volcal_tests::repo_root();
    let dir = volcal_tests::scratch("tracer-python");
    let machine = root.join("launch_configs/machines/paper_cmm.yaml");
    let plan = root.join("launch_configs/plans/paper_tracer.yaml");
    let (campaign, truth, model) = (dir.join("campaign.csv"), dir.join("truth.json"), dir.join("model.json"));
    commands::simulate_cmd(&machine, Some(&plan), 3, &campaign, Some(&truth), &Default::default()).unwrap();
    commands::solve_cmd(&campaign, &machine, &model).unwrap();
    let out = Command::new(py)
        .arg(root.join("tests/py/check_tracer_model.py"))
        .args([&campaign, &model, &truth])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    eprintln!("{text}{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "the Python checker disagrees:\n{text}");
    assert_eq!(text.matches(" ok").count(), 8, "{text}");
}
