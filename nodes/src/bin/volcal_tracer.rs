//! ROS 2 node `tracer` of the volcal node set (see `volcal_nodes::node::tracer`).

fn main() -> std::process::ExitCode {
    volcal_nodes::node::run("tracer", volcal_nodes::node::tracer::run)
}
