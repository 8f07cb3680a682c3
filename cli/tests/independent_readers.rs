//! Independent readers (acceptance 2): every sample bag in `bags/` decodes with the Python
//! packages `rosbags` and `mcap-ros2-support` (pinned in `.ci/requirements.txt`), which count
//! the same messages per topic, and read the same stamps and pair values, as volcal's reader.

mod common;

#[test]
fn sample_bags_decode_with_rosbags_and_mcap_ros2_support() {
    let dir = common::repo().join("bags");
    let mut bags: Vec<std::path::PathBuf> = std::fs::read_dir(&dir)
        .expect("bags/ is missing")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("metadata.yaml").exists())
        .collect();
    bags.sort();
    assert!(!bags.is_empty(), "no bags in {}", dir.display());
    common::check_with_independent_readers(&bags);
}
