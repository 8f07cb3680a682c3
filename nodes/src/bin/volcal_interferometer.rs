//! ROS 2 node `interferometer` of the volcal node set (see `volcal_nodes::node::interferometer`).

fn main() -> std::process::ExitCode {
    volcal_nodes::node::run("interferometer", volcal_nodes::node::interferometer::run)
}
