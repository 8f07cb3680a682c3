//! `volcal bench recorder` and `volcal bench replay`: throughput of the recording chain.
//!
//! The recorder benchmark starts the real recorder node (a separate process, its own ROS
//! domain, loopback only) and publishes to it, from this process, an on-the-fly acquisition:
//! interferometer readings and machine coordinates at a fixed rate (individually, or batched),
//! split into one-second segments by `SEGMENT_START`/`SEGMENT_END` triggers. Every reading
//! falls inside a segment and between two machine samples, so every reading must come out as a
//! synchronised pair: the benchmark counts the pairs in the bag (loss = readings - pairs) and
//! reports the recorder's CPU share (from `/proc`, user + system time over wall time).
//!
//! With `viz`, the viz node (`volcal_viz`, saving its live view to an `.rrd` file) watches the
//! same acquisition, as a user watching a 1 kHz campaign live would: it subscribes to the machine
//! positions and to the recorder's pairs. The benchmark then also reports the viz node's CPU
//! share and its exit report (what it received, its lag in the first and the last 10 s), so
//! that the recorder's figures with and without the viz node can be compared and the viz node
//! seen to keep up.
//!
//! The replay benchmark reads a bag and decodes every message into its type, and reports
//! messages per second; then it turns the pairs into a campaign as `volcal solve` does.

use anyhow::{anyhow, bail, Context, Result};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use volcal_bag::Bag;
use volcal_msgs::cdr;
use volcal_msgs::msg::*;
use volcal_msgs::std_msgs::msg::Header;
use volcal_msgs::{topics, RosMessage};
use volcal_nodes::launch::node_dir;
use volcal_nodes::ros::node::DdsConfig;
use volcal_nodes::ros::{domain, now_ns, qos, NodeArgs, RosNode};

/// Options of the recorder benchmark.
#[derive(Clone, Debug)]
pub struct RecorderBench {
    /// Sampling rate of the interferometer and the machine, Hz.
    pub rate_hz: f64,
    pub duration_s: f64,
    /// Samples per message (1: `Abscissa`/`MachinePosition`; more: the batched types).
    pub batch: usize,
    /// Where the bag goes (a fresh temporary directory if `None`).
    pub bag: Option<PathBuf>,
    /// The recorder also publishes every pair on `/campaign/pairs`.
    pub publish_pairs: bool,
    /// Run the viz node too, watching the acquisition live (saving to an `.rrd` file).
    pub viz: bool,
}

/// What the viz node did during the recorder benchmark.
#[derive(Clone, Debug)]
pub struct VizBenchReport {
    /// CPU seconds of the viz node over the benchmark's wall time.
    pub cpu_s: f64,
    /// Its own exit report.
    pub report: volcal_nodes::node::viz::VizReport,
    pub rrd: PathBuf,
    pub rrd_bytes: u64,
}

/// What the recorder benchmark measured.
#[derive(Clone, Debug)]
pub struct RecorderReport {
    pub readings: u64,
    pub machine_samples: u64,
    pub messages_sent: u64,
    pub pairs: u64,
    pub wall_s: f64,
    pub recorder_cpu_s: f64,
    pub bag: PathBuf,
    pub bag_bytes: u64,
    /// The publisher fell behind its schedule by this much at worst, seconds.
    pub max_lag_s: f64,
    pub viz: Option<VizBenchReport>,
}

impl RecorderReport {
    pub fn loss(&self) -> i64 {
        self.readings as i64 - self.pairs as i64
    }

    pub fn describe(&self, b: &RecorderBench) -> String {
        let mut s = format!(
            "recorder benchmark: {:.0} Hz for {:.0} s, {}\n  sent {} readings and {} machine samples in {} messages (publisher at most {:.1} ms behind schedule)\n  recorded {} synchronised pairs: {} lost\n  recorder CPU {:.1} % of one core ({:.2} s over {:.1} s)\n  bag {} ({:.1} MB)",
            b.rate_hz,
            b.duration_s,
            if b.batch > 1 { format!("batches of {} samples", b.batch) } else { "one message per sample".into() },
            self.readings,
            self.machine_samples,
            self.messages_sent,
            self.max_lag_s * 1e3,
            self.pairs,
            self.loss(),
            100.0 * self.recorder_cpu_s / self.wall_s,
            self.recorder_cpu_s,
            self.wall_s,
            self.bag.display(),
            self.bag_bytes as f64 / 1e6
        );
        if let Some(v) = &self.viz {
            let r = &v.report;
            s += &format!(
                "\n  viz node: received {} pairs and {} machine samples, {} display flushes; CPU {:.1} % of one core ({:.2} s)\n  viz lag (processing time minus stamp), mean of the first / last 10 s, max: machine samples {:.1} / {:.1} ms, max {:.1} ms; pairs {:.1} / {:.1} ms, max {:.1} ms\n  viz recording {} ({:.1} MB)",
                r.pairs,
                r.machine_samples,
                r.flushes,
                100.0 * v.cpu_s / self.wall_s,
                v.cpu_s,
                r.machine_lag_first_ms,
                r.machine_lag_last_ms,
                r.machine_lag_max_ms,
                r.pair_lag_first_ms,
                r.pair_lag_last_ms,
                r.pair_lag_max_ms,
                v.rrd.display(),
                v.rrd_bytes as f64 / 1e6
            );
        }
        s
    }

    /// Whether every reading became a pair and, with the viz node, it received them all.
    pub fn complete(&self) -> bool {
        self.loss() == 0 && self.viz.as_ref().is_none_or(|v| v.report.pairs == self.pairs)
    }
}

/// CPU seconds (user + system) a process has used, from `/proc/<pid>/stat`.
pub fn process_cpu_seconds(pid: u32) -> Result<f64> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).with_context(|| format!("process {pid}"))?;
    // Fields after the command name (which is in parentheses and may contain spaces).
    let rest = &s[s.rfind(')').ok_or_else(|| anyhow!("/proc/{pid}/stat: unexpected format"))? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = f.get(11).and_then(|v| v.parse().ok()).ok_or_else(|| anyhow!("/proc/{pid}/stat: no utime"))?;
    let stime: f64 = f.get(12).and_then(|v| v.parse().ok()).ok_or_else(|| anyhow!("/proc/{pid}/stat: no stime"))?;
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    Ok((utime + stime) / hz)
}

fn send<M: RosMessage>(p: &ros2_client::Publisher<M>, m: M) -> Result<()> {
    p.publish(m).map_err(|e| anyhow!("publish {}: {e:?}", M::type_name()))
}

/// Runs the recorder benchmark.
pub fn recorder(b: &RecorderBench) -> Result<RecorderReport> {
    if !(b.rate_hz > 0.0 && b.duration_s > 0.0) || b.batch == 0 {
        bail!("rate, duration and batch must be positive");
    }
    let lease = domain::lease()?;
    let bag = match &b.bag {
        Some(p) => p.clone(),
        None => std::env::temp_dir().join(format!("volcal-bench-recorder-{}", std::process::id())),
    };
    if b.bag.is_none() {
        let _ = std::fs::remove_dir_all(&bag);
    }
    let exe = node_dir()?.join("volcal_recorder");
    let mut args = vec!["--ros-args".to_string(), "-p".into(), format!("bag:={}", bag.display())];
    args.extend(["-p".into(), format!("publish_pairs:={}", b.publish_pairs)]);
    let mut child = Command::new(&exe)
        .args(&args)
        .env("ROS_DOMAIN_ID", lease.id.to_string())
        .env("ROS_LOCALHOST_ONLY", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::inherit())
        .stderr(Stdio::inherit())
        .spawn()
        .with_context(|| format!("cannot start {}", exe.display()))?;
    let viz_files = (bag.with_extension("viz.rrd"), bag.with_extension("viz.json"));
    let mut viz = if b.viz {
        match start_viz(lease.id, &viz_files.0, &viz_files.1) {
            Ok(c) => Some(c),
            Err(e) => {
                let _ = stop(&mut child);
                return Err(e);
            }
        }
    } else {
        None
    };
    let result = (|| -> Result<RecorderReport> {
        let mut node = RosNode::with_config(
            NodeArgs::default(),
            "bench_instruments",
            DdsConfig { domain_id: lease.id, localhost_only: true },
        )?;
        let trig = node.publisher::<Trigger>(topics::TRIGGER, qos::commands())?;
        let (abs, pos, abs_b, pos_b) = if b.batch > 1 {
            (
                None,
                None,
                Some(node.publisher::<AbscissaBatch>(topics::ABSCISSA_BATCH, qos::data())?),
                Some(node.publisher::<MachinePositionBatch>(topics::MACHINE_POSITION_BATCH, qos::data())?),
            )
        } else {
            (
                Some(node.publisher::<Abscissa>(topics::ABSCISSA, qos::data())?),
                Some(node.publisher::<MachinePosition>(topics::MACHINE_POSITION, qos::data())?),
                None,
                None,
            )
        };
        // The recorder subscribes to every topic; wait until it is discovered, then a little
        // longer for the endpoints to match.
        let data_topic = if b.batch > 1 { topics::ABSCISSA_BATCH } else { topics::ABSCISSA };
        let t = Instant::now();
        while node.ros_node().subscription_count(data_topic) == 0
            || node.ros_node().subscription_count(topics::TRIGGER) == 0
        {
            if t.elapsed() > Duration::from_secs(30) {
                bail!("the recorder did not subscribe to {data_topic} within 30 s");
            }
            node.wait(Duration::from_millis(50));
        }
        // The viz node is the only subscriber of the pairs.
        while viz.is_some() && node.ros_node().subscription_count(topics::PAIRS) == 0 {
            if t.elapsed() > Duration::from_secs(30) {
                bail!("the viz node did not subscribe to {} within 30 s", topics::PAIRS);
            }
            node.wait(Duration::from_millis(50));
        }
        std::thread::sleep(Duration::from_millis(1000));

        let period_ns = (1e9 / b.rate_hz).round() as i64;
        let n = (b.duration_s * b.rate_hz).round() as i64;
        let per_segment = b.rate_hz.round() as i64; // one-second segments
        let speed = 0.1; // m/s along X
        let t0 = now_ns() + 200_000_000;
        let reading_at = |i: i64| t0 + i * period_ns;
        // Machine samples from one period before the first reading to one after the last,
        // offset by 30 % of a period from the readings (different clocks' phases).
        let machine_at = |j: i64| t0 + j * period_ns + period_ns * 3 / 10;
        let x_at = |ns: i64| 0.1 + speed * (ns - t0) as f64 * 1e-9;
        let mut next_trigger_id = 1u64;
        let mut sent = 0u64;
        let mut machine_samples = 0u64;
        let mut max_lag = 0i64;
        let started = Instant::now();
        let cpu0 = process_cpu_seconds(child.id())?;
        let viz_cpu0 = viz.as_ref().map(|v| process_cpu_seconds(v.id())).transpose()?;
        let mut j = -1i64;
        let mut i = 0i64;
        while i < n {
            // Send everything due, a batch at a time.
            let k = b.batch as i64;
            let due = reading_at(i + k - 1).max(machine_at(j + k - 1));
            let now = now_ns();
            if now < due {
                std::thread::sleep(Duration::from_nanos(((due - now) as u64).min(2_000_000)));
                continue;
            }
            max_lag = max_lag.max(now - due);
            // Segment boundaries within this batch.
            for r in i..(i + k).min(n) {
                if r % per_segment == 0 {
                    let seg = r / per_segment;
                    let start = reading_at(r) - period_ns / 2;
                    send(&trig, segment(next_trigger_id, Trigger::SEGMENT_START, seg, start))?;
                    next_trigger_id += 1;
                    sent += 1;
                }
            }
            // Machine samples first (the recorder pairs a reading once a later sample exists).
            let jm: Vec<i64> = (j..j + k).collect();
            if let Some(p) = &pos_b {
                let s = machine_at(jm[0]);
                send(
                    p,
                    MachinePositionBatch {
                        header: Header::at(s, "machine"),
                        sample_period_s: period_ns as f64 * 1e-9,
                        x_m: jm.iter().map(|&q| x_at(machine_at(q))).collect(),
                        y_m: vec![0.4; jm.len()],
                        z_m: vec![-0.3; jm.len()],
                        probe_offset_m: [0.0, 0.0, -0.1],
                        position_id: 1,
                        in_position: false,
                    },
                )?;
                sent += 1;
            } else if let Some(p) = &pos {
                for &q in &jm {
                    let s = machine_at(q);
                    send(
                        p,
                        MachinePosition {
                            header: Header::at(s, "machine"),
                            x_m: x_at(s),
                            y_m: 0.4,
                            z_m: -0.3,
                            probe_offset_m: [0.0, 0.0, -0.1],
                            velocity_mps: [speed, 0.0, 0.0],
                            position_id: 1,
                            ..Default::default()
                        },
                    )?;
                    sent += 1;
                }
            }
            machine_samples += jm.len() as u64;
            j += k;
            let ir: Vec<i64> = (i..(i + k).min(n)).collect();
            if let Some(p) = &abs_b {
                send(
                    p,
                    AbscissaBatch {
                        header: Header::at(reading_at(ir[0]), "deflector/0"),
                        station: 0,
                        beam: 0,
                        sample_period_s: period_ns as f64 * 1e-9,
                        abscissa_m: ir.iter().map(|&r| x_at(reading_at(r))).collect(),
                        signal_strength: vec![1.0; ir.len()],
                        beam_broken: vec![false; ir.len()],
                    },
                )?;
                sent += 1;
            } else if let Some(p) = &abs {
                for &r in &ir {
                    send(
                        p,
                        Abscissa {
                            header: Header::at(reading_at(r), "deflector/0"),
                            station: 0,
                            beam: 0,
                            abscissa_m: x_at(reading_at(r)),
                            signal_strength: 1.0,
                            beam_broken: false,
                            trigger_id: 0,
                        },
                    )?;
                    sent += 1;
                }
            }
            for &r in &ir {
                if r % per_segment == per_segment - 1 || r == n - 1 {
                    let end = reading_at(r) + period_ns / 2;
                    send(&trig, segment(next_trigger_id, Trigger::SEGMENT_END, r / per_segment, end))?;
                    next_trigger_id += 1;
                    sent += 1;
                }
            }
            i += k;
        }
        // One machine sample beyond the last reading, so that it is bracketed.
        if let Some(p) = &pos {
            let s = machine_at(j);
            send(p, MachinePosition { header: Header::at(s, "machine"), x_m: x_at(s), ..Default::default() })?;
        } else if let Some(p) = &pos_b {
            let s = machine_at(j);
            send(
                p,
                MachinePositionBatch {
                    header: Header::at(s, "machine"),
                    sample_period_s: period_ns as f64 * 1e-9,
                    x_m: vec![x_at(s)],
                    y_m: vec![0.4],
                    z_m: vec![-0.3],
                    ..Default::default()
                },
            )?;
        }
        machine_samples += 1;
        // Let the recorder drain, then stop it.
        std::thread::sleep(Duration::from_secs(1));
        let wall = started.elapsed().as_secs_f64();
        let cpu = process_cpu_seconds(child.id())? - cpu0;
        let viz_cpu = match (&viz, viz_cpu0) {
            (Some(v), Some(c0)) => Some(process_cpu_seconds(v.id())? - c0),
            _ => None,
        };
        Ok(RecorderReport {
            readings: n as u64,
            machine_samples,
            messages_sent: sent,
            pairs: 0,
            wall_s: wall,
            recorder_cpu_s: cpu,
            bag: bag.clone(),
            bag_bytes: 0,
            max_lag_s: max_lag as f64 * 1e-9,
            viz: viz_cpu.map(|cpu_s| VizBenchReport {
                cpu_s,
                report: Default::default(),
                rrd: viz_files.0.clone(),
                rrd_bytes: 0,
            }),
        })
    })();
    // The recorder first (it publishes its last pairs as it stops), then the viz node.
    let status = stop(&mut child)?;
    let viz_status = viz.as_mut().map(|v| {
        std::thread::sleep(Duration::from_millis(500));
        stop(v)
    });
    let mut report = result?;
    if !status.success() {
        bail!("the recorder failed ({status})");
    }
    if let Some(st) = viz_status.transpose()? {
        if !st.success() {
            bail!("the viz node failed ({st})");
        }
        let v = report.viz.as_mut().expect("viz report");
        let text = std::fs::read_to_string(&viz_files.1)
            .with_context(|| format!("the viz node wrote no report {}", viz_files.1.display()))?;
        v.report = serde_json::from_str(&text).with_context(|| format!("{}", viz_files.1.display()))?;
        v.rrd_bytes = std::fs::metadata(&v.rrd).map(|m| m.len()).unwrap_or(0);
    }
    let pairs = Bag::open(&bag)?.count()?.per_topic.get(topics::PAIRS).map_or(0, |c| c.count);
    report.pairs = pairs;
    report.bag_bytes = std::fs::read_dir(&bag)?.filter_map(|e| e.ok()?.metadata().ok()).map(|m| m.len()).sum();
    Ok(report)
}

/// Starts the viz node on `domain`, saving to `rrd` and reporting to `report`.
fn start_viz(domain: u16, rrd: &Path, report: &Path) -> Result<std::process::Child> {
    let exe = node_dir()?.join("volcal_viz");
    let _ = std::fs::remove_file(rrd);
    Command::new(&exe)
        .args([
            "--ros-args",
            "-p",
            &format!("rerun:={}", rrd.display()),
            "-p",
            &format!("report:={}", report.display()),
        ])
        .env("ROS_DOMAIN_ID", domain.to_string())
        .env("ROS_LOCALHOST_ONLY", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::inherit())
        .stderr(Stdio::inherit())
        .spawn()
        .with_context(|| format!("cannot start {}", exe.display()))
}

/// SIGINT to a node this benchmark started, and waits for it.
fn stop(child: &mut std::process::Child) -> Result<std::process::ExitStatus> {
    // SAFETY: signalling the child we started.
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGINT);
    }
    Ok(child.wait()?)
}

fn segment(id: u64, ty: u8, line: i64, stamp: i64) -> Trigger {
    Trigger {
        header: Header::at(stamp, "machine"),
        trigger_id: id,
        trigger_type: ty,
        kind: Trigger::KIND_BEAM,
        station: 0,
        line: 0,
        point: line as u32,
        position_id: 1,
    }
}

/// What the replay benchmark measured.
#[derive(Clone, Debug)]
pub struct ReplayReport {
    pub messages: u64,
    pub read_s: f64,
    pub pairs: usize,
    pub campaign_s: f64,
}

impl ReplayReport {
    pub fn describe(&self, bag: &Path) -> String {
        format!(
            "replay benchmark on {}:\n  read and decoded {} messages in {:.3} s: {:.0} messages per second\n  campaign of {} pairs (as `volcal solve` reads it) in {:.3} s: {:.0} pairs per second",
            bag.display(),
            self.messages,
            self.read_s,
            self.messages as f64 / self.read_s,
            self.pairs,
            self.campaign_s,
            self.pairs as f64 / self.campaign_s
        )
    }
}

type Decoder = fn(&[u8]) -> Result<()>;

fn decoder<M: RosMessage>(data: &[u8]) -> Result<()> {
    cdr::decode::<M>(data).map(|_| ())
}

/// The decoder of each volcal message type, by `package/msg/Type`.
fn decoders() -> std::collections::HashMap<&'static str, Decoder> {
    let mut m: std::collections::HashMap<&'static str, Decoder> = std::collections::HashMap::new();
    macro_rules! add {
        ($($t:ty),*) => { $(m.insert(<$t>::TYPE_NAME, decoder::<$t>);)* };
    }
    add!(
        SyncedPair,
        Abscissa,
        MachinePosition,
        AbscissaBatch,
        MachinePositionBatch,
        Trigger,
        TracerRange,
        Environment,
        MachineCommand,
        BeamCommand,
        BeamState,
        SequencerStatus,
        InterferometerInfo,
        ReflectorTruth,
        ErrorModel
    );
    m
}

/// Runs the replay benchmark on a bag.
pub fn replay(bag: &Path) -> Result<ReplayReport> {
    let start = Instant::now();
    let b = Bag::open(bag)?;
    let mut unknown = 0u64;
    let table = decoders();
    // The decoder of the previous message's type: consecutive messages often share it.
    let mut last: Option<(*const u8, Decoder)> = None;
    let s = b.read(|m| {
        let d = match last {
            Some((p, d)) if p == m.type_name.as_ptr() => Some(d),
            _ => {
                let d = table.get(m.type_name).copied();
                last = d.map(|d| (m.type_name.as_ptr(), d));
                d
            }
        };
        match d {
            Some(d) => d(m.data)?,
            None => unknown += 1,
        }
        Ok(())
    })?;
    let read_s = start.elapsed().as_secs_f64();
    if unknown > 0 {
        log::warn!("{unknown} messages of types volcal does not know were read but not decoded");
    }
    let start = Instant::now();
    let c = volcal_bag::campaign::read_bag(bag)?;
    let campaign_s = start.elapsed().as_secs_f64();
    Ok(ReplayReport { messages: s.messages, read_s, pairs: c.campaign.readings.len(), campaign_s })
}
