//! ROS 2 node `deflector` of the volcal node set (see `volcal_nodes::node::deflector`).

fn main() -> std::process::ExitCode {
    volcal_nodes::node::run("deflector", volcal_nodes::node::deflector::run)
}
