//! ROS 2 node `machine` of the volcal node set (see `volcal_nodes::node::machine`).

fn main() -> std::process::ExitCode {
    volcal_nodes::node::run("machine", volcal_nodes::node::machine::run)
}
