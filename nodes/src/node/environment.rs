//! The environment node: publishes the air and material temperatures on `/environment` at
//! `rate_hz` (default 1).
//!
//! Parameters: `backend` (sim, or line: `device`, `reply_timeout_s`, see
//! [`crate::backend::line`]), `rate_hz`, and for the sim backend `machine`, `seed`.

use super::runtime::{backend, secs};
use crate::backend::sim::{SimEnvironment, SimWorld};
use crate::backend::EnvironmentBackend;
use crate::ros::{now_ns, qos, shutdown, RosNode};
use anyhow::{anyhow, bail, Result};
use volcal_msgs::msg::Environment;
use volcal_msgs::std_msgs::msg::Header;
use volcal_msgs::topics;

pub fn run(node: &mut RosNode) -> Result<()> {
    if backend(node, &["sim", "line"])? == "line" {
        let link = crate::backend::line::open_from_args(&node.args)?;
        return run_with(node, crate::backend::line::LineEnvironment { link });
    }
    let world = SimWorld::from_args(&node.args)?;
    run_with(node, SimEnvironment::new(&world))
}

/// The node loop over any backend.
pub fn run_with<B: EnvironmentBackend>(node: &mut RosNode, mut backend: B) -> Result<()> {
    let rate: f64 = node.args.get_or("rate_hz", 1.0)?;
    if !(rate > 0.0 && rate.is_finite()) {
        bail!("parameter rate_hz: must be positive, got {rate}");
    }
    node.warn_unused_parameters();
    let out = node.publisher::<Environment>(topics::ENVIRONMENT, qos::data())?;
    let period = secs(1.0 / rate);
    let mut next = std::time::Instant::now();
    while !shutdown::requested() {
        let now = std::time::Instant::now();
        if now >= next {
            let t = now_ns();
            let s = backend.read(t)?;
            let air = s.air.unwrap_or(volcal::environment::Air::standard());
            out.publish(Environment {
                header: Header::at(t, "machine"),
                air_valid: s.air.is_some(),
                air_temp_c: air.temp_c,
                air_pressure_pa: air.pressure_pa,
                air_rh_pct: air.humidity_pct,
                air_co2_ppm: air.co2_ppm,
                machine_temp_valid: s.machine_temp_c.is_some(),
                machine_temp_c: s.machine_temp_c.unwrap_or(20.0),
                material_sensor: s.materials.iter().map(|m| m.0.clone()).collect(),
                material_temp_c: s.materials.iter().map(|m| m.1).collect(),
            })
            .map_err(|e| anyhow!("publish {}: {e:?}", topics::ENVIRONMENT))?;
            next += period;
        }
        std::thread::sleep(next.saturating_duration_since(std::time::Instant::now()).min(secs(0.05)));
    }
    Ok(())
}
