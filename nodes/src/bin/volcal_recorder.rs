//! ROS 2 node `recorder` of the volcal node set (see `volcal_nodes::node::recorder`).

fn main() -> std::process::ExitCode {
    volcal_nodes::node::run("recorder", volcal_nodes::node::recorder::run)
}
