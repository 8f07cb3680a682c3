//! Cost of the live view per reading, in process: a simulated on-the-fly campaign sampled at
//! about 1 kHz is fed to [`LiveViz`] as the `viz` node feeds it (a machine position and a pair
//! per reading, a beam command per beam, a flush every 50 ms of campaign time), logging to an
//! `.rrd` file; prints the processing time per reading and how much faster than real time it
//! runs.
//!
//! usage: cargo run --release -p volcal_viz --example live_viz_cost [-- BEAMS_PER_STATION]

use std::time::Instant;
use volcal_formats::machine::{Machine, DEMO_MACHINE};
use volcal_sim::plan::{task_direction, Acquisition};
use volcal_sim::{simulate, Plan};
use volcal_viz::live::{DeflectorState, LiveViz};
use volcal_viz::{blueprint, RerunArgs};

fn main() -> anyhow::Result<()> {
    let beams: usize = std::env::args().nth(1).map(|a| a.parse()).transpose()?.unwrap_or(4);
    let machine = Machine::parse(DEMO_MACHINE)?;
    let travel = machine.layout.travel;
    // 50 mm/s with 16 000 points over beams of about 0.8 m: about 1 kHz.
    let plan = Plan {
        directions_per_station: beams,
        points_per_beam: 16_000,
        acquisition: Acquisition::OnTheFly { speed_mps: 0.05 },
        station_setup_s: 0.0,
        ..Plan::default()
    };
    let tasks = plan.beam_tasks(&travel)?;
    let cfg = volcal_formats::plan::sim_config(&machine, plan, 1);
    let sim = simulate(&cfg, &[], 1).map_err(|e| anyhow::anyhow!("{e}"))?;
    let readings = &sim.campaign.readings;
    let duration = readings.last().map_or(0.0, |r| r.t_s) - readings[0].t_s;

    let out = std::env::temp_dir().join(format!("volcal-live-viz-cost-{}.rrd", std::process::id()));
    let args = RerunArgs { save: Some(out.clone()), ..RerunArgs::default() };
    let rec = args.open("live viz cost", &blueprint::live(Some(&travel)))?.expect("a sink");
    let mut viz = LiveViz::new(rec, Some(travel), "demo CMM")?;

    let start = Instant::now();
    let (mut next_flush, mut flushes, mut beam) = (readings[0].t_s, 0usize, None);
    for r in readings {
        if beam != Some((r.station, r.line)) {
            beam = Some((r.station, r.line));
            if let Some(t) = tasks.iter().find(|t| t.station == r.station && t.beam == r.line) {
                let state = DeflectorState {
                    station: t.station,
                    beam: t.beam,
                    origin: t.pivot,
                    direction: task_direction(t),
                    azimuth_rad: t.azimuth_rad,
                    elevation_rad: t.elevation_rad,
                    settled: true,
                };
                viz.beam_command(r.t_s, state)?;
            }
        }
        viz.machine_position(r.t_s, r.x, r.p);
        viz.pair(r);
        if r.t_s >= next_flush {
            viz.flush()?;
            flushes += 1;
            next_flush = r.t_s + 0.05;
        }
    }
    viz.finish()?;
    let elapsed = start.elapsed().as_secs_f64();
    let size = std::fs::metadata(&out)?.len();
    let _ = std::fs::remove_file(&out);
    let n = readings.len();
    println!(
        "{n} readings over {duration:.1} s of campaign ({:.0} Hz), {flushes} flushes: {elapsed:.2} s to log \
         ({:.1} µs per reading, {:.0}x faster than real time, {:.1}% of one core at this rate); recording {:.1} MB ({:.1} kB per campaign second)",
        n as f64 / duration,
        elapsed / n as f64 * 1e6,
        duration / elapsed,
        100.0 * elapsed / duration,
        size as f64 / 1e6,
        size as f64 / duration / 1e3,
    );
    Ok(())
}
