//! ROS 2 node `sequencer` of the volcal node set (see `volcal_nodes::node::sequencer`).

fn main() -> std::process::ExitCode {
    volcal_nodes::node::run("sequencer", volcal_nodes::node::sequencer::run)
}
