//! ROS 2 node `environment` of the volcal node set (see `volcal_nodes::node::environment`).

fn main() -> std::process::ExitCode {
    volcal_nodes::node::run("environment", volcal_nodes::node::environment::run)
}
