//! The solver node during a recording (`live: true`): it diagnoses the campaign while it runs,
//! so that a lost count or a drifting set-up is flagged while the beam can still be measured
//! again, not when the bag is replayed days later.
//!
//! It listens to what the recorder publishes, never to the bag: the synchronised pairs
//! (`/campaign/pairs`), the air compensation (`/interferometer/info`) and the progress
//! (`/sequencer/status`). It runs the diagnosis of `volcal diagnose`
//! ([`volcal_formats::diagnosing::diagnose_campaign`], the same code) on the pairs received so
//! far:
//! - after each completed device position (when the first pair of the next one arrives), over
//!   the completed positions;
//! - every `refit_every_pairs` pairs when that is positive (on-the-fly plans, where one
//!   position lasts long), over everything received;
//! - once more at the end of the campaign (the sequencer done, or a stop request), over
//!   everything, with `partial` cleared; that one's refit model is written to `out` (if given)
//!   and published on `/error_model`.
//!
//! A part of a campaign does not determine a representation sized for the whole: fitted with
//! the machine file's, the first positions absorb a lost count and the diagnosis names what the
//! surplus freedom fits. A partial diagnosis is therefore made with the representation the
//! pairs so far support (the machine file's or a coarser one, least BIC:
//! [`volcal::flexibility`]), and says which; the final one uses the machine file's, as
//! `volcal diagnose` on the bag does.
//!
//! Each diagnosis goes out on `/diagnosis` (transient-local): `partial` while the campaign
//! runs, with the residual RMS of every line before and after and the lines a named effect
//! flags. A diagnosis runs on a worker thread, so the node keeps receiving; a trigger that comes
//! while one runs is served when it ends (the newest pairs then), never dropped. A diagnosis that
//! cannot run yet (one position may not determine the model) is logged and skipped.
//!
//! Parameters (besides the solver's `machine`, `out`, `linger_s`): `refit_every_pairs` (0),
//! `drain_s` (0.5: silence on `/campaign/pairs` after the end before the final diagnosis, as
//! the recorder drains its last readings).

use super::runtime::{secs, TICK};
use crate::ros::{now_ns, qos, shutdown, RosNode};
use anyhow::{anyhow, Result};
use ros2_client::Publisher;
use sha2::{Digest, Sha256};
use std::path::PathBuf;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Instant;
use volcal::campaign::{Campaign, CampaignMeta, Reading};
use volcal::flexibility::choose;
use volcal_bag::convert::{diagnosis_msg, error_model_msg, meta_from_info, pair_to_reading};
use volcal_formats::diagnosing::{diagnose_campaign, Diagnosed};
use volcal_formats::machine::Machine;
use volcal_formats::model_file::Provenance;
use volcal_formats::solving::prepare_campaign;
use volcal_msgs::msg::{Diagnosis, ErrorModel, InterferometerInfo, SequencerStatus, SyncedPair};
use volcal_msgs::topics;

/// The machine file as the node loaded it.
pub struct MachineSource {
    pub machine: Machine,
    pub name: String,
    pub sha256: String,
}

/// What one diagnosis covers.
#[derive(Clone, Debug, PartialEq)]
enum Scope {
    /// The positions completed before `next` started.
    Completed { next: u32 },
    /// Everything received, the campaign still running.
    SoFar,
    /// Everything, the campaign over.
    Final,
}

/// A pair as received: the reading and its order key (stamp, trigger), as `volcal diagnose`
/// sorts a bag's pairs.
struct Received {
    key: (i64, u64),
    reading: Reading,
}

/// A diagnosis on its worker thread.
struct Running {
    scope: Scope,
    pairs: usize,
    started: Instant,
    handle: JoinHandle<Result<(Diagnosed, Provenance)>>,
}

/// SHA-256 over the numbers of the diagnosed readings: the provenance of a live diagnosis,
/// which has no input file (a bag replayed later, with the same pairs, diagnoses the same).
fn readings_sha256(readings: &[Reading]) -> String {
    let mut h = Sha256::new();
    for r in readings {
        h.update([r.kind as u8]);
        h.update(r.station.to_le_bytes());
        h.update(r.line.to_le_bytes());
        for v in [r.t_s, r.l_m, r.x.x, r.x.y, r.x.z, r.p.x, r.p.y, r.p.z] {
            h.update(v.to_le_bytes());
        }
    }
    format!("{:x}", h.finalize())
}

/// The campaign a scope covers, in acquisition order.
fn snapshot(received: &mut [Received], meta: &CampaignMeta, scope: &Scope) -> Campaign {
    received.sort_by_key(|r| r.key);
    let readings = received
        .iter()
        .filter(|r| match scope {
            Scope::Completed { next } => r.reading.station != *next,
            _ => true,
        })
        .map(|r| r.reading.clone())
        .collect();
    Campaign { meta: meta.clone(), readings }
}

/// In words, for the log and the provenance.
fn describe(scope: &Scope, campaign: &Campaign) -> String {
    let mut stations: Vec<u32> = campaign.readings.iter().map(|r| r.station).collect();
    stations.sort_unstable();
    stations.dedup();
    let list = stations.iter().map(u32::to_string).collect::<Vec<_>>().join(", ");
    let what = match scope {
        Scope::Completed { .. } => "completed position(s)",
        Scope::SoFar => "the campaign so far, position(s)",
        Scope::Final => "the whole campaign, position(s)",
    };
    format!("live {} ({} pairs of {what} {list})", topics::PAIRS, campaign.readings.len())
}

pub fn run(node: &mut RosNode, machine: MachineSource, out: Option<PathBuf>, linger: f64) -> Result<()> {
    let every: usize = node.args.get_or("refit_every_pairs", 0usize)?;
    let drain = secs(node.args.get_or("drain_s", 0.5)?);
    node.warn_unused_parameters();
    let machine = Arc::new(machine);

    let mut pairs = node.subscription::<SyncedPair>(topics::PAIRS, qos::data())?;
    let mut info = node.subscription::<InterferometerInfo>(topics::INTERFEROMETER_INFO, qos::latched())?;
    let mut status = node.subscription::<SequencerStatus>(topics::SEQUENCER_STATUS, qos::latched())?;
    let diagnosis_pub = node.publisher::<Diagnosis>(topics::DIAGNOSIS, qos::latched())?;
    let mut model_pub: Option<Publisher<ErrorModel>> = None;
    log::info!(
        "diagnosing {} live: after each completed position{}",
        node.resolve(topics::PAIRS),
        if every > 0 { format!(" and every {every} pairs") } else { String::new() }
    );

    let mut received: Vec<Received> = Vec::new();
    let mut meta = CampaignMeta::default();
    let mut meta_known = false;
    let mut station: Option<u32> = None;
    let mut since_refit = 0usize;
    let mut last_pair = Instant::now();
    let mut done_at: Option<Instant> = None;
    let mut stop_at: Option<Instant> = None;
    let mut running: Option<Running> = None;
    let mut queued: Option<Scope> = None;
    let mut finished = false;

    loop {
        node.wait(TICK);
        if stop_at.is_none() && shutdown::requested() {
            if finished {
                break;
            }
            stop_at = Some(Instant::now());
        }
        info.drain(|m| {
            meta = meta_from_info(&m)?;
            meta_known = true;
            Ok(())
        })?;
        status.drain(|m| {
            if m.state == SequencerStatus::DONE && done_at.is_none() {
                log::info!("the sequencer is done ({} points): final diagnosis once the pairs stop", m.points_done);
                done_at = Some(Instant::now());
            }
            Ok(())
        })?;
        pairs.drain(|m| {
            last_pair = Instant::now();
            let reading = match pair_to_reading(&m, received.len() + 1) {
                Ok(r) => r,
                Err(e) => {
                    log::warn!("{}: pair stamped {} ns: {e:#}; left out", topics::PAIRS, m.header.stamp.to_nanos());
                    return Ok(());
                }
            };
            if let Some(s) = station.filter(|&s| s != reading.station) {
                log::info!("position {s} complete");
                queued = Some(Scope::Completed { next: reading.station });
                since_refit = 0;
            }
            station = Some(reading.station);
            received.push(Received { key: (m.header.stamp.to_nanos(), m.trigger_id), reading });
            since_refit += 1;
            if every > 0 && since_refit >= every {
                queued = Some(Scope::SoFar);
                since_refit = 0;
            }
            Ok(())
        })?;
        let ended = done_at.or(stop_at).is_some_and(|_| last_pair.elapsed() >= drain);
        if ended
            && !finished
            && queued != Some(Scope::Final)
            && running.as_ref().is_none_or(|r| r.scope != Scope::Final)
        {
            queued = Some(Scope::Final);
        }

        // A finished diagnosis goes out.
        if running.as_ref().is_some_and(|r| r.handle.is_finished()) {
            let Running { scope, pairs: n, started, handle } = running.take().unwrap();
            let result = handle.join().map_err(|_| anyhow!("the diagnosis thread panicked"))?;
            match result {
                Ok((d, provenance)) => {
                    let last = scope == Scope::Final;
                    publish(&diagnosis_pub, &d, last, n, started.elapsed().as_secs_f64(), node)?;
                    if last {
                        let model = d.refit_model(provenance);
                        if let Some(p) = &out {
                            model.write(p)?;
                            log::info!("wrote the refit model to {}", p.display());
                        }
                        let publisher = node.publisher::<ErrorModel>(topics::ERROR_MODEL, qos::latched())?;
                        publisher
                            .publish(error_model_msg(&model, now_ns())?)
                            .map_err(|e| anyhow!("publish {}: {e:?}", topics::ERROR_MODEL))?;
                        log::info!("published the model on {} (transient-local)", node.resolve(topics::ERROR_MODEL));
                        model_pub = Some(publisher);
                        finished = true;
                    }
                }
                Err(e) => {
                    log::warn!("live diagnosis of {n} pairs not possible yet: {e:#}");
                    finished |= scope == Scope::Final;
                }
            }
        }

        // The next one starts when the worker is free.
        if running.is_none() {
            if let Some(scope) = queued.take() {
                if !meta_known && !received.is_empty() {
                    log::warn!(
                        "no {} received: diagnosing with the default air compensation",
                        topics::INTERFEROMETER_INFO
                    );
                    meta_known = true;
                }
                let campaign = snapshot(&mut received, &meta, &scope);
                if campaign.readings.is_empty() {
                    finished |= scope == Scope::Final;
                } else {
                    let source = describe(&scope, &campaign);
                    let provenance = Provenance {
                        input: source.clone(),
                        input_sha256: readings_sha256(&campaign.readings),
                        machine: machine.name.clone(),
                        machine_sha256: machine.sha256.clone(),
                        software: volcal_formats::software_version(),
                    };
                    let m = machine.clone();
                    let pairs = campaign.readings.len();
                    log::info!("diagnosing {source}");
                    let partial = scope != Scope::Final;
                    let handle = std::thread::spawn(move || {
                        diagnose_live(&campaign, &m.machine, &source, partial, provenance.clone())
                            .map(|d| (d, provenance))
                    });
                    running = Some(Running { scope, pairs, started: Instant::now(), handle });
                }
            }
        }

        if finished && running.is_none() {
            if stop_at.is_some() {
                // Give the subscribers the final diagnosis before the writers go.
                let t = Instant::now();
                while t.elapsed() < secs(1.0) {
                    node.wait(TICK);
                }
                break;
            }
            if linger >= 0.0 && done_at.is_some_and(|d| d.elapsed() >= secs(linger)) {
                break;
            }
        }
    }
    drop(model_pub);
    Ok(())
}

/// The diagnosis of `campaign`. A partial one is made with the representation that the pairs
/// so far support ([`volcal::flexibility::choose`]: the machine file's or a coarser one, by BIC),
/// which its statements say; the final one with the machine file's, as `volcal diagnose` on the
/// bag. With `representation: auto` both are the machine file's: auto already fits the knots to
/// the positions the pairs so far occupy.
fn diagnose_live(
    campaign: &Campaign,
    machine: &Machine,
    source: &str,
    partial: bool,
    provenance: Provenance,
) -> Result<Diagnosed> {
    if !partial || machine.auto.is_some() {
        return diagnose_campaign(campaign, machine, source, provenance);
    }
    let obs = prepare_campaign(campaign, machine, source)?.obs;
    let choice = choose(&machine.layout, &obs, &machine.solve_options()).map_err(|e| anyhow!("{source}: {e}"))?;
    let why = choice.describe();
    let mut m = machine.clone();
    m.layout = choice.layout;
    let mut d = diagnose_campaign(campaign, &m, source, provenance)?;
    d.file.statements.insert(0, format!("Partial campaign: {why}."));
    Ok(d)
}

/// Publishes one diagnosis on `/diagnosis` and says in the log what it found.
fn publish(
    publisher: &Publisher<Diagnosis>,
    d: &Diagnosed,
    last: bool,
    pairs: usize,
    seconds: f64,
    node: &RosNode,
) -> Result<()> {
    let which = if last {
        "the refit of the whole campaign, also on /error_model".to_string()
    } else {
        "none yet: a partial diagnosis while the campaign runs (/error_model comes with the final one)".to_string()
    };
    let msg = diagnosis_msg(&d.file, &which, !last, now_ns())?;
    let flagged: Vec<String> = d
        .file
        .lines
        .iter()
        .filter(|l| !l.flagged_by.is_empty())
        .map(|l| format!("station {} beam {} ({})", l.station, l.line, l.flagged_by.join(", ")))
        .collect();
    let named: Vec<&str> = d.file.effects.iter().map(|e| e.id.as_str()).collect();
    publisher.publish(msg).map_err(|e| anyhow!("publish {}: {e:?}", topics::DIAGNOSIS))?;
    log::info!(
        "published the {} diagnosis of {} pairs on {} ({:.1} s): {}{}",
        if last { "final" } else { "partial" },
        pairs,
        node.resolve(topics::DIAGNOSIS),
        seconds,
        if named.is_empty() { "nothing named".to_string() } else { format!("named {}", named.join(", ")) },
        if flagged.is_empty() { String::new() } else { format!("; flagged {}", flagged.join("; ")) }
    );
    Ok(())
}
