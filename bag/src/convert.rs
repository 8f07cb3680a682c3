//! Conversions between the ROS 2 messages (`volcal_msgs`) and the domain types of the core
//! (`volcal::campaign::Reading`), the pairing events and the model file. Serialisation lives in
//! the shell: the core never sees a message.

use crate::pairing::{EnvironmentEvent, Method, Pair, PositionEvent, ReadingEvent, TriggerEvent};
use anyhow::{anyhow, Result};
use nalgebra::{Point3, Vector3};
use volcal::campaign::{CampaignMeta, Compensation, ObsKind, Reading};
use volcal::environment::{Air, AirIndexEquation};
use volcal_formats::diagnosis_file::{DiagnosisFile, LocationEntry};
use volcal_formats::instrument::{InstrumentInfo, Truth};
use volcal_formats::model_file::ModelFile;
use volcal_msgs::msg::{
    Abscissa, AbscissaBatch, BeamState, DiagnosedEffect, Diagnosis, EffectParameter, Environment, ErrorFunction,
    ErrorModel, InterferometerInfo, LineResidual, MachinePosition, MachinePositionBatch, ReflectorTruth,
    ResidualLocation, SyncedPair, TracerRange, Trigger,
};
use volcal_msgs::std_msgs::msg::Header;

pub fn kind_to_msg(k: ObsKind) -> u8 {
    match k {
        ObsKind::Beam => Trigger::KIND_BEAM,
        ObsKind::Range => Trigger::KIND_RANGE,
    }
}

pub fn kind_from_msg(k: u8) -> Result<ObsKind> {
    match k {
        Trigger::KIND_BEAM => Ok(ObsKind::Beam),
        Trigger::KIND_RANGE => Ok(ObsKind::Range),
        _ => Err(anyhow!("field kind: {k} is neither KIND_BEAM (0) nor KIND_RANGE (1)")),
    }
}

pub fn trigger_event(t: &Trigger) -> Result<TriggerEvent> {
    Ok(TriggerEvent {
        id: t.trigger_id,
        trigger_type: t.trigger_type,
        kind: kind_from_msg(t.kind)?,
        station: t.station,
        line: t.line,
        point: t.point,
        stamp_ns: t.header.stamp.to_nanos(),
    })
}

pub fn abscissa_event(a: &Abscissa) -> ReadingEvent {
    ReadingEvent {
        kind: ObsKind::Beam,
        station: a.station,
        line: a.beam,
        value_m: a.abscissa_m,
        signal_strength: a.signal_strength,
        beam_broken: a.beam_broken,
        trigger_id: a.trigger_id,
        stamp_ns: a.header.stamp.to_nanos(),
    }
}

pub fn range_event(r: &TracerRange) -> ReadingEvent {
    ReadingEvent {
        kind: ObsKind::Range,
        station: r.station,
        line: r.path,
        value_m: r.range_m,
        signal_strength: r.signal_strength,
        beam_broken: r.beam_broken,
        trigger_id: r.trigger_id,
        stamp_ns: r.header.stamp.to_nanos(),
    }
}

/// The samples of a batch, each stamped `header.stamp + k * sample_period_s`.
pub fn abscissa_batch_events(b: &AbscissaBatch) -> Result<Vec<ReadingEvent>> {
    let n = b.abscissa_m.len();
    if b.signal_strength.len() != n || b.beam_broken.len() != n {
        return Err(anyhow!(
            "AbscissaBatch: {} abscissae but {} signal strengths and {} beam_broken flags",
            n,
            b.signal_strength.len(),
            b.beam_broken.len()
        ));
    }
    let t0 = b.header.stamp.to_nanos();
    Ok((0..n)
        .map(|k| ReadingEvent {
            kind: ObsKind::Beam,
            station: b.station,
            line: b.beam,
            value_m: b.abscissa_m[k],
            signal_strength: b.signal_strength[k] as f64,
            beam_broken: b.beam_broken[k],
            trigger_id: 0,
            stamp_ns: t0 + (k as f64 * b.sample_period_s * 1e9).round() as i64,
        })
        .collect())
}

pub fn position_event(m: &MachinePosition) -> PositionEvent {
    PositionEvent {
        x: [m.x_m, m.y_m, m.z_m],
        probe_offset: m.probe_offset_m,
        velocity: m.velocity_mps,
        position_id: m.position_id,
        in_position: m.in_position,
        trigger_id: m.trigger_id,
        stamp_ns: m.header.stamp.to_nanos(),
    }
}

pub fn position_batch_events(b: &MachinePositionBatch) -> Result<Vec<PositionEvent>> {
    let n = b.x_m.len();
    if b.y_m.len() != n || b.z_m.len() != n {
        return Err(anyhow!("MachinePositionBatch: {} x, {} y and {} z values", n, b.y_m.len(), b.z_m.len()));
    }
    let t0 = b.header.stamp.to_nanos();
    Ok((0..n)
        .map(|k| PositionEvent {
            x: [b.x_m[k], b.y_m[k], b.z_m[k]],
            probe_offset: b.probe_offset_m,
            velocity: [0.0; 3],
            position_id: b.position_id,
            in_position: b.in_position && k + 1 == n,
            trigger_id: 0,
            stamp_ns: t0 + (k as f64 * b.sample_period_s * 1e9).round() as i64,
        })
        .collect())
}

pub fn environment_event(e: &Environment) -> EnvironmentEvent {
    EnvironmentEvent {
        air: e.air_valid.then_some(Air {
            temp_c: e.air_temp_c,
            pressure_pa: e.air_pressure_pa,
            humidity_pct: e.air_rh_pct,
            co2_ppm: e.air_co2_ppm,
        }),
        machine_temp_c: e.machine_temp_valid.then_some(e.machine_temp_c),
        stamp_ns: e.header.stamp.to_nanos(),
    }
}

/// The `/campaign/pairs` message of a pair; `t0_ns` is the campaign's time origin.
pub fn pair_to_msg(p: &Pair, t0_ns: i64, clock_offset_s: f64) -> SyncedPair {
    let air = p.environment.and_then(|e| e.air);
    let temp = p.environment.and_then(|e| e.machine_temp_c);
    SyncedPair {
        header: Header::at(p.stamp_ns, "machine"),
        kind: kind_to_msg(p.kind),
        station: p.station,
        line: p.line,
        point: p.point,
        t_s: (p.stamp_ns - t0_ns) as f64 * 1e-9,
        l_m: p.l_m,
        position_m: p.x,
        probe_offset_m: p.probe_offset,
        velocity_mps: p.velocity,
        beam_broken: p.beam_broken,
        pairing: match p.method {
            Method::Trigger => SyncedPair::PAIRING_TRIGGER,
            Method::Interpolated => SyncedPair::PAIRING_INTERPOLATED,
        },
        clock_offset_s,
        pairing_gap_s: p.gap_s,
        trigger_id: p.trigger_id,
        air_valid: air.is_some(),
        air_temp_c: air.map_or(0.0, |a| a.temp_c),
        air_pressure_pa: air.map_or(0.0, |a| a.pressure_pa),
        air_rh_pct: air.map_or(0.0, |a| a.humidity_pct),
        air_co2_ppm: air.map_or(0.0, |a| a.co2_ppm),
        machine_temp_valid: temp.is_some(),
        machine_temp_c: temp.unwrap_or(0.0),
    }
}

/// A campaign reading from a recorded pair; `source` is the message's position in the bag.
pub fn pair_to_reading(m: &SyncedPair, source: usize) -> Result<Reading> {
    Ok(Reading {
        kind: kind_from_msg(m.kind)?,
        station: m.station,
        line: m.line,
        t_s: m.t_s,
        l_m: m.l_m,
        x: Point3::from(m.position_m),
        p: Vector3::from(m.probe_offset_m),
        air: m.air_valid.then_some(Air {
            temp_c: m.air_temp_c,
            pressure_pa: m.air_pressure_pa,
            humidity_pct: m.air_rh_pct,
            co2_ppm: m.air_co2_ppm,
        }),
        machine_temp_c: m.machine_temp_valid.then_some(m.machine_temp_c),
        velocity: (m.pairing == SyncedPair::PAIRING_INTERPOLATED).then(|| Vector3::from(m.velocity_mps)),
        beam_broken: m.beam_broken,
        source_line: source,
    })
}

pub fn info_to_msg(i: &InstrumentInfo, stamp_ns: i64) -> InterferometerInfo {
    InterferometerInfo {
        header: Header::at(stamp_ns, ""),
        instrument: i.instrument.clone(),
        wavelength_vac_m: i.wavelength_vac_m,
        compensated: i.compensated,
        assumed_index: i.assumed_index,
        air_equation: i.air_equation.clone(),
    }
}

/// Campaign metadata from the interferometer's info message.
pub fn meta_from_info(i: &InterferometerInfo) -> Result<CampaignMeta> {
    let air_equation = match i.air_equation.as_str() {
        "ciddor" | "" => AirIndexEquation::Ciddor,
        "edlen" => AirIndexEquation::Edlen,
        e => return Err(anyhow!("InterferometerInfo field air_equation: {e:?} (expected ciddor or edlen)")),
    };
    Ok(CampaignMeta {
        wavelength_vac_m: i.wavelength_vac_m,
        compensation: if i.compensated {
            Compensation::Compensated
        } else {
            Compensation::Uncompensated { assumed_index: i.assumed_index }
        },
        air_equation,
    })
}

/// The `/error_model` message of a model file (with the file itself as lossless JSON).
pub fn error_model_msg(f: &ModelFile, stamp_ns: i64) -> Result<ErrorModel> {
    let mut travel = [0.0; 6];
    for (a, r) in f.travel.iter().enumerate() {
        travel[2 * a] = r[0];
        travel[2 * a + 1] = r[1];
    }
    let r = f.residuals.as_ref();
    Ok(ErrorModel {
        header: Header::at(stamp_ns, "machine"),
        format: f.format.clone(),
        topology: f.topology.clone(),
        travel_m: travel,
        gauge: f.gauge.name().to_string(),
        functions: f
            .functions
            .iter()
            .map(|e| {
                Ok(ErrorFunction {
                    name: e.name.clone(),
                    representation: serde_json::to_string(&e.representation)?,
                    coefficients: e.coefficients.clone(),
                })
            })
            .collect::<Result<_>>()?,
        squareness_names: f.squareness.iter().map(|(n, _)| n.clone()).collect(),
        squareness_rad: f.squareness.iter().map(|(_, v)| *v).collect(),
        covariance_dim: f.covariance.n as u32,
        covariance_upper: f.covariance.upper.clone(),
        n_obs: r.map_or(0, |r| r.n_obs as u64),
        residual_rms_m: r.map_or(0.0, |r| r.rms_m),
        chi2: r.map_or(0.0, |r| r.chi2),
        dof: r.map_or(0, |r| r.dof as u64),
        variance_factor: r.map_or(0.0, |r| r.variance_factor),
        identifiability: f.identifiability.statements.clone(),
        warnings: f.warnings.clone(),
        input: f.provenance.input.clone(),
        input_sha256: f.provenance.input_sha256.clone(),
        machine: f.provenance.machine.clone(),
        machine_sha256: f.provenance.machine_sha256.clone(),
        software: f.provenance.software.clone(),
        model_json: serde_json::to_string(f)?,
    })
}

/// The `/diagnosis` message of a diagnosis file (with the file itself as lossless JSON).
/// `model` says which model was published on `/error_model` with it. The figures are the
/// file's, unchanged: the message and `volcal diagnose --json` agree to the bit. `partial`: a
/// live diagnosis of the pairs so far, while the campaign runs.
pub fn diagnosis_msg(f: &DiagnosisFile, model: &str, partial: bool, stamp_ns: i64) -> Result<Diagnosis> {
    let location = |l: &LocationEntry| ResidualLocation {
        kind: l.kind.clone(),
        label: l.label.clone(),
        excess_chi2: l.excess_chi2,
        share: l.share,
        fraction: l.fraction,
        p_value: l.p_value,
        detail: l.detail.clone(),
    };
    let verdict = if !f.effects.is_empty() {
        Diagnosis::EFFECTS_NAMED
    } else if f.unexplained.is_some() {
        Diagnosis::UNEXPLAINED
    } else {
        Diagnosis::CLEAN
    };
    Ok(Diagnosis {
        header: Header::at(stamp_ns, "machine"),
        format: f.format.clone(),
        verdict,
        model: model.to_string(),
        input: f.provenance.input.clone(),
        input_sha256: f.provenance.input_sha256.clone(),
        machine: f.provenance.machine.clone(),
        machine_sha256: f.provenance.machine_sha256.clone(),
        software: f.provenance.software.clone(),
        n_readings: f.n_readings as u64,
        rms_before_m: f.rms_before_m,
        rms_after_m: f.rms_after_m,
        noise_rms_m: f.noise_rms_m,
        chi2_per_dof_before: f.chi2_per_dof_before,
        chi2_per_dof_after: f.chi2_per_dof_after,
        effects: f
            .effects
            .iter()
            .map(|e| DiagnosedEffect {
                id: e.id.clone(),
                parameters: e
                    .parameters
                    .iter()
                    .map(|(name, v)| EffectParameter {
                        name: name.clone(),
                        value: *v,
                        uncertainty: e.uncertainty.get(name).copied().unwrap_or(0.0),
                        unit: volcal::diagnose::parameter_unit(name).to_string(),
                    })
                    .collect(),
                delta_rms_m: e.delta_rms_m,
                log10_bayes_factor: e.evidence,
                p_value: e.p_value,
                statement: e.statement.clone(),
                alternatives: e.alternatives.clone(),
            })
            .collect(),
        locations: f.locations.iter().map(location).collect(),
        remaining: f.remaining.iter().map(location).collect(),
        unexplained: f.unexplained.clone().unwrap_or_default(),
        map_change_rms_m: f.map_change_rms_m,
        map_change_max_m: f.map_change_max_m,
        statements: f.statements.clone(),
        diagnosis_json: serde_json::to_string(f)?,
        partial,
        lines: f
            .lines
            .iter()
            .map(|l| LineResidual {
                kind: l.kind.clone(),
                station: l.station,
                line: l.line,
                segment: l.segment,
                n_readings: l.n_readings as u32,
                rms_before_m: l.rms_before_m,
                rms_after_m: l.rms_after_m,
                flagged_by: l.flagged_by.clone(),
            })
            .collect(),
    })
}

/// The simulation truth of the actual beam (`/sim/truth/beam`).
pub fn beam_truth(b: &BeamState) -> Truth {
    Truth::Beam {
        stamp_ns: b.header.stamp.to_nanos(),
        station: b.station,
        beam: b.beam,
        origin: Point3::from(b.origin_m),
        direction: Vector3::from(b.direction),
    }
}

/// The simulation truth of the reflector (`/sim/truth/reflector`).
pub fn reflector_truth(r: &ReflectorTruth) -> Truth {
    Truth::Reflector {
        stamp_ns: r.header.stamp.to_nanos(),
        position_id: r.position_id,
        settled: r.settled,
        actual: Point3::from(r.actual_m),
        velocity: Vector3::from(r.velocity_mps),
    }
}
