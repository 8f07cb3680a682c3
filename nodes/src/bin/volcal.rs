//! `volcal`: laser-interferometric calibration of Cartesian machines.

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;
use volcal_nodes::commands::{self, SolveStatus};

#[derive(Parser)]
#[command(name = "volcal", version, about = "Identify the 21 geometric error functions of a Cartesian machine from laser-interferometer data", long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a campaign on a virtual machine.
    #[command(
        after_help = "Example:\n  volcal simulate --machine launch_configs/machines/demo_cmm.yaml --seed 7 --out campaign.csv --truth truth.json"
    )]
    Simulate {
        /// Machine file (YAML).
        #[arg(long)]
        machine: PathBuf,
        /// Campaign plan (YAML); default: the patent's example, 3 positions x 25 beams x 100 points.
        #[arg(long)]
        plan: Option<PathBuf>,
        /// Random seed (truth and noise).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Campaign CSV to write.
        #[arg(long)]
        out: PathBuf,
        /// Also write the simulation truth (JSON).
        #[arg(long)]
        truth: Option<PathBuf>,
    },
    /// Identify the error model from a campaign (CSV or MCAP bag).
    #[command(
        after_help = "Example:\n  volcal solve campaign.csv --machine launch_configs/machines/demo_cmm.yaml --out model.json\n  volcal solve campaign.csv --machine launch_configs/machines/demo_cmm.yaml --out model.json --rerun solve.rrd\n\nExit status: 0 complete; 3 model written but some functions are not identifiable (see the report); 4 not converged; 1 error."
    )]
    Solve {
        /// Campaign file (.csv, or .mcap from the recorder).
        campaign: PathBuf,
        #[arg(long)]
        machine: PathBuf,
        /// Model file (JSON) to write.
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        rerun: volcal_nodes::viz::RerunArgs,
    },
    /// Predict the volumetric error and its uncertainty at given points.
    #[command(
        after_help = "Example:\n  volcal predict model.json points.csv --out errors.csv\n\npoints.csv has columns x_m,y_m,z_m and optionally px_m,py_m,pz_m; errors.csv repeats them and adds ex_m,ey_m,ez_m,u95_m (u95: expanded uncertainty, k = 2, along the least favourable direction)."
    )]
    Predict {
        model: PathBuf,
        points: PathBuf,
        #[arg(long)]
        out: PathBuf,
    },
    /// Volumetric error map on a regular grid over the travel.
    #[command(after_help = "Example:\n  volcal map model.json --step 0.05 --out map.csv --probe 0,0,-0.1")]
    Map {
        model: PathBuf,
        /// Grid spacing, metres.
        #[arg(long, default_value_t = 0.05)]
        step: f64,
        /// Probe offset px,py,pz in metres.
        #[arg(long, default_value = "0,0,0", allow_hyphen_values = true)]
        probe: String,
        #[arg(long)]
        out: PathBuf,
    },
    /// Print a model's report; optionally write per-axis compensation tables.
    #[command(after_help = "Example:\n  volcal report model.json --compensation-dir comp/ --points 101")]
    Report {
        model: PathBuf,
        /// Write compensation_x.csv, compensation_y.csv, compensation_z.csv here.
        #[arg(long)]
        compensation_dir: Option<PathBuf>,
        /// Positions per compensation table.
        #[arg(long, default_value_t = 51)]
        points: usize,
    },
    /// Run the whole offline chain on the built-in example and compare with the truth.
    #[command(after_help = "Example:\n  volcal demo")]
    Demo {
        /// Keep the files here instead of a temporary directory.
        #[arg(long)]
        workdir: Option<PathBuf>,
        #[arg(long, default_value_t = 7)]
        seed: u64,
    },
}

fn run() -> anyhow::Result<ExitCode> {
    let cli = Cli::parse();
    match cli.command {
        Command::Simulate { machine, plan, seed, out, truth } => {
            commands::simulate_cmd(&machine, plan.as_deref(), seed, &out, truth.as_deref())?
        }
        Command::Solve { campaign, machine, out, rerun } => {
            rerun.validate()?;
            let (solved, status) = commands::solve_cmd(&campaign, &machine, &out)?;
            let name = format!("volcal solve {}", campaign.display());
            volcal_nodes::viz::solve::record(&rerun, &name, &solved.prepared.obs, &solved.solution)?;
            return Ok(match status {
                SolveStatus::Complete => ExitCode::SUCCESS,
                SolveStatus::Partial => ExitCode::from(3),
                SolveStatus::NotConverged => ExitCode::from(4),
            });
        }
        Command::Predict { model, points, out } => {
            let n = commands::predict_cmd(&model, &points, &out)?;
            eprintln!("wrote {n} predictions to {}", out.display());
        }
        Command::Map { model, step, probe, out } => {
            let n = commands::map_cmd(&model, step, commands::parse_vec3(&probe)?, &out)?;
            eprintln!("wrote {n} grid points to {}", out.display());
        }
        Command::Report { model, compensation_dir, points } => {
            print!("{}", commands::report_cmd(&model, compensation_dir.as_deref(), points)?)
        }
        Command::Demo { workdir, seed } => commands::demo_cmd(workdir.as_deref(), seed)?,
    }
    Ok(ExitCode::SUCCESS)
}

fn main() -> ExitCode {
    match run() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
