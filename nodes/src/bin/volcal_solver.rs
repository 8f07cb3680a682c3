//! ROS 2 node `solver` of the volcal node set (see `volcal_nodes::node::solver`).

fn main() -> std::process::ExitCode {
    volcal_nodes::node::run("solver", volcal_nodes::node::solver::run)
}
