//! The viz node: watches a campaign live in Rerun. It subscribes to the campaign topics and
//! feeds [`volcal_viz::live::LiveViz`]: `/campaign/pairs` (the recorder's synchronised pairs),
//! `/machine/position` and `/machine/position_batch` (the current point), `/deflector/command`
//! and `/deflector/state` (stations, commanded beams, the beam now), `/sequencer/status`
//! (progress), and `/diagnosis` (a live solver node's diagnoses: flagged beams, residuals per
//! line before and after the refit). It only listens: nothing it does reaches the recorder.
//!
//! Output, as on `volcal solve`: `volcal_viz --rerun FILE.rrd`, `--rerun-connect [ADDR]`,
//! `--rerun-spawn` before `--ros-args`, or the parameters `rerun`, `rerun_connect`,
//! `rerun_spawn` (launch files). Other parameters: `machine` (machine file: draws the working
//! volume), `flush_period_s` (0.05: display rate), `report` (a JSON file written at exit with
//! what was received and how far behind the node ran).
//!
//! Keeping up is measured, not assumed: for every machine sample and pair the node records its
//! lag, wall clock at processing minus the message's stamp; a node that keeps up has a lag that
//! stays flat, one that falls behind has a lag that grows. The lags of the first and the last
//! ten seconds are compared in the exit report.

use super::runtime::{secs, TICK};
use crate::ros::{now_ns, qos, shutdown, RosNode};
use anyhow::{bail, Context, Result};
use clap::Parser;
use nalgebra::{Point3, Vector3};
use std::path::PathBuf;
use std::time::Instant;
use volcal_bag::convert;
use volcal_formats::machine::Machine;
use volcal_msgs::msg::*;
use volcal_msgs::topics;
use volcal_sim::instruments::direction_from_angles;
use volcal_viz::live::{DeflectorState, LineVerdict, LiveDiagnosis, LiveViz};
use volcal_viz::{blueprint, RerunArgs};

/// The node's own flags, before `--ros-args`.
#[derive(Parser, Debug)]
#[command(
    name = "volcal_viz",
    about = "Watch a volcal campaign live in Rerun (ROS 2 node; its parameters go after --ros-args)",
    after_help = "Examples:\n  volcal_viz --rerun-spawn --ros-args -p machine:=launch_configs/machines/demo_cmm.yaml\n  volcal_viz --rerun-connect --rerun campaign.rrd --ros-args -p machine:=M.yaml"
)]
struct Cli {
    #[command(flatten)]
    rerun: RerunArgs,
}

/// Turns `volcal_viz [--rerun ...] [--ros-args ...]` into ROS arguments: the flags become the
/// parameters `rerun`, `rerun_connect`, `rerun_spawn`.
pub fn command_line(args: Vec<String>) -> Result<Vec<String>> {
    let split = args.iter().position(|a| a == "--ros-args").unwrap_or(args.len());
    let (own, ros) = args.split_at(split);
    let cli = Cli::try_parse_from(std::iter::once("volcal_viz".to_string()).chain(own.iter().cloned()))
        .map_err(|e| if e.use_stderr() { anyhow::anyhow!("{e}") } else { e.exit() })?;
    let mut out: Vec<String> = if ros.is_empty() { vec!["--ros-args".into()] } else { ros.to_vec() };
    if let Some(p) = &cli.rerun.save {
        out.extend(["-p".into(), format!("rerun:={}", p.display())]);
    }
    if let Some(a) = &cli.rerun.connect {
        out.extend(["-p".into(), format!("rerun_connect:={a}")]);
    }
    if cli.rerun.spawn {
        out.extend(["-p".into(), "rerun_spawn:=true".into()]);
    }
    Ok(out)
}

/// What the node received and how far behind it ran (the `report` file).
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct VizReport {
    pub pairs: u64,
    pub machine_samples: u64,
    pub deflector_messages: u64,
    pub flushes: u64,
    pub wall_s: f64,
    pub cpu_s: f64,
    /// Lag of the machine samples (processing time minus stamp), milliseconds: mean over the
    /// first and the last 10 s, and the largest.
    pub machine_lag_first_ms: f64,
    pub machine_lag_last_ms: f64,
    pub machine_lag_max_ms: f64,
    /// The same for the pairs (includes the recorder's pairing delay).
    pub pair_lag_first_ms: f64,
    pub pair_lag_last_ms: f64,
    pub pair_lag_max_ms: f64,
    /// Diagnoses received on `/diagnosis` (a live solver node's).
    #[serde(default)]
    pub diagnoses: u64,
}

/// What the live view shows of a `/diagnosis` message.
fn live_diagnosis(m: &Diagnosis) -> LiveDiagnosis {
    LiveDiagnosis {
        partial: m.partial,
        readings: m.n_readings as usize,
        rms_before_m: m.rms_before_m,
        rms_after_m: m.rms_after_m,
        noise_rms_m: m.noise_rms_m,
        statements: m.effects.iter().map(|e| e.statement.clone()).collect(),
        unexplained: (!m.unexplained.is_empty()).then(|| m.unexplained.clone()),
        lines: m
            .lines
            .iter()
            .map(|l| LineVerdict {
                station: l.station,
                line: l.line,
                rms_before_m: l.rms_before_m,
                rms_after_m: l.rms_after_m,
                flagged_by: l.flagged_by.clone(),
            })
            .collect(),
    }
}

/// Lags over time, for the first and last windows and the maximum.
#[derive(Default)]
struct LagStats {
    samples: Vec<(f64, f64)>,
    max_ms: f64,
}

impl LagStats {
    fn add(&mut self, wall_s: f64, lag_ms: f64) {
        self.samples.push((wall_s, lag_ms));
        self.max_ms = self.max_ms.max(lag_ms);
    }

    /// Mean lag over the first and over the last `window_s` seconds of samples.
    fn first_last(&self, window_s: f64) -> (f64, f64) {
        let (Some(a), Some(b)) = (self.samples.first(), self.samples.last()) else { return (0.0, 0.0) };
        let mean = |f: &dyn Fn(f64) -> bool| {
            let v: Vec<f64> = self.samples.iter().filter(|(t, _)| f(*t)).map(|s| s.1).collect();
            v.iter().sum::<f64>() / v.len().max(1) as f64
        };
        (mean(&|t| t <= a.0 + window_s), mean(&|t| t >= b.0 - window_s))
    }
}

/// The Rerun outputs from the node's parameters.
fn rerun_args(node: &RosNode) -> Result<RerunArgs> {
    let a = RerunArgs {
        save: node.args.path("rerun")?,
        // Empty: not asked for (a launch argument left at its default); `default` or `true`:
        // the default address.
        connect: node.args.get::<String>("rerun_connect")?.filter(|s| !s.is_empty()).map(|s| {
            if s == "default" || s == "true" {
                volcal_viz::DEFAULT_CONNECT_ADDR.to_string()
            } else {
                s
            }
        }),
        spawn: node.args.get_or("rerun_spawn", false)?,
    };
    if !a.enabled() {
        bail!("no Rerun output: give --rerun FILE.rrd, --rerun-connect [ADDR] or --rerun-spawn (parameters rerun, rerun_connect, rerun_spawn)");
    }
    a.validate()?;
    Ok(a)
}

pub fn run(node: &mut RosNode) -> Result<()> {
    let rerun = rerun_args(node)?;
    let machine = node.args.path("machine")?.map(|p| Machine::load(&p)).transpose()?;
    let flush_period = secs(node.args.get_or("flush_period_s", 0.05)?);
    let report_path: Option<PathBuf> = node.args.path("report")?;
    node.warn_unused_parameters();

    let d = qos::data;
    let mut pairs = node.subscription::<SyncedPair>(topics::PAIRS, d())?;
    let mut positions = node.subscription::<MachinePosition>(topics::MACHINE_POSITION, d())?;
    let mut batches = node.subscription::<MachinePositionBatch>(topics::MACHINE_POSITION_BATCH, d())?;
    let mut commands = node.subscription::<BeamCommand>(topics::DEFLECTOR_COMMAND, qos::commands())?;
    let mut states = node.subscription::<BeamState>(topics::DEFLECTOR_STATE, qos::latched())?;
    let mut status = node.subscription::<SequencerStatus>(topics::SEQUENCER_STATUS, qos::latched())?;
    let mut diagnoses = node.subscription::<Diagnosis>(topics::DIAGNOSIS, qos::latched())?;

    let travel = machine.as_ref().map(|m| m.layout.travel);
    let name = machine.as_ref().and_then(|m| m.file.name.clone()).unwrap_or_else(|| "machine".into());
    let rec = rerun
        .open(&format!("volcal live campaign ({})", node.name), &blueprint::live(travel.as_ref()))?
        .context("no Rerun output")?;
    let mut viz = LiveViz::new(rec, travel, &name)?;
    log::info!(
        "showing the campaign live in Rerun{}",
        rerun.save.as_ref().map(|p| format!(", saving to {}", p.display())).unwrap_or_default()
    );

    let wall = Instant::now();
    let cpu0 = super::recorder::cpu_seconds();
    // Campaign time of a stamp: the recorder's origin, learned from the first pair (t_s is
    // counted from it); until then, from this node's start.
    let mut t0_ns = now_ns();
    let mut t0_known = false;
    let mut last_command: Option<DeflectorState> = None;
    let mut report = VizReport::default();
    let (mut machine_lag, mut pair_lag) = (LagStats::default(), LagStats::default());
    let mut next_flush = Instant::now() + flush_period;
    let mut sequencer = String::new();
    let ts = |ns: i64, t0: i64| (ns - t0) as f64 * 1e-9;
    while !shutdown::requested() {
        node.wait(TICK);
        commands.drain(|m| {
            let state = DeflectorState {
                station: m.station,
                beam: m.beam,
                origin: Point3::from(m.device_position_m),
                direction: direction_from_angles(m.azimuth_rad, m.elevation_rad),
                azimuth_rad: m.azimuth_rad,
                elevation_rad: m.elevation_rad,
                settled: false,
            };
            last_command = Some(state);
            report.deflector_messages += 1;
            viz.beam_command(ts(m.header.stamp.to_nanos(), t0_ns), state)
        })?;
        states.drain(|m| {
            let (origin, direction) = if m.geometry_known {
                (Point3::from(m.origin_m), Vector3::from(m.direction))
            } else {
                let o = last_command.filter(|c| c.station == m.station).map_or(Point3::origin(), |c| c.origin);
                (o, direction_from_angles(m.azimuth_rad, m.elevation_rad))
            };
            report.deflector_messages += 1;
            let state = DeflectorState {
                station: m.station,
                beam: m.beam,
                origin,
                direction,
                azimuth_rad: m.azimuth_rad,
                elevation_rad: m.elevation_rad,
                settled: m.settled,
            };
            let t = ts(m.header.stamp.to_nanos(), t0_ns);
            // A command sent before discovery matched this subscription is missed (the
            // topic is volatile); the settled beam, whose geometry the deflector reports,
            // stands in for it.
            if m.settled && m.geometry_known && !viz.is_commanded(m.station, m.beam) {
                viz.beam_command(t, state)
            } else {
                viz.deflector_state(t, state);
                Ok(())
            }
        })?;
        positions.drain(|m| {
            let stamp = m.header.stamp.to_nanos();
            machine_lag.add(wall.elapsed().as_secs_f64(), (now_ns() - stamp) as f64 * 1e-6);
            report.machine_samples += 1;
            viz.machine_position(ts(stamp, t0_ns), Point3::new(m.x_m, m.y_m, m.z_m), Vector3::from(m.probe_offset_m));
            Ok(())
        })?;
        batches.drain(|m| {
            let n = m.x_m.len().min(m.y_m.len()).min(m.z_m.len());
            if n == 0 {
                return Ok(());
            }
            // The newest sample is the current point.
            let stamp = m.header.stamp.to_nanos() + ((n - 1) as f64 * m.sample_period_s * 1e9) as i64;
            machine_lag.add(wall.elapsed().as_secs_f64(), (now_ns() - stamp) as f64 * 1e-6);
            report.machine_samples += n as u64;
            let x = Point3::new(m.x_m[n - 1], m.y_m[n - 1], m.z_m[n - 1]);
            viz.machine_position(ts(stamp, t0_ns), x, Vector3::from(m.probe_offset_m));
            Ok(())
        })?;
        pairs.drain(|m| {
            let stamp = m.header.stamp.to_nanos();
            if !t0_known {
                t0_ns = stamp - (m.t_s * 1e9).round() as i64;
                t0_known = true;
            }
            pair_lag.add(wall.elapsed().as_secs_f64(), (now_ns() - stamp) as f64 * 1e-6);
            report.pairs += 1;
            match convert::pair_to_reading(&m, report.pairs as usize) {
                Ok(r) => viz.pair(&r),
                Err(e) => log::warn!("topic {}: {e:#}; not shown", topics::PAIRS),
            }
            Ok(())
        })?;
        status.drain(|m| {
            let state = match m.state {
                SequencerStatus::WAITING => "waiting",
                SequencerStatus::RUNNING => "running",
                SequencerStatus::DONE => "done",
                _ => "failed",
            };
            sequencer = format!(
                "**Sequencer**: {state}, {} of {} points{}",
                m.points_done,
                m.points_total,
                if m.message.is_empty() { String::new() } else { format!(" — {}", m.message) }
            );
            Ok(())
        })?;
        diagnoses.drain(|m| {
            report.diagnoses += 1;
            viz.diagnosis(ts(m.header.stamp.to_nanos(), t0_ns), &live_diagnosis(&m))
        })?;
        if Instant::now() >= next_flush {
            let lag = machine_lag.samples.last().map(|s| format!(" · viz lag {:.0} ms", s.1)).unwrap_or_default();
            viz.note(format!("{sequencer}{lag}"));
            viz.flush()?;
            report.flushes += 1;
            next_flush += flush_period;
            if next_flush < Instant::now() {
                next_flush = Instant::now() + flush_period;
            }
        }
    }
    viz.finish()?;
    report.wall_s = wall.elapsed().as_secs_f64();
    report.cpu_s = super::recorder::cpu_seconds() - cpu0;
    (report.machine_lag_first_ms, report.machine_lag_last_ms) = machine_lag.first_last(10.0);
    (report.pair_lag_first_ms, report.pair_lag_last_ms) = pair_lag.first_last(10.0);
    (report.machine_lag_max_ms, report.pair_lag_max_ms) = (machine_lag.max_ms, pair_lag.max_ms);
    log::info!(
        "viz: {} pairs, {} machine samples, {} flushes in {:.1} s, CPU {:.1} % of one core; lag of machine samples {:.1} ms (first 10 s) -> {:.1} ms (last 10 s), max {:.1} ms; of pairs {:.1} -> {:.1} ms, max {:.1} ms",
        report.pairs,
        report.machine_samples,
        report.flushes,
        report.wall_s,
        100.0 * report.cpu_s / report.wall_s.max(1e-9),
        report.machine_lag_first_ms,
        report.machine_lag_last_ms,
        report.machine_lag_max_ms,
        report.pair_lag_first_ms,
        report.pair_lag_last_ms,
        report.pair_lag_max_ms
    );
    if let Some(p) = report_path {
        std::fs::write(&p, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rerun_flags_become_parameters() {
        let a = |v: &[&str]| command_line(v.iter().map(|s| s.to_string()).collect()).unwrap();
        assert_eq!(a(&[]), ["--ros-args"]);
        assert_eq!(
            a(&["--rerun", "x.rrd", "--rerun-connect", "--ros-args", "-p", "machine:=m.yaml"]),
            [
                "--ros-args",
                "-p",
                "machine:=m.yaml",
                "-p",
                "rerun:=x.rrd",
                "-p",
                &format!("rerun_connect:={}", volcal_viz::DEFAULT_CONNECT_ADDR)
            ]
        );
        assert_eq!(a(&["--rerun-spawn"]), ["--ros-args", "-p", "rerun_spawn:=true"]);
        assert!(command_line(vec!["--bogus".into()]).is_err());
    }

    #[test]
    fn lag_windows() {
        let mut l = LagStats::default();
        for i in 0..300 {
            l.add(i as f64 * 0.1, if i < 100 { 2.0 } else { 4.0 });
        }
        let (first, last) = l.first_last(10.0);
        assert!((first - 2.0).abs() < 0.05 && last == 4.0, "{first} {last}");
        assert_eq!(l.max_ms, 4.0);
    }
}
