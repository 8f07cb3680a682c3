//! The recorder node: writes every topic of the node set to a bag and pairs readings with
//! machine coordinates ([`volcal_bag::pairing`]), writing the pairs to `/campaign/pairs` in the bag and
//! publishing them. A chunk is closed every `flush_period_s`, so a recorder killed with SIGKILL
//! loses at most that much; on SIGINT/SIGTERM it finishes the bag properly.
//!
//! Parameters: `bag` (directory to create; required), `flush_period_s` (0.5), `clock_offset_s`
//! (machine clock minus instrument clock, 0), `max_gap_s` (largest machine-sample interval for
//! interpolation, 0.05), `horizon_s` (how long incomplete pairs wait, 10), `publish_pairs`
//! (true), `record_truth` (false: the simulation truth topics are not recorded), `conceal`
//! (false; true refuses `record_truth`, so that nothing in the bag reveals what a simulation
//! injected: the bag holds what a real acquisition would), `drain_s`
//! (0.3) and `drain_max_s` (5): after a stop request the recorder keeps receiving until no
//! message has arrived for `drain_s`, for at most `drain_max_s`. The launch stops every node at
//! once, so the last on-the-fly segment's readings, machine samples and end trigger may still be
//! queued for the recorder when the stop arrives (on a loaded machine, for more than 0.3 s);
//! stopping on silence rather than after a fixed time keeps them in the bag and in the pairs.

use super::runtime::{secs, TICK};
use crate::ros::Inbox;
use crate::ros::{now_ns, qos, shutdown, RosNode};
use anyhow::{anyhow, Result};
use ros2_client::qos::QosProfile;
use ros2_client::Publisher;
use std::path::PathBuf;
use std::time::Instant;
use volcal_bag::convert;
use volcal_bag::pairing::{Pair, Pairer, PairingConfig, PairingStats};
use volcal_bag::{BagWriter, TopicHandle};
use volcal_msgs::msg::*;
use volcal_msgs::{topics, RosMessage};

type Feed<M> = fn(&M, &mut Pairer, &mut Vec<Pair>) -> Result<()>;

/// One recorded topic.
trait Source {
    /// Takes everything that arrived, writes it to the bag and feeds the pairing.
    fn drain(&mut self, bag: &mut BagWriter, pairer: &mut Pairer, out: &mut Vec<Pair>) -> Result<u64>;
}

struct TopicSource<M: RosMessage> {
    topic: String,
    qos: QosProfile,
    sub: Inbox<M>,
    handle: Option<TopicHandle>,
    stamp: fn(&M) -> i64,
    feed: Feed<M>,
}

impl<M: RosMessage> Source for TopicSource<M> {
    fn drain(&mut self, bag: &mut BagWriter, pairer: &mut Pairer, out: &mut Vec<Pair>) -> Result<u64> {
        let mut n = 0;
        let (topic, qos, handle, stamp, feed) = (&self.topic, &self.qos, &mut self.handle, self.stamp, self.feed);
        self.sub.drain(|m| {
            let h = match *handle {
                Some(h) => h,
                None => *handle.insert(bag.add_topic::<M>(topic, qos)?),
            };
            bag.write(h, &m, now_ns(), stamp(&m))?;
            if let Err(e) = feed(&m, pairer, out) {
                log::warn!("topic {topic}: {e:#}; not paired");
            }
            n += 1;
            Ok(())
        })?;
        Ok(n)
    }
}

fn source<M: RosMessage>(
    node: &mut RosNode,
    topic: &str,
    qos: QosProfile,
    stamp: fn(&M) -> i64,
    feed: Feed<M>,
) -> Result<Box<dyn Source>> {
    let sub = node.subscription::<M>(topic, qos.clone())?;
    Ok(Box::new(TopicSource { topic: node.resolve(topic), qos, sub, handle: None, stamp, feed }))
}

fn none<M>(_: &M, _: &mut Pairer, _: &mut Vec<Pair>) -> Result<()> {
    Ok(())
}

/// Seconds of CPU (user + system) this process has used.
pub fn cpu_seconds() -> f64 {
    // SAFETY: getrusage only writes the struct we pass.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(u.ru_utime) + tv(u.ru_stime)
}

pub fn run(node: &mut RosNode) -> Result<()> {
    let bag: PathBuf = node.args.require::<String>("bag")?.into();
    let flush = node.args.get_or("flush_period_s", 0.5)?;
    let clock_offset_s: f64 = node.args.get_or("clock_offset_s", 0.0)?;
    let cfg = PairingConfig {
        clock_offset_ns: (clock_offset_s * 1e9).round() as i64,
        max_gap_ns: (node.args.get_or("max_gap_s", 0.05)? * 1e9) as i64,
        horizon_ns: (node.args.get_or("horizon_s", 10.0)? * 1e9) as i64,
    };
    let publish_pairs: bool = node.args.get_or("publish_pairs", true)?;
    let record_truth: bool = node.args.get_or("record_truth", false)?;
    let conceal: bool = node.args.get_or("conceal", false)?;
    if record_truth && conceal {
        return Err(anyhow!(
            "parameters record_truth and conceal exclude each other: a concealed bag holds no simulation truth"
        ));
    }
    let drain = secs(node.args.get_or("drain_s", 0.3)?);
    let drain_max = secs(node.args.get_or("drain_max_s", 5.0)?);
    node.warn_unused_parameters();

    let mut writer = BagWriter::create(&bag, secs(flush))?;
    let d = qos::data;
    let c = qos::commands;
    let l = qos::latched;
    let mut sources: Vec<Box<dyn Source>> = vec![
        source::<Trigger>(
            node,
            topics::TRIGGER,
            c(),
            |m| m.header.stamp.to_nanos(),
            |m, p, o| {
                p.trigger(convert::trigger_event(m)?, o);
                Ok(())
            },
        )?,
        source::<Abscissa>(
            node,
            topics::ABSCISSA,
            d(),
            |m| m.header.stamp.to_nanos(),
            |m, p, o| {
                p.reading(convert::abscissa_event(m), o);
                Ok(())
            },
        )?,
        source::<AbscissaBatch>(
            node,
            topics::ABSCISSA_BATCH,
            d(),
            |m| m.header.stamp.to_nanos(),
            |m, p, o| {
                for e in convert::abscissa_batch_events(m)? {
                    p.reading(e, o);
                }
                Ok(())
            },
        )?,
        source::<TracerRange>(
            node,
            topics::TRACER_RANGE,
            d(),
            |m| m.header.stamp.to_nanos(),
            |m, p, o| {
                p.reading(convert::range_event(m), o);
                Ok(())
            },
        )?,
        source::<MachinePosition>(
            node,
            topics::MACHINE_POSITION,
            d(),
            |m| m.header.stamp.to_nanos(),
            |m, p, o| {
                p.position(convert::position_event(m), o);
                Ok(())
            },
        )?,
        source::<MachinePositionBatch>(
            node,
            topics::MACHINE_POSITION_BATCH,
            d(),
            |m| m.header.stamp.to_nanos(),
            |m, p, o| {
                for e in convert::position_batch_events(m)? {
                    p.position(e, o);
                }
                Ok(())
            },
        )?,
        source::<Environment>(
            node,
            topics::ENVIRONMENT,
            d(),
            |m| m.header.stamp.to_nanos(),
            |m, p, _| {
                p.environment(convert::environment_event(m));
                Ok(())
            },
        )?,
        source::<MachineCommand>(node, topics::MACHINE_COMMAND, c(), |m| m.header.stamp.to_nanos(), none)?,
        source::<BeamCommand>(node, topics::DEFLECTOR_COMMAND, c(), |m| m.header.stamp.to_nanos(), none)?,
        source::<BeamState>(node, topics::DEFLECTOR_STATE, l(), |m| m.header.stamp.to_nanos(), none)?,
        source::<SequencerStatus>(node, topics::SEQUENCER_STATUS, l(), |m| m.header.stamp.to_nanos(), none)?,
        source::<InterferometerInfo>(node, topics::INTERFEROMETER_INFO, l(), |m| m.header.stamp.to_nanos(), none)?,
    ];
    if record_truth {
        sources.push(source::<BeamState>(node, topics::TRUTH_BEAM, l(), |m| m.header.stamp.to_nanos(), none)?);
        sources.push(source::<ReflectorTruth>(
            node,
            topics::TRUTH_REFLECTOR,
            qos::truth(),
            |m| m.header.stamp.to_nanos(),
            none,
        )?);
    }
    let pairs_topic = node.resolve(topics::PAIRS);
    let pairs_handle = writer.add_topic::<SyncedPair>(&pairs_topic, &qos::data())?;
    let pairs_pub: Option<Publisher<SyncedPair>> =
        if publish_pairs { Some(node.publisher(topics::PAIRS, qos::data())?) } else { None };
    log::info!("recording to {}", bag.display());

    let t0 = now_ns();
    let wall = Instant::now();
    let cpu0 = cpu_seconds();
    let mut pairer = Pairer::new(cfg);
    let mut out: Vec<Pair> = Vec::new();
    let mut n_pairs = 0u64;
    let mut write_pairs = |out: &mut Vec<Pair>, writer: &mut BagWriter| -> Result<()> {
        for p in out.drain(..) {
            let m = convert::pair_to_msg(&p, t0, clock_offset_s);
            let now = now_ns();
            writer.write(pairs_handle, &m, now, p.stamp_ns)?;
            if let Some(pp) = &pairs_pub {
                pp.publish(m).map_err(|e| anyhow!("publish {pairs_topic}: {e:?}"))?;
            }
            n_pairs += 1;
        }
        Ok(())
    };
    // After a stop request: (when it came, when the last message arrived).
    let mut stopping: Option<(Instant, Instant)> = None;
    loop {
        if stopping.is_none() && shutdown::requested() {
            stopping = Some((Instant::now(), Instant::now()));
        }
        if let Some((asked, last)) = stopping {
            if last.elapsed() >= drain || asked.elapsed() >= drain_max {
                break;
            }
        }
        node.wait(TICK);
        let mut received = 0;
        for s in sources.iter_mut() {
            received += s.drain(&mut writer, &mut pairer, &mut out)?;
        }
        if let Some((_, last)) = stopping.as_mut() {
            if received > 0 {
                *last = Instant::now();
            }
        }
        write_pairs(&mut out, &mut writer)?;
        writer.flush_if_due()?;
    }
    let stats = pairer.finish(&mut out);
    write_pairs(&mut out, &mut writer)?;
    let cpu = cpu_seconds() - cpu0;
    let elapsed = wall.elapsed().as_secs_f64();
    let summary = writer.finish()?;
    let topics: Vec<String> = summary.per_topic.iter().map(|(t, n)| format!("{t} {n}")).collect();
    log::info!(
        "bag {}: {} messages ({}), {:.1} MB",
        summary.dir.display(),
        summary.messages,
        topics.join(", "),
        summary.bytes as f64 / 1e6
    );
    log::info!("{}", describe_pairing(n_pairs, &stats));
    if stats.late_breaks > 0 {
        log::warn!(
            "{} count loss(es) reported by unrecorded readings (centring probes, free-running samples) arrived after a later point of their line had been paired: the next point carries the loss, but the point before it may hang on the previous origin (its line's residuals in `volcal solve` show it)",
            stats.late_breaks
        );
    }
    log::info!(
        "recorder CPU {:.1} % of one core over {:.1} s ({:.2} s user+system)",
        100.0 * cpu / elapsed.max(1e-9),
        elapsed,
        cpu
    );
    Ok(())
}

/// One line on the pairing outcome.
pub fn describe_pairing(n_pairs: u64, s: &PairingStats) -> String {
    format!(
        "pairs: {n_pairs} ({} by trigger, {} interpolated); ignored: {} duplicated and {} conflicting messages; {} incomplete points; {} free-running readings outside segments, {} without machine samples around them; {} count loss(es) on unrecorded readings carried to the next point of their line",
        s.trigger_pairs,
        s.interpolated_pairs,
        s.duplicates,
        s.conflicts,
        s.incomplete_points,
        s.outside_segments,
        s.unbracketed,
        s.carried_breaks
    )
}
