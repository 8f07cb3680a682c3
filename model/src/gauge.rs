//! Gauge: the freedoms of the error model that no interferometric data can observe, and the
//! constraints that fix them.
//!
//! Beams measure displacements along a line relative to their own barycentre (patent eq. 2) and
//! tracers measure ranges from stations whose positions are unknown (paper eq. 4), so neither sees
//! a rigid motion of the whole error field. In the model's parameters these freedoms are
//! (see ARCHITECTURE.md for the derivation):
//!
//! - 9 constant translations (`t_k = const`);
//! - 9 constant rotations `r_a = w`, each combined with the straightness slopes that cancel its
//!   lever-arm part, leaving `w x p`, a constant per line (the "arbitrary coefficients" of Balsamo
//!   1995: predictions for a new probe offset are known up to a translation per probe);
//! - 3 rigid rotations of the reference frame (straightness slopes `t_b = w x e_b q_b`);
//! - 3 redundancies between the explicit squareness errors and straightness slopes.
//!
//! That is the patent's 21 plus 3. Both constraint sets remove exactly these 24:
//! [`Gauge::Patent`] (eq. 9-10: every function has zero mean; every straightness function has
//! zero mean slope, so that squareness is carried by the explicit parameters) and [`Gauge::Datum`]
//! (the paper: every function is zero at its axis origin; straightness is zero at the far end).

use crate::functions::{ErrorFunction, Motion, Squareness};
use crate::model::ModelLayout;
use faer::linalg::solvers::Solve;
use faer::Mat;

/// Choice of gauge constraints `C u = 0`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Gauge {
    /// Patent eq. (8)-(10): zero mean of every function, zero mean slope of every straightness.
    #[default]
    Patent,
    /// The paper's datum constraints: zero at each axis origin, straightness zero at the far end.
    Datum,
}

/// Number of gauge freedoms of the model (patent's 21 plus 3 squareness redundancies).
pub const GAUGE_DIM: usize = 24;

impl Gauge {
    pub fn parse(s: &str) -> Option<Gauge> {
        match s.trim().to_ascii_lowercase().as_str() {
            "patent" | "mean" | "barycentre" => Some(Gauge::Patent),
            "datum" | "paper" | "origin" => Some(Gauge::Datum),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Gauge::Patent => "patent",
            Gauge::Datum => "datum",
        }
    }

    pub fn describe(self) -> &'static str {
        match self {
            Gauge::Patent => "patent eq. 8-10: zero mean of each function, zero mean slope of each straightness",
            Gauge::Datum => "datum: each function zero at its axis origin, straightness zero at the far end",
        }
    }
}

/// Origin of an axis for the datum gauge: coordinate 0 clamped into the travel.
pub fn axis_origin(layout: &ModelLayout, f: ErrorFunction) -> f64 {
    let [lo, hi] = layout.travel.range(f.axis);
    0.0f64.clamp(lo, hi)
}

/// The far end of an axis: the end of the travel farthest from its origin.
pub fn axis_far_end(layout: &ModelLayout, f: ErrorFunction) -> f64 {
    let [lo, hi] = layout.travel.range(f.axis);
    let o = axis_origin(layout, f);
    if (hi - o).abs() >= (o - lo).abs() {
        hi
    } else {
        lo
    }
}

/// The constraint matrix `C` (24 x n_params) of a gauge.
pub fn constraints(layout: &ModelLayout, gauge: Gauge) -> Mat<f64> {
    let mut c = Mat::<f64>::zeros(GAUGE_DIM, layout.n_params);
    let mut row = 0;
    let mut put = |c: &mut Mat<f64>, f: ErrorFunction, g: Vec<f64>| {
        let r = layout.range(f);
        for (k, v) in r.zip(g) {
            c[(row, k)] = v;
        }
        row += 1;
    };
    for f in ErrorFunction::all() {
        let b = layout.basis(f);
        let g = match gauge {
            Gauge::Patent => b.mean_functional(),
            Gauge::Datum => b.value_functional(axis_origin(layout, f)),
        };
        put(&mut c, f, g);
    }
    for f in ErrorFunction::all().into_iter().filter(|f| f.is_straightness()) {
        let b = layout.basis(f);
        let g = match gauge {
            Gauge::Patent => b.slope_functional(),
            Gauge::Datum => b.value_functional(axis_far_end(layout, f)),
        };
        put(&mut c, f, g);
    }
    debug_assert_eq!(row, GAUGE_DIM);
    c
}

/// Basis (n_params x 24) of the gauge freedoms, built analytically from constant and linear
/// functions in each representation.
pub fn null_basis(layout: &ModelLayout) -> Mat<f64> {
    let n = layout.n_params;
    let mut out = Mat::<f64>::zeros(n, GAUGE_DIM);
    // Per function, the coefficients of a constant and of a line. The six functions of an axis
    // usually share one basis, which is then projected once.
    let mut projected: Vec<(&crate::repr::Basis, Vec<f64>, Vec<f64>)> = Vec::new();
    let (constant, linear): (Vec<Vec<f64>>, Vec<Vec<f64>>) = ErrorFunction::all()
        .iter()
        .map(|&f| {
            let b = layout.basis(f);
            if let Some((_, c, l)) = projected.iter().find(|(p, ..)| *p == b) {
                return (c.clone(), l.clone());
            }
            let (c, l) = (b.line(1.0, 0.0), b.line(0.0, 1.0));
            projected.push((b, c.clone(), l.clone()));
            (c, l)
        })
        .unzip();
    let trans = |axis, comp| ErrorFunction { axis, motion: Motion::Translation, component: comp };
    let mut col = 0;
    // Adds `scale * shape` to function f in column col.
    let add = |out: &mut Mat<f64>, col: usize, f: ErrorFunction, shape: &[Vec<f64>], scale: f64| {
        for (k, v) in layout.range(f).zip(&shape[f.index()]) {
            out[(k, col)] += scale * v;
        }
    };
    let axes = crate::axis::Axis::ALL;
    // 1. Constant translations.
    for a in axes {
        for c in axes {
            add(&mut out, col, trans(a, c), &constant, 1.0);
            col += 1;
        }
    }
    // 2. Constant rotations, lever-arm part cancelled by straightness slopes of carried axes.
    for a in axes {
        for c in axes {
            let r = ErrorFunction { axis: a, motion: Motion::Rotation, component: c };
            add(&mut out, col, r, &constant, 1.0);
            for &b in layout.topology.carried_by(a) {
                let v = c.unit().cross(&b.unit());
                for d in axes {
                    if v[d.index()] != 0.0 {
                        add(&mut out, col, trans(b, d), &linear, -v[d.index()]);
                    }
                }
            }
            col += 1;
        }
    }
    // 3. Rigid rotations of the reference frame.
    for c in axes {
        for b in axes {
            let v = c.unit().cross(&b.unit());
            for d in axes {
                if v[d.index()] != 0.0 {
                    add(&mut out, col, trans(b, d), &linear, v[d.index()]);
                }
            }
        }
        col += 1;
    }
    // 4. Squareness versus straightness slope.
    for s in Squareness::ALL {
        out[(layout.squareness_index(s), col)] = 1.0;
        let dir = s.direction_per_metre();
        let f = s.straightness();
        add(&mut out, col, f, &linear, -dir[f.component.index()]);
        col += 1;
    }
    debug_assert_eq!(col, GAUGE_DIM);
    out
}

/// Moves `u` along the gauge freedoms so that it satisfies the gauge's constraints. Two models
/// that differ only by gauge become identical; this is how simulated truth is compared with an
/// estimate ("after removing the gauge freedom").
pub fn align(layout: &ModelLayout, gauge: Gauge, u: &[f64]) -> Vec<f64> {
    let c = constraints(layout, gauge);
    let nb = null_basis(layout);
    let cn = &c * &nb;
    let uu = Mat::from_fn(u.len(), 1, |i, _| u[i]);
    let mut a = &c * &uu;
    cn.partial_piv_lu().solve_in_place(a.as_mut());
    let shift = &nb * &a;
    (0..u.len()).map(|i| u[i] - shift[(i, 0)]).collect()
}

/// Smallest singular value of `C N` relative to its largest: how well the constraints fix the
/// gauge freedoms (0 means some freedom is left free or constrained twice).
pub fn constraint_conditioning(layout: &ModelLayout, gauge: Gauge) -> f64 {
    conditioning_of(&constraints(layout, gauge), &null_basis(layout))
}

/// [`constraint_conditioning`] from an already computed constraint matrix and null basis.
pub fn conditioning_of(c: &Mat<f64>, null_basis: &Mat<f64>) -> f64 {
    let cn = c * null_basis;
    let s = cn.singular_values().unwrap_or_default();
    match (s.first(), s.last()) {
        (Some(&max), Some(&min)) if max > 0.0 => min / max,
        _ => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::axis::Travel;
    use crate::repr::Representation;
    use crate::topology::Topology;

    #[test]
    fn constraints_fix_every_freedom() {
        for topo in ["FXYZ", "FYXZ", "XFYZ"] {
            for repr in [
                Representation::default(),
                Representation::Table { nodes: 6 },
                Representation::Polynomial { degree: 4 },
                Representation::Harmonic { harmonics: 2, period_m: None },
            ] {
                let layout = ModelLayout::uniform(
                    Topology::parse(topo).unwrap(),
                    Travel::new([0.0, 1.0], [-0.5, 0.0], [-0.7, 0.0]),
                    repr,
                );
                for g in [Gauge::Patent, Gauge::Datum] {
                    let k = constraint_conditioning(&layout, g);
                    assert!(k > 1e-4, "{topo} {repr:?} {g:?}: {k}");
                }
            }
        }
    }
}
