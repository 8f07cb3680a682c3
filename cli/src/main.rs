//! `volcal`: laser-interferometric calibration of Cartesian machines.

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;
use volcal_cli::commands::{self, SolveStatus};
use volcal_cli::{paper_cmd, validation};
use volcal_formats::merge;

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
        /// Also write the simulation truth (JSON), with the injected effects and their
        /// parameters.
        #[arg(long)]
        truth: Option<PathBuf>,
        /// Inject a physical effect outside the rigid-body model: ID[:key=value,...], e.g.
        /// latency:latency_s=2e-5. Repeat (or join with +) to combine. Ids: air_refraction,
        /// material_expansion, setup_drift, latency, reversal, periodic_pitch, nonrigid,
        /// probe_offset, beam_break, cyclic_nonlinearity, unmodelled_bump.
        #[arg(long = "inject", value_name = "SPEC")]
        inject: Vec<String>,
        /// Keep the injected effects out of the campaign file (a blind test: only the truth
        /// file says what was injected). Without it the file's header names them.
        #[arg(long)]
        conceal: bool,
        /// Air temperature drift during the campaign, kelvin per hour (default: the machine
        /// file's).
        #[arg(long, allow_hyphen_values = true)]
        air_rate: Option<f64>,
        /// Record the air (temperature, pressure, humidity) with every reading.
        #[arg(long)]
        record_air: bool,
        /// Simulate the machine under a controller applying the compensation in this directory (from `volcal export`): a volumetric grid (grid.csv, interpolated trilinearly, added to the command), ISG volumetric tables (isg_x.csv, isg_y.csv, isg_z.csv: the 21 functions through the machine's chain, at the active tool), SINUMERIK EEC and CEC tables (eec.mpf, cec.mpf) or LinuxCNC COMP_FILEs (x.comp, y.comp, z.comp): measure the compensated machine.
        #[arg(long)]
        compensation: Option<PathBuf>,
        /// COMP_FILE_TYPE of the --compensation files (0 or 1).
        #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=1))]
        comp_type: u8,
        /// Seed of the measurement noise (default: --seed, which also draws the machine): the same machine measured again with new noise.
        #[arg(long)]
        noise_seed: Option<u64>,
    },
    /// Find out why a campaign disagrees with the model: locate the excess residual, name the
    /// physics left out, model it and show the fit improve.
    #[command(after_help = "Example:
  volcal diagnose campaign.csv --machine launch_configs/machines/demo_cmm.yaml --json diagnosis.json
  volcal diagnose bags/concealed/setup_drift.csv --machine launch_configs/machines/diagnosis_cmm.yaml --rerun diagnosis.rrd

The catalogue: air_refraction, material_expansion, setup_drift, latency, reversal, periodic_pitch, nonrigid, probe_offset, beam_break, cyclic_nonlinearity. An effect is named only when its nested-model F-test is significant (Bonferroni over all candidates, 0.1 %), its BIC improves, it explains at least 30 % of the excess, it predicts held-out lines, and it does not rest on a single line; what remains is reported as unexplained, with where it is concentrated.")]
    Diagnose {
        /// Campaign file (.csv, or a bag recorded by the node set).
        campaign: PathBuf,
        /// Machine file (YAML): topology and travel are enough (`representation: auto`).
        #[arg(long)]
        machine: PathBuf,
        /// Write the diagnosis (JSON).
        #[arg(long)]
        json: Option<PathBuf>,
        #[command(flatten)]
        rerun: volcal_viz::RerunArgs,
    },
    /// Identify the error model from a campaign (CSV or MCAP bag).
    #[command(
        after_help = "Example:\n  volcal solve campaign.csv --machine launch_configs/machines/demo_cmm.yaml --out model.json\n  volcal solve campaign.csv --machine launch_configs/machines/demo_cmm.yaml --out model.json --rerun solve.rrd\n\nExit status: 0 complete; 3 model written but some functions are not identifiable (see the report); 4 not converged; 1 error."
    )]
    Solve {
        /// Campaign file (.csv, or .mcap from the recorder).
        campaign: PathBuf,
        /// Machine file (YAML): topology and travel are enough (`representation: auto`).
        #[arg(long)]
        machine: PathBuf,
        /// Model file (JSON) to write.
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        rerun: volcal_viz::RerunArgs,
    },
    /// Predict the volumetric error and its uncertainty at given points.
    #[command(
        after_help = "Example:\n  volcal predict model.json points.csv --out errors.csv\n\npoints.csv has columns x_m,y_m,z_m and optionally px_m,py_m,pz_m; errors.csv repeats them and adds ex_m,ey_m,ez_m,u95_m (u95: expanded uncertainty, k = 2, along the least favourable direction), determined (0: the readings do not determine the error there, or the point lies outside the calibrated travel; no value is given) and interpolated (1: between the measured positions of an axis the readings resolve only there, e.g. a tracer's stops)."
    )]
    Predict {
        /// Model file (JSON, from `volcal solve`).
        model: PathBuf,
        /// Points (CSV: x_m,y_m,z_m, optionally px_m,py_m,pz_m).
        points: PathBuf,
        /// Errors to write (CSV).
        #[arg(long)]
        out: PathBuf,
    },
    /// Volumetric error map on a regular grid over the travel.
    #[command(after_help = "Example:\n  volcal map model.json --step 0.05 --out map.csv --probe 0,0,-0.1")]
    Map {
        /// Model file (JSON, from `volcal solve`).
        model: PathBuf,
        /// Grid spacing, metres.
        #[arg(long, default_value_t = 0.05)]
        step: f64,
        /// Probe offset px,py,pz in metres.
        #[arg(long, default_value = "0,0,0", allow_hyphen_values = true)]
        probe: String,
        /// Map to write (CSV: the point, the error, its U95, whether the data determine it and
        /// whether it is interpolated between measured positions).
        #[arg(long)]
        out: PathBuf,
    },
    /// Write compensation files a controller loads (LinuxCNC COMP_FILEs, ISG/TwinCAT volumetric tables, SINUMERIK EEC/CEC, a volumetric grid), with a README.txt.
    #[command(
        after_help = "Example:\n  volcal export model.json --format linuxcnc --out comp/ --step-mm 10 --point 0.5,0.4,-0.3\n  volcal export model.json --format grid --out grid/ --step-mm 50\n  volcal export model.json --format isg --out isg/ --step-mm 10\n  volcal export model.json --format sinumerik --out sin/ --step-mm 20 --point 0.5,0.4,-0.3 --diagnosis diag.json\n\nREADME.txt in the output directory says how to load the files, what the format drops and the error that remains."
    )]
    Export {
        /// Model file (JSON, from `volcal solve`).
        model: PathBuf,
        /// The controller's format.
        #[arg(long, value_enum)]
        format: volcal_cli::export_cmd::Format,
        /// Directory to write the files and their README.txt to.
        #[arg(long)]
        out: PathBuf,
        /// Node spacing, millimetres (default: linuxcnc 10, isg 10, sinumerik 20, grid 50).
        #[arg(long, allow_hyphen_values = true)]
        step_mm: Option<f64>,
        /// Where the nodes lie: `even` (--step-mm apart) or `measured` (at the measured positions, e.g. a tracer's stops, of each axis whose readings contradict the interpolation between them: the only tables the data determine there; even on the others).
        #[arg(long, value_enum, default_value = "even")]
        nodes: volcal_cli::export_cmd::NodePlacement,
        /// Where the other axes stand for each joint's table, x,y,z in metres (machine coordinates; default: the travel's centre).
        #[arg(long, allow_hyphen_values = true)]
        point: Option<String>,
        /// Tool (probe) offset px,py,pz in metres the tables refer to.
        #[arg(long, default_value = "0,0,0", allow_hyphen_values = true)]
        probe: String,
        /// LinuxCNC COMP_FILE_TYPE: 0 (columns are actual positions) or 1 (columns are offsets).
        #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=1))]
        comp_type: u8,
        /// A `volcal diagnose --json` file: its reversal error (backlash) goes into the LinuxCNC forward/reverse columns, SINUMERIK MD32450 or ISG P-AXIS-00103.
        #[arg(long)]
        diagnosis: Option<PathBuf>,
    },
    /// Evaluate a bidirectional positioning test to ISO 230-2:2014: accuracy A, repeatability R,
    /// reversal value B, systematic error E, mean bidirectional error M, per direction too.
    #[command(
        name = "iso230-2",
        after_help = "Example:\n  volcal iso230-2 tests/data/iso230_2/ecmc_fat_sat.csv --json figures.json --plot deviations.png\n\nRUNS.csv has the header target_mm,run,direction,deviation_um: one row per approach, direction + (moving up) or - (moving down), deviation = measured minus commanded position in micrometres. The JSON holds A, A_up, A_down, E, E_up, E_down, R, R_up, R_down, B, B_mean, M (micrometres) and the per-target table."
    )]
    Iso230_2 {
        /// Runs file (CSV).
        runs: PathBuf,
        /// Write the figures and the per-target table (JSON).
        #[arg(long)]
        json: Option<PathBuf>,
        /// Draw the deviations, means and +-2s bands (PNG).
        #[arg(long)]
        plot: Option<PathBuf>,
    },
    /// Print a model's report (or a bag's: what was recorded and paired); optionally write per-axis compensation tables.
    #[command(
        after_help = "Example:\n  volcal report model.json --compensation-dir comp/ --points 101\n  volcal report bags/sim_short          (a bag: topics, pairs, pairing; and model.json if the solver node left one there)"
    )]
    Report {
        /// Model file (JSON), or a bag directory from the recorder.
        model: PathBuf,
        /// Write compensation_x.csv, compensation_y.csv, compensation_z.csv here.
        #[arg(long)]
        compensation_dir: Option<PathBuf>,
        /// Positions per compensation table.
        #[arg(long, default_value_t = 51)]
        points: usize,
    },
    /// Start the ROS 2 nodes of a YAML launch description (ROS 2 launch-file subset).
    #[command(
        after_help = "Example:\n  volcal launch launch_configs/sim_campaign_short.yaml --bag /tmp/short --domain 42\n  volcal launch launch_configs/replay.yaml --bag /tmp/short\n\nLaunch arguments are given as name:=value. Node output is forwarded with the node name as prefix. Ctrl-C stops all nodes cleanly; so does the end of a node marked on_exit: shutdown (the sequencer, the solver). Exit status 1 if a node failed."
    )]
    Launch {
        /// Launch file (YAML).
        file: PathBuf,
        /// Value of the launch argument `bag` (the bag to record or replay).
        #[arg(long)]
        bag: Option<PathBuf>,
        /// ROS_DOMAIN_ID for the nodes.
        #[arg(long)]
        domain: Option<u16>,
        /// Launch arguments, name:=value.
        #[arg(value_name = "NAME:=VALUE")]
        args: Vec<String>,
    },
    /// Run one ROS 2 node of the node set (what its own binary, e.g. volcal_recorder, does).
    #[command(
        hide = true,
        after_help = "Example:\n  volcal node recorder --ros-args -p bag:=/tmp/bag",
        disable_help_flag = true
    )]
    Node {
        /// Node (interferometer, tracer, deflector, machine, environment, sequencer, recorder, solver).
        name: String,
        /// Node arguments: --ros-args -p name:=value -r from:=to ...
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// Inspect a bag: messages per topic, and what was recovered from an unclosed one.
    #[command(after_help = "Example:\n  volcal bag info bags/sim_short")]
    Bag {
        #[command(subcommand)]
        command: BagCommand,
    },
    /// Throughput benchmarks of the recording chain (figures in README).
    #[command(
        after_help = "Examples:\n  volcal bench recorder --rate 1000 --duration 60\n  volcal bench recorder --rate 1000 --duration 60 --viz\n  volcal bench recorder --rate 10000 --duration 60 --batch 100\n  volcal bench replay /tmp/volcal-bench-recorder-1234"
    )]
    Bench {
        #[command(subcommand)]
        command: BenchCommand,
    },
    /// Positioning error along lines (ISO 230-2 style), predicted with uncertainty and optionally
    /// compared with a simulated laser interferometer.
    #[command(
        after_help = "Examples:\n  volcal validate model.json --axis x\n  volcal validate model.json --diagonals --truth truth.json --machine launch_configs/machines/paper_cmm.yaml\n  volcal validate model.json --axis y --start 0,0,-0.7 --points 11 --out y.csv\n  volcal validate model.json --line 0,0,-0.7:0.7,-0.5,0\n\nThe deviation at each target is the model's volumetric error projected on the line, referred to the start (where an interferometer would be zeroed). Diagonals are the paper's Table 4 (NPP, NPN, PPN, PPP). With --truth (a simulation truth file) each line is also measured by a simulated interferometer on the true machine, --runs bidirectional runs averaged, and the differences reported; with --compensation too, the machine is measured under its controller's compensation (after `volcal export`): the verification of a compensation along its axes.\n  volcal validate model.json --axis x --start 0.4,0.25,-0.25 --truth truth.json --machine M.yaml --compensation comp/"
    )]
    Validate {
        /// Model file (JSON, from `volcal solve`).
        model: PathBuf,
        /// Axis line: x, y or z.
        #[arg(long, conflicts_with_all = ["diagonals", "line"])]
        axis: Option<String>,
        /// The four body diagonals NPP, NPN, PPN, PPP.
        #[arg(long, conflicts_with = "line")]
        diagonals: bool,
        /// Any line x0,y0,z0:x1,y1,z1 in metres.
        #[arg(long, allow_hyphen_values = true)]
        line: Option<String>,
        /// Start of the axis line x,y,z in metres (default: lower end, other axes centred).
        #[arg(long, allow_hyphen_values = true, requires = "axis")]
        start: Option<String>,
        /// Targets per line, ends included.
        #[arg(long, default_value_t = 11)]
        points: usize,
        /// Probe offset px,py,pz in metres.
        #[arg(long, default_value = "0,0,0", allow_hyphen_values = true)]
        probe: String,
        /// Simulation truth (JSON): also measure each line with a simulated interferometer.
        #[arg(long)]
        truth: Option<PathBuf>,
        /// Machine file whose simulation section gives the interferometer and repeatability.
        #[arg(long, requires = "truth")]
        machine: Option<PathBuf>,
        /// Bidirectional runs averaged per line.
        #[arg(long, default_value_t = 5)]
        runs: usize,
        /// Seed of the simulated interferometer's repeatability (with --truth).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Write the lines as CSV.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Measure the simulated machine under a controller applying the compensation in this directory (from `volcal export`: LinuxCNC COMP_FILEs, grid.csv, ISG tables or SINUMERIK EEC/CEC): the ISO 230-2 verification of a compensation. Needs --truth.
        #[arg(long, requires = "truth")]
        compensation: Option<PathBuf>,
        /// COMP_FILE_TYPE of the --compensation files (0 or 1).
        #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=1))]
        comp_type: u8,
    },
    /// Reproduce the laser-tracer scenario of Han et al. (2021): simulate, solve, Table 2,
    /// volumetric maximum, axis and diagonal validation.
    #[command(after_help = "Example:\n  volcal paper --workdir paper/")]
    Paper {
        /// Keep the files here instead of a temporary directory.
        #[arg(long)]
        workdir: Option<PathBuf>,
        /// Random seed of the campaign and the validation runs (the paper's machine is fixed: the
        /// seed draws the noise).
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// Merge campaigns of one machine (e.g. fixed beams and tracer ranges) for a joint solve.
    #[command(
        after_help = "Example:\n  volcal merge beams.csv ranges.csv --out joint.csv\n  volcal solve joint.csv --machine M.yaml --out model.json\n\nStation ids already used by an earlier file for the same kind are renumbered; times are shifted so that each campaign follows the previous one."
    )]
    Merge {
        /// Campaign files (CSV) of the same machine, in the order they were measured.
        #[arg(required = true, num_args = 1..)]
        campaigns: Vec<PathBuf>,
        /// Merged campaign to write (CSV).
        #[arg(long)]
        out: PathBuf,
    },
    /// Run the whole chain on the built-in example (offline, then through the ROS 2 node set: launch, record, replay, solve) and compare with the truth.
    #[command(after_help = "Example:\n  volcal demo")]
    Demo {
        /// Keep the files here instead of a temporary directory.
        #[arg(long)]
        workdir: Option<PathBuf>,
        /// Random seed (truth and noise).
        #[arg(long, default_value_t = 7)]
        seed: u64,
    },
}

#[derive(Subcommand)]
enum BenchCommand {
    /// Publish an on-the-fly acquisition to the recorder node and count the pairs it records.
    Recorder {
        /// Sampling rate of the interferometer and the machine, Hz.
        #[arg(long, default_value_t = 1000.0)]
        rate: f64,
        /// Seconds.
        #[arg(long, default_value_t = 60.0)]
        duration: f64,
        /// Samples per message (1: one message per sample; more: the batched message types).
        #[arg(long, default_value_t = 1)]
        batch: usize,
        /// Keep the bag here (default: a temporary directory, printed).
        #[arg(long)]
        bag: Option<PathBuf>,
        /// Do not publish the pairs on /campaign/pairs (bag only).
        #[arg(long)]
        no_publish_pairs: bool,
        /// Also run the viz node watching the acquisition live (saving BAG.viz.rrd): its CPU share and lag.
        #[arg(long, conflicts_with = "no_publish_pairs")]
        viz: bool,
    },
    /// Read and decode every message of a bag; messages per second.
    Replay {
        /// Bag directory (from `volcal bench recorder` or the recorder node).
        bag: PathBuf,
    },
}

#[derive(Subcommand)]
enum BagCommand {
    /// Messages per topic (read from the MCAP data, not from metadata.yaml).
    Info {
        /// Bag directory (rosbag2: metadata.yaml and .mcap files), or one .mcap file.
        bag: PathBuf,
    },
}

fn run() -> anyhow::Result<ExitCode> {
    let cli = Cli::parse();
    match cli.command {
        Command::Simulate {
            machine,
            plan,
            seed,
            out,
            truth,
            inject,
            conceal,
            air_rate,
            record_air,
            compensation,
            comp_type,
            noise_seed,
        } => {
            use volcal_formats::compensation::CompFileType;
            let kind = if comp_type == 1 { CompFileType::Offset } else { CompFileType::Actual };
            let opts = commands::SimulateOptions {
                inject,
                conceal,
                air_rate_k_per_h: air_rate,
                record_air,
                compensation: compensation.map(|d| (d, kind)),
                noise_seed,
            };
            commands::simulate_cmd(&machine, plan.as_deref(), seed, &out, truth.as_deref(), &opts)?
        }
        Command::Diagnose { campaign, machine, json, rerun } => {
            rerun.validate()?;
            let d = volcal_cli::diagnosis::diagnose_cmd(&campaign, &machine, json.as_deref())?;
            print!("{}", d.report);
            let name = format!("volcal diagnose {}", campaign.display());
            volcal_viz::diagnosis::record(&rerun, &name, &d.obs, &d.diagnosis, &d.report)?;
            if let Some(j) = json {
                eprintln!("wrote the diagnosis to {}", j.display());
            }
        }
        Command::Solve { campaign, machine, out, rerun } => {
            rerun.validate()?;
            let (solved, status) = commands::solve_cmd(&campaign, &machine, &out)?;
            let name = format!("volcal solve {}", campaign.display());
            volcal_viz::solve::record(&rerun, &name, &solved.prepared.obs, &solved.solution)?;
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
            let n = commands::map_cmd(&model, step, commands::parse_option_vec3("--probe", &probe)?, &out)?;
            eprintln!("wrote {n} grid points to {}", out.display());
        }
        Command::Export { model, format, out, step_mm, nodes, point, probe, comp_type, diagnosis } => {
            use volcal_formats::compensation::CompFileType;
            let opts = volcal_cli::export_cmd::ExportOptions {
                format,
                step_m: step_mm.map(|s| s * 1e-3),
                nodes,
                point: point
                    .as_deref()
                    .map(|p| commands::parse_option_vec3("--point", p))
                    .transpose()?
                    .map(nalgebra::Point3::from),
                probe: commands::parse_option_vec3("--probe", &probe)?,
                comp_type: if comp_type == 1 { CompFileType::Offset } else { CompFileType::Actual },
                diagnosis,
            };
            print!("{}", volcal_cli::export_cmd::export_cmd(&model, &out, &opts)?);
        }
        Command::Iso230_2 { runs, json, plot } => {
            let (text, wrote) = volcal_cli::iso230_2_cmd::iso230_2_cmd(&runs, json.as_deref(), plot.as_deref())?;
            print!("{text}");
            for w in wrote {
                eprintln!("{w}");
            }
        }
        Command::Report { model, compensation_dir, points } => {
            if volcal_cli::launch_cmd::is_bag(&model) {
                print!("{}", volcal_cli::launch_cmd::bag_report(&model, compensation_dir.as_deref(), points)?)
            } else {
                print!("{}", commands::report_cmd(&model, compensation_dir.as_deref(), points)?)
            }
        }
        Command::Demo { workdir, seed } => commands::demo_cmd(workdir.as_deref(), seed)?,
        Command::Launch { file, bag, domain, args } => {
            return volcal_cli::launch_cmd::launch_cmd(&file, bag.as_deref(), domain, &args);
        }
        Command::Bench { command: BenchCommand::Recorder { rate, duration, batch, bag, no_publish_pairs, viz } } => {
            let b = volcal_cli::bench::RecorderBench {
                rate_hz: rate,
                duration_s: duration,
                batch,
                bag,
                publish_pairs: !no_publish_pairs,
                viz,
            };
            let r = volcal_cli::bench::recorder(&b)?;
            println!("{}", r.describe(&b));
            if !r.complete() {
                return Ok(ExitCode::from(2));
            }
        }
        Command::Bench { command: BenchCommand::Replay { bag } } => {
            println!("{}", volcal_cli::bench::replay(&bag)?.describe(&bag))
        }
        Command::Node { name, args } => {
            let (default_name, body) = volcal_nodes::node::by_name(&name)
                .ok_or_else(|| anyhow::anyhow!("no node {name:?} (expected interferometer, tracer, deflector, machine, environment, sequencer, recorder or solver)"))?;
            return Ok(volcal_nodes::node::run_with_args(default_name, body, args));
        }
        Command::Bag { command: BagCommand::Info { bag } } => print!("{}", volcal_cli::launch_cmd::bag_info(&bag)?),
        Command::Validate {
            model,
            axis,
            diagonals,
            line,
            start,
            points,
            probe,
            truth,
            machine,
            runs,
            seed,
            out,
            compensation,
            comp_type,
        } => {
            let lines = match (axis, diagonals, line) {
                (Some(a), _, _) => {
                    let axis = volcal::Axis::from_letter(a.trim().chars().next().unwrap_or(' ').to_ascii_uppercase())
                        .filter(|_| a.trim().len() == 1)
                        .ok_or_else(|| anyhow::anyhow!("--axis {a:?}: expected x, y or z"))?;
                    let start = start
                        .as_deref()
                        .map(|s| commands::parse_option_vec3("--start", s))
                        .transpose()?
                        .map(nalgebra::Point3::from);
                    validation::LineSpec::Axis { axis, start }
                }
                (None, true, _) => validation::LineSpec::Diagonals,
                (None, false, Some(l)) => validation::LineSpec::Custom(validation::parse_line(&l)?),
                (None, false, None) => anyhow::bail!("say which lines: --axis x|y|z, --diagonals or --line"),
            };
            let args = validation::ValidateArgs {
                model: &model,
                lines,
                points,
                probe: commands::parse_option_vec3("--probe", &probe)?,
                truth: truth.as_deref(),
                machine: machine.as_deref(),
                runs,
                seed,
                out: out.as_deref(),
                compensation: compensation.as_deref().map(|d| {
                    use volcal_formats::compensation::CompFileType;
                    (d, if comp_type == 1 { CompFileType::Offset } else { CompFileType::Actual })
                }),
            };
            print!("{}", validation::validate_cmd(&args)?);
        }
        Command::Paper { workdir, seed } => paper_cmd::paper_cmd(workdir.as_deref(), seed)?,
        Command::Merge { campaigns, out } => {
            let mut read = Vec::new();
            for p in &campaigns {
                read.push((p.display().to_string(), volcal_bag::campaign::load_campaign(p)?));
            }
            let (merged, notes) = merge::merge(read)?;
            for n in notes {
                eprintln!("note: {n}");
            }
            volcal_formats::campaign_csv::write(&out, &merged)?;
            eprintln!("wrote {} readings to {}", merged.readings.len(), out.display());
        }
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
