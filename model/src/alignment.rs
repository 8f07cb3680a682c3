//! What the fixed beams' alignment leaves open, when the campaign does not say it.
//!
//! A fixed beam reads the reflector's displacement along the beam, `n . (P_i - P_mean)`. The
//! patent takes `n` as the least-squares line of the reflector's actual points (the machine
//! moves the reflector along the beam: [`BeamAlignment::Motion`]); a campaign whose machine ran
//! its commanded straight lines along beams pointed at them has `n` along the commanded line
//! instead ([`BeamAlignment::Commanded`]). The two differ by the angle `a` between the
//! commanded line and the actual motion, the errors' mean slope across the beam: the readings
//! differ by the cosine error `-a^2 s / 2` and by `a` times the drift across the beam, both of
//! second order in the machine's errors. A beam scale of that kind is what the model's own
//! positioning errors absorb, so the readings do not tell the alignments apart (at thirty times
//! a CMM's usual errors the fits' chi-square differ by half a percent, the maps by micrometres:
//! docs/representation-auto.md, "The beams' alignment").
//!
//! [`cover`] therefore keeps the estimate of the stated or default alignment and, where the
//! other one would move the model by more than a tenth of its uncertainty somewhere, refits
//! with the other and adds the difference to the covariance: a rectangular distribution from
//! the estimate to the other alignment's model, variance `d d^T / 3`. At a CMM's usual errors
//! the two alignments' readings differ by nanometres and nothing changes.

use crate::beam::{centred_segments, fit_line, BeamAlignment};
use crate::campaign::{ObsKind, Observations};
use crate::estimator::{solve, Solution, SolveError, SolveOptions};
use crate::kinematics::exact_position;
use crate::model::ErrorModel;
use crate::smoothing::Smoothing;
use nalgebra::{Point3, Vector3};

/// The separation below which [`cover`] leaves a solution as it is: no derived quantity can
/// move by more than this many of its standard uncertainties.
pub const NEGLIGIBLE_SEPARATION: f64 = 0.1;

/// How far apart the readings' predictions of the two alignments lie for `model`, as a
/// whole: `sqrt(sum_i (dl_i / sigma_i)^2)` over the beam readings, `dl_i` the change of reading
/// `i` (its line's origin eliminated) when the beams' directions are taken from the commanded
/// points instead of the actual ones (or the reverse), `sigma_i` its noise (`sigmas`, one per
/// reading of `obs`, e.g. [`Solution::sigmas`]).
///
/// It bounds what the other alignment does to any quantity derived from the model: to first
/// order the change of the estimate is the fit's response to readings changed by `dl`, and by
/// Cauchy-Schwarz that moves a quantity by at most this separation times its standard
/// uncertainty. Zero without beams.
pub fn separation(model: &ErrorModel, sigmas: &[f64], obs: &Observations) -> f64 {
    let owners = obs.line_owners();
    let mut sum = 0.0;
    for (gi, _) in obs.groups_of(ObsKind::Beam).filter(|&(gi, _)| owners[gi] == gi) {
        let members: Vec<usize> = (0..obs.groups.len()).filter(|&k| owners[k] == gi).collect();
        let points = |at: &dyn Fn(usize) -> Point3<f64>| -> Vec<Point3<f64>> {
            let segments: Vec<Vec<Point3<f64>>> =
                members.iter().map(|&k| obs.groups[k].range().map(at).collect()).collect();
            centred_segments(&segments)
        };
        let actual = points(&|i| exact_position(model, &obs.x[i], &obs.p[i]));
        let commanded = points(&|i| obs.x[i] + obs.p[i]);
        let n_motion = fit_line(&actual).direction;
        let mut n_commanded = fit_line(&commanded).direction;
        if n_commanded.dot(&n_motion) < 0.0 {
            n_commanded = -n_commanded;
        }
        let dn = n_commanded - n_motion;
        let readings = members.iter().flat_map(|&k| obs.groups[k].range());
        sum += actual.iter().zip(readings).map(|(q, i)| (dn.dot(&q.coords) / sigmas[i]).powi(2)).sum::<f64>();
    }
    sum.sqrt()
}

/// What [`cover`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct Covered {
    /// [`separation`] at the estimate.
    pub separation: f64,
    /// Largest change of a volumetric error component (metres) between the two alignments'
    /// models, over the map's 50 mm grid of the travel with the probe at the tool; zero when the
    /// separation was negligible and no refit was made.
    pub largest_change_m: f64,
}

/// A solution whose uncertainty covers the other beam alignment than `opts.beam_alignment`,
/// for a campaign that does not say which one its beams had (see the module's documentation):
/// unchanged where the [`separation`] is below [`NEGLIGIBLE_SEPARATION`]; otherwise refitted
/// with the other alignment (same layout, smoothing held, started from the estimate), the
/// difference `d` of the coefficients added to the covariance as `d d^T / 3`, and a warning
/// that says by how much and what to state.
///
/// # Errors
/// When the refit fails ([`solve`]'s errors).
pub fn cover(
    obs: &Observations,
    opts: &SolveOptions,
    mut solution: Solution,
) -> Result<(Solution, Covered), SolveError> {
    let separation = separation(&solution.model, &solution.sigmas, obs);
    if separation <= NEGLIGIBLE_SEPARATION {
        return Ok((solution, Covered { separation, largest_change_m: 0.0 }));
    }
    let other = match opts.beam_alignment {
        BeamAlignment::Motion => BeamAlignment::Commanded,
        BeamAlignment::Commanded => BeamAlignment::Motion,
    };
    let o = SolveOptions {
        beam_alignment: other,
        smoothing: solution.smoothing.as_ref().map(Smoothing::fixed_from).or_else(|| opts.smoothing.clone()),
        initial_model: Some(solution.model.u.clone()),
        ..opts.clone()
    };
    let refit = solve(&solution.model.layout, obs, &o, &[])?;
    let d: Vec<f64> = refit.model.u.iter().zip(&solution.model.u).map(|(a, b)| a - b).collect();
    let n = d.len();
    for i in 0..n {
        for j in 0..n {
            solution.covariance[(i, j)] += d[i] * d[j] / 3.0;
        }
    }
    let largest_change_m = largest_change(&solution, &refit);
    solution.warnings.push(format!(
        "the campaign does not say what its beams were aligned with (machine file: beam_alignment): along the \
         commanded line instead of the reflector's motion ({} here), the readings' prediction moves by {:.1} times \
         their noise as a whole and the map by up to {:.2} um. The readings cannot tell the two apart (a cosine \
         error, second order in the machine's errors), so the uncertainty includes the difference; state \
         `beam_alignment: motion` or `beam_alignment: commanded` to remove it",
        opts.beam_alignment.name(),
        separation,
        largest_change_m * 1e6
    ));
    Ok((solution, Covered { separation, largest_change_m }))
}

/// Largest change of an error component between two models over the map's grid (50 mm).
fn largest_change(a: &Solution, b: &Solution) -> f64 {
    crate::predict::grid(&a.model.layout.travel, 0.05)
        .iter()
        .map(|x| (a.model.error_linear(x, &Vector3::zeros()) - b.model.error_linear(x, &Vector3::zeros())).amax())
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::axis::Travel;
    use crate::campaign::LineGroup;
    use crate::functions::Squareness;
    use crate::model::ModelLayout;
    use crate::repr::Representation;
    use crate::topology::Topology;

    /// A beam along Y on a machine whose only error is the squareness `EC0Y` (X gains
    /// `-y EC0Y`): the reflector's motion leans by `EC0Y` from the commanded line, and the two
    /// alignments' readings differ by the cosine error `(1 - sqrt(1 + S^2)) (y - mean y)`.
    #[test]
    fn separation_is_the_cosine_error_over_the_noise() {
        let travel = Travel::new([0.0, 1.0], [0.0, 0.8], [-0.6, 0.0]);
        let layout = ModelLayout::uniform(Topology::parse("FXYZ").unwrap(), travel, Representation::default());
        let mut model = ErrorModel::zero(layout);
        let s = 1e-3;
        model.set_squareness(Squareness::EC0Y, s);
        let n = 21;
        let ys: Vec<f64> = (0..n).map(|i| 0.8 * i as f64 / (n - 1) as f64).collect();
        let obs = Observations {
            x: ys.iter().map(|&y| Point3::new(0.5, y, -0.3)).collect(),
            p: vec![Vector3::zeros(); n],
            l: ys.clone(),
            t: vec![0.0; n],
            velocity: vec![None; n],
            air: vec![None; n],
            machine_temp: vec![None; n],
            reading: (0..n).collect(),
            groups: vec![LineGroup { kind: ObsKind::Beam, station: 0, line: 0, segment: 0, start: 0, end: n }],
        };
        let sigma = 1e-7;
        let got = separation(&model, &vec![sigma; n], &obs);
        let ym = ys.iter().sum::<f64>() / n as f64;
        let cosine = 1.0 - (1.0 + s * s).sqrt();
        let want = ys.iter().map(|y| (cosine * (y - ym) / sigma).powi(2)).sum::<f64>().sqrt();
        assert!((got - want).abs() < 1e-3 * want, "{got} against {want}");
        // Without errors the two alignments are the same beam.
        let zero = ErrorModel::zero(model.layout.clone());
        assert!(separation(&zero, &vec![sigma; n], &obs) < 1e-9);
    }
}
