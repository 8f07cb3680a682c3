//! ROS 2 node `viz` of the volcal node set (see `volcal_nodes::node::viz`): its `--rerun*`
//! flags become parameters, then it runs like every node.

fn main() -> std::process::ExitCode {
    match volcal_nodes::node::viz::command_line(std::env::args().skip(1).collect()) {
        Ok(args) => volcal_nodes::node::run_with_args("viz", volcal_nodes::node::viz::run, args),
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
