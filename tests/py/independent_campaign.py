#!/usr/bin/env python3
"""An independent simulator of fixed-beam and laser-tracer campaigns (issue 12: data we did not
simulate), and the truth of validation lines measured on the same virtual machine.

Nothing here comes from volcal: the machine's errors, the plan and the readings are made from
the conventions of DESIGN.md section 3 and the campaign format of its section 4 alone.

- The machine: each of the 18 error functions is a draw of a smooth Gaussian process (squared
  exponential covariance, length scale 0.15 to 0.4 of the travel, by random Fourier features),
  scaled to a largest excursion of 10 um (positioning), 4 um (straightness) or 8 urad
  (rotations), and three squareness errors of up to 25 urad. This family is none of volcal's
  representations (no B-spline, polynomial or table) and none of its test families.
  `--amplitude K` scales every error by K and `--length-scale LO,HI` sets the range of the
  length scales, and `--bump H,WLO,WHI` adds to every function a Gaussian bump (a guideway's
  local defect) whose place and width the oracle is told: machines of other magnitudes and
  shapes, for studies of what the test seeds do not have (the defaults draw the same machine as
  before these options).
- The errors compose as ISO 230-1 and patent eq. (7) say: along the chain from workpiece to tool,
  each axis's translation errors plus its rotation errors acting on the lever arm to the tool
  (the coordinates of the axes it carries plus the probe offset), and the squareness errors
  `EC0Y` (Y rotated about Z: x gains -y EC0Y), `EB0Z` (x gains z EB0Z), `EA0Z` (y gains -z EA0Z).
  `e(X, p) = actual reflector position - (X + p)`. That is the small-angle sum (the default,
  `--composition first`); with `--composition rigid` the carriages compose as rigid bodies do,
  each axis's finite rotation (the rotation vector of its three angular errors) turning
  everything it carries, the errors of the axes it carries included, and its translation
  errors and sheared direction moving it: `P = q1 d1 + t1 + R1 (q2 d2 + t2 + R2 (q3 d3 + t3 +
  R3 p))`. The two differ by the rotations times what they carry, nanometres at the usual
  errors and tenths of a micrometre at thirty times them.
- Fixed beams (`--method beams`): lines through the working volume (axis-parallel lines on a
  3 x 3 grid of each cross-section, and the 18 face diagonals of the mid planes and the faces),
  each read at `--points` positions for each of three probe offsets. A reading is the
  reflector's displacement along the beam from an arbitrary origin per beam:
  `l = n . (X + p + e(X, p) + d) + c + w`, `d` the machine's repeatability (a displacement
  N(0, repeatability) per axis), `w` the interferometer's noise. With `--sparse`, 12 of the
  lines (two axis lines per axis and the mid planes' face diagonals): a plan whose beams leave
  the rolls of the three axes and the squareness EB0Z open in combination.
  `n` is the commanded line's direction in the frame the machine's errors are drawn in (the
  default, `--beam-alignment commanded`: beams set along the axes of a reference that is not
  the machine's motion), or with `--beam-alignment motion` the least-squares line of the
  reflector's actual positions along the beam (the patent's procedure: the beam aligned with
  the motion by its walk on the target). The two differ by the cosine of the angle between the
  motion and the reference, a beam scale of second order in the errors (nanometres at the usual
  magnitude, tenths of a micrometre at thirty times), and the readings alone cannot tell which.
- Laser tracer (`--method tracer`): 4 stations beside the corners of the volume, at four
  heights; the reflector at
  the tool (zero probe offset) visits the 12 edges of the working cuboid, `--points` stops per
  edge, in one continuous track per station (one dead path per station):
  `l = |X + p + e(X, p) + d - S| + c + w`, with `w` of the tracer's noise model.
- Both (`--method joint`): the 45 beams and the tracer's 4 tracks (`--stops` per edge) on one
  machine, in one campaign.
- Validation lines, none of them a beam of the campaign: three axis lines off the beams' grid,
  the four body diagonals (the paper's Table 4) and two face diagonals, 11 targets each, at the campaign's probe offsets: the
  positioning deviation an interferometer zeroed at the start reads, its beam aligned with the
  reflector's motion (through the actual positions at the line's start and end, direction `n'`),
  `n' . (P(X_s) - P(A)) - s`, from the true errors (noise-free); to first order
  `n . (e(X_s, p) - e(A, p))`.

- The oracle (`--oracle`): the estimator that knows the truth's own basis and prior (each
  function's random Fourier features and the Gaussian prior on their weights), the readings'
  noise and nothing else. Its prediction of each validation line is the posterior mean given
  the readings (the Bayes estimator under the prior the truth was drawn from), with a flat prior
  on the beams' origins and the stations' dead paths, and its uncertainty the posterior's. No
  estimator does better on this family and these readings on average, so volcal's error over
  the oracle's says how near the information limit it comes. With `--map-step S` also the map
  it would draw: its posterior-mean machine's volumetric error, beside the truth's, on the grid
  `volcal map --step S` uses, at each probe offset of the campaign.

Usage:
    independent_campaign.py --method beams|tracer --topology FXYZ --travel "0,1;0,0.8;-0.6,0" \
        --seed N --points 25 [--oracle [--map-step 0.2]] --out DIR

writes DIR/campaign.csv (volcal's campaign CSV) and DIR/validation.json (with `--oracle`, each
line also has `oracle_m` and `oracle_sd_m`; with `--map-step`, DIR/map.csv: the point, the
probe offset, the truth's and the oracle's error vector). Noise as volcal's
defaults (interferometer 0.05 um, repeatability 0.2 um, tracer 0.1 um + 0.2 ppm), so that the
two-line machine file states it. Needs NumPy.
"""

import argparse
import copy
import json
import os

import numpy as np

AXES = "XYZ"
INTERFEROMETER_M = 0.05e-6
REPEATABILITY_M = 0.2e-6
TRACER_M = 0.1e-6
TRACER_PPM = 0.2
SQUARENESS = ("EC0Y", "EB0Z", "EA0Z")
SQUARENESS_SD = 12.5e-6


def smooth_draw(rng, lo, hi, amplitude, length_scale=(0.15, 0.4)):
    """A squared-exponential Gaussian-process draw on [lo, hi], largest excursion `amplitude`,
    length scale drawn uniformly from `length_scale` (fractions of the travel)."""
    length = (hi - lo) * rng.uniform(*length_scale)
    m = 400
    omega = rng.normal(0.0, 1.0 / length, m)
    phase = rng.uniform(0.0, 2.0 * np.pi, m)
    weight = rng.normal(0.0, 1.0, m)
    grid = np.linspace(lo, hi, 2001)
    raw = (weight[None, :] * np.cos(np.outer(grid - lo, omega) + phase[None, :])).sum(axis=1)
    scale = amplitude / max(np.max(np.abs(raw - raw.mean())), 1e-30)

    return Draw(lo, omega, phase, weight, scale)


def largest_excursion(c, a):
    """The largest excursion of function `E{c}{a}` at amplitude 1: 10 um of positioning, 4 um of
    straightness, 8 urad of rotation."""
    if c in AXES:
        return 10e-6 if c == a else 4e-6
    return 8e-6


class Draw:
    """One function of the machine, `scale * sum_j w_j cos(omega_j (q - lo) + phase_j)`: its
    own basis (the features) and its weights; with a bump (`with_bump`), one more feature, a
    Gaussian `height * exp(-(q - centre)^2 / (2 width^2))`, and its weight."""

    def __init__(self, lo, omega, phase, weight, scale):
        self.lo, self.omega, self.phase, self.weight, self.scale = lo, omega, phase, weight, scale
        self.bump = None

    def with_bump(self, centre, width, height, weight):
        """The same function plus a local bump at `centre` of standard width `width` and weight
        `weight` (N(0, 1) under the prior) on the feature of height `height`: a guideway's
        local defect, which the oracle is told the place and width of, as the suite's is."""
        self.bump = (centre, width, height)
        self.weight = np.append(self.weight, weight)
        return self

    def features(self, q):
        """The basis at `q` (n x m), so that f(q) = features(q) @ weight."""
        q = np.asarray(q, dtype=float)
        f = self.scale * np.cos(np.multiply.outer(q - self.lo, self.omega) + self.phase)
        if self.bump is None:
            return f
        centre, width, height = self.bump
        g = height * np.exp(-0.5 * ((q - centre) / width) ** 2)
        return np.concatenate([f, g[..., None]], axis=-1)

    def __call__(self, q):
        return self.features(q) @ self.weight


def rotated(r, v):
    """Each row of `v` turned by the finite rotation whose vector is the same row of `r`
    (Rodrigues: `v + a (r x v) + b r x (r x v)`, `a = sin t / t`, `b = (1 - cos t) / t^2`)."""
    t2 = np.sum(r * r, axis=1)
    t = np.sqrt(t2)
    # Their series where the angle is tiny (every angle here is below a milliradian).
    a = np.where(t > 1e-4, np.sin(t) / np.where(t > 1e-4, t, 1.0), 1.0 - t2 / 6.0 + t2 * t2 / 120.0)
    b = np.where(t > 1e-4, (1.0 - np.cos(t)) / np.where(t > 1e-4, t2, 1.0), 0.5 - t2 / 24.0 + t2 * t2 / 720.0)
    rv = np.cross(r, v)
    return v + a[:, None] * rv + b[:, None] * np.cross(r, rv)


class Machine:
    def __init__(self, topology, travel, seed, amplitude=1.0, length_scale=(0.15, 0.4), composition="first", bump=None):
        """`amplitude` scales every error (the functions' largest excursions and the squareness
        errors' spread); `length_scale` is the range of the functions' length scales, fractions of
        the travel; `bump` `(height, width_lo, width_hi)` adds to every function a Gaussian bump
        at a uniformly drawn place, its standard width drawn from `width_lo..width_hi` of the
        travel and its height N(0, (height x the function's largest excursion)^2), drawn from a
        stream of their own (the rest of the machine is the same draw). The defaults are the
        machine of the docstring."""
        self.chain = [c for c in topology if c in AXES]
        self.travel = travel
        self.sq_sd = SQUARENESS_SD * amplitude
        rng = np.random.default_rng(seed)
        self.f = {}
        for a in AXES:
            lo, hi = travel[AXES.index(a)]
            for c in "XYZABC":
                self.f[f"E{c}{a}"] = smooth_draw(rng, lo, hi, amplitude * largest_excursion(c, a), length_scale)
        if bump is not None:
            height, w_lo, w_hi = bump
            brng = np.random.default_rng([seed, 1797])
            for a in AXES:
                lo, hi = travel[AXES.index(a)]
                for c in "XYZABC":
                    amp = amplitude * largest_excursion(c, a)
                    centre, width = brng.uniform(lo, hi), (hi - lo) * brng.uniform(w_lo, w_hi)
                    self.f[f"E{c}{a}"].with_bump(centre, width, height * amp, brng.normal())
        self.sq = {s: float(np.clip(rng.normal(0.0, self.sq_sd), -2 * self.sq_sd, 2 * self.sq_sd)) for s in SQUARENESS}
        self.composition = composition

    def error(self, x, p):
        """e(X, p) for arrays x, p of shape (n, 3), composed as `composition` says."""
        return self.rigid_error(x, p) if self.composition == "rigid" else self.first_order_error(x, p)

    def rigid_error(self, x, p):
        """e(X, p) of rigid carriages: from the tool back to the frame, each axis moves what it
        carries by its sheared direction times its coordinate and its translation errors, and
        turns it by the finite rotation whose vector is its angular errors (Rodrigues)."""
        x = np.atleast_2d(x)
        v = np.array(np.broadcast_to(np.atleast_2d(p), x.shape), dtype=float)
        shear = {
            "X": np.zeros(3),
            "Y": np.array([-self.sq["EC0Y"], 0.0, 0.0]),
            "Z": np.array([self.sq["EB0Z"], -self.sq["EA0Z"], 0.0]),
        }
        for a in reversed(self.chain):
            q = x[:, AXES.index(a)]
            t = np.stack([self.f[f"E{c}{a}"](q) for c in AXES], axis=1)
            r = np.stack([self.f[f"E{c}{a}"](q) for c in "ABC"], axis=1)
            d = np.eye(3)[AXES.index(a)] + shear[a]
            v = q[:, None] * d + t + rotated(r, v)
        return v - (x + np.broadcast_to(np.atleast_2d(p), x.shape))

    def first_order_error(self, x, p):
        """e(X, p) as the small-angle sum, for arrays x, p of shape (n, 3): what the
        sensitivities below write as a linear map."""
        x = np.atleast_2d(x)
        p = np.broadcast_to(np.atleast_2d(p), x.shape)
        e = np.zeros_like(x)
        for k, a in enumerate(self.chain):
            q = x[:, AXES.index(a)]
            t = np.stack([self.f[f"E{c}{a}"](q) for c in AXES], axis=1)
            r = np.stack([self.f[f"E{c}{a}"](q) for c in "ABC"], axis=1)
            h = np.array(p, dtype=float)
            for b in self.chain[k + 1:]:
                h[:, AXES.index(b)] += x[:, AXES.index(b)]
            e += t + np.cross(r, h)
        e[:, 0] += -x[:, 1] * self.sq["EC0Y"] + x[:, 2] * self.sq["EB0Z"]
        e[:, 1] += -x[:, 2] * self.sq["EA0Z"]
        return e

    def sensitivities(self, x, p, n):
        """How `n . e(X, p)` depends on each function's value at the readings' positions and on
        each squareness: `({function: (axis, multiplier)}, {squareness: multiplier})`, for
        arrays x, p, n of shape (n, 3). It is `error` written as a linear map."""
        x = np.atleast_2d(x)
        p = np.broadcast_to(np.atleast_2d(p), x.shape)
        out = {}
        for k, a in enumerate(self.chain):
            h = np.array(p, dtype=float)
            for b in self.chain[k + 1:]:
                h[:, AXES.index(b)] += x[:, AXES.index(b)]
            lever = np.cross(h, n)  # n . (r x h) = r . (h x n)
            for i, c in enumerate(AXES):
                out[f"E{c}{a}"] = (AXES.index(a), n[:, i])
            for i, c in enumerate("ABC"):
                out[f"E{c}{a}"] = (AXES.index(a), lever[:, i])
        sq = {"EC0Y": -n[:, 0] * x[:, 1], "EB0Z": n[:, 0] * x[:, 2], "EA0Z": -n[:, 1] * x[:, 2]}
        return out, sq

    def covariance(self, a, b):
        """The prior covariance of `n . e(X, p)` between two sets of readings `a` and `b`
        (each a tuple x, p, n of arrays (n, 3)), under the prior the truth was drawn from: each
        function's weights N(0, 1) on its own features, the squareness errors N(0, `sq_sd`)."""
        (fa, sa), (fb, sb) = self.sensitivities(*a), self.sensitivities(*b)
        ca = [sa[s][:, None] * self.sq_sd for s in SQUARENESS]
        cb = [sb[s][:, None] * self.sq_sd for s in SQUARENESS]
        for name, (axis, ga) in fa.items():
            # The features at the distinct positions, reduced to their column space (exact: the
            # same kernel, fewer columns where there are fewer positions than features).
            q, inverse = np.unique(np.concatenate([a[0][:, axis], b[0][:, axis]]), return_inverse=True)
            u, s, _ = np.linalg.svd(self.f[name].features(q), full_matrices=False)
            factor = u * s
            ca.append(ga[:, None] * factor[inverse[: len(ga)]])
            cb.append(fb[name][1][:, None] * factor[inverse[len(ga) :]])
        return np.hstack(ca) @ np.hstack(cb).T

    def projected(self, x, p, n):
        """`n . e(X, p)` from the sensitivities, to check them against `first_order_error`."""
        funcs, sq = self.sensitivities(x, p, n)
        return sum(g * self.f[name](x[:, axis]) for name, (axis, g) in funcs.items()) + sum(
            sq[s] * self.sq[s] for s in SQUARENESS
        )


def corners(travel):
    return [np.array([travel[0][i], travel[1][j], travel[2][k]]) for i in (0, 1) for j in (0, 1) for k in (0, 1)]


def beam_lines(travel, sparse=False):
    """Axis-parallel lines on a 3 x 3 grid of each cross-section and the face diagonals of the
    three mid planes and of the six faces (the body diagonals are left to the validation); with
    `sparse`, 12 of them: two axis lines per axis (opposite edges of the grid) and the mid
    planes' face diagonals."""
    lo = np.array([t[0] for t in travel])
    hi = np.array([t[1] for t in travel])
    span = hi - lo
    lines = []
    for a in range(3):
        others = [b for b in range(3) if b != a]
        for u in (0.15, 0.5, 0.85):
            for v in (0.15, 0.5, 0.85):
                if sparse and not (u == v and u != 0.5):
                    continue
                start = lo.copy()
                start[others[0]] += u * span[others[0]]
                start[others[1]] += v * span[others[1]]
                end = start.copy()
                start[a], end[a] = lo[a], hi[a]
                lines.append((start, end))
    for a in range(3):
        b, c = [k for k in range(3) if k != a]
        for level in (0.5,) if sparse else (0.0, 0.5, 1.0):
            for flip in (False, True):
                s = lo.copy()
                s[a] = lo[a] + level * span[a]
                e = s.copy()
                s[b], e[b] = lo[b], hi[b]
                s[c], e[c] = (hi[c], lo[c]) if flip else (lo[c], hi[c])
                lines.append((s, e))
    return lines


def validation_lines(travel):
    lo = np.array([t[0] for t in travel])
    hi = np.array([t[1] for t in travel])
    out = []
    for a in range(3):
        # Off the beams' 3 x 3 grid of lines.
        s = lo + np.array([0.3, 0.7, 0.6]) * (hi - lo)
        e = s.copy()
        s[a], e[a] = lo[a], hi[a]
        out.append((f"axis {AXES[a]}", s, e))
    # The paper's diagonals (NPP, NPN, PPN, PPP: from the bottom of Z to the opposite corner).
    for name, (x0, y0) in {"NPP": (1, 0), "NPN": (0, 1), "PPN": (1, 1), "PPP": (0, 0)}.items():
        s = np.array([[lo, hi][x0][0], [lo, hi][y0][1], lo[2]])
        e = np.array([[hi, lo][x0][0], [hi, lo][y0][1], hi[2]])
        out.append((name, s, e))
    # Two face diagonals off the mid planes (not among the beams' lines).
    s = np.array([lo[0], lo[1] + 0.3 * (hi[1] - lo[1]), lo[2] + 0.3 * (hi[2] - lo[2])])
    e = np.array([hi[0], lo[1] + 0.3 * (hi[1] - lo[1]), hi[2] - 0.3 * (hi[2] - lo[2])])
    out.append(("XZ diagonal", s, e))
    s = np.array([lo[0] + 0.7 * (hi[0] - lo[0]), lo[1], hi[2] - 0.2 * (hi[2] - lo[2])])
    e = np.array([lo[0] + 0.3 * (hi[0] - lo[0]), hi[1], hi[2] - 0.2 * (hi[2] - lo[2])])
    out.append(("XY diagonal", s, e))
    return out


def oracle(machine, seen, targets):
    """The oracle: the estimator that knows the truth's own basis and prior (each function's
    features, its weights N(0, 1), the squareness errors N(0, 12.5 urad)), the readings' noise
    and nothing else, i.e. not the weights. It is the Bayes estimator of the validation lines
    under the prior the truth was drawn from: the posterior mean given the readings, with a
    flat prior on each beam's origin and each station's dead path (universal kriging, in the
    space of the readings). Returns, per validation line, the predicted deviation and its
    standard uncertainty, in metres, and the posterior mean of the machine (whose `error` is
    the oracle's map)."""
    um = 1e6
    stack = lambda i: np.vstack([np.broadcast_to(s[i], s[0].shape) for s in seen])
    readings = (stack(0), stack(1), stack(2))
    y = np.concatenate([s[3] for s in seen]) * um
    group = np.concatenate([s[4] for s in seen])
    var = np.concatenate([np.broadcast_to(s[5], s[4].shape) for s in seen]) * um**2
    # The sensitivities are the machine's error written as a linear map: check them.
    e = np.einsum("ij,ij->i", readings[2], machine.first_order_error(readings[0], readings[1]))
    assert np.allclose(machine.projected(*readings), e, rtol=0, atol=1e-15)
    # A validation target is the difference of `n . e` between a point and its line's start.
    full = [[np.broadcast_to(t[i], t[0].shape) for i in range(3)] for t in targets]
    ends = [np.vstack([t[i] for t in full]) for i in range(3)]
    starts = [np.vstack([np.broadcast_to(t[i][:1], t[0].shape) for t in full]) for i in range(3)]
    both = tuple(np.vstack([u, v]) for u, v in zip(ends, starts))
    m = len(ends[0])
    diff = np.hstack([np.eye(m), -np.eye(m)])
    c = machine.covariance(readings, readings) * um**2 + np.diag(var)
    k = machine.covariance(readings, both) @ diff.T * um**2
    kzz = np.diag(diff @ machine.covariance(both, both) @ diff.T) * um**2
    ids = np.unique(group)
    nuisance = (group[:, None] == ids[None, :]).astype(float)
    solved = np.linalg.solve(c, np.hstack([y[:, None], nuisance, k]))
    ciy, cin, cik = solved[:, :1], solved[:, 1 : 1 + len(ids)], solved[:, 1 + len(ids) :]
    mnn = nuisance.T @ cin
    beta = np.linalg.solve(mnn, nuisance.T @ ciy)
    mean = (cik.T @ (y[:, None] - nuisance @ beta))[:, 0]
    r = nuisance.T @ cik
    variance = kzz - np.sum(k * cik, axis=0) + np.sum(r * np.linalg.solve(mnn, r), axis=0)
    sdev = np.sqrt(np.maximum(variance, 0.0))
    out, at = [], 0
    for tx, _, _ in targets:
        out.append((mean[at : at + len(tx)] / um, sdev[at : at + len(tx)] / um))
        at += len(tx)
    # The posterior mean of the machine itself: each function's weights and each squareness,
    # E[w] = Phi' G alpha with alpha = C^-1 (y - N beta) (the prior's covariance of the weights
    # is the identity), a machine whose `error` is the oracle's map. Its validation lines must
    # be the oracle's.
    # (Solved again rather than from C^-1 y - C^-1 N beta: the readings carry their origins,
    # up to half a metre, and that difference would cancel to nanometres.)
    alpha = np.linalg.solve(c, y[:, None] - nuisance @ beta)[:, 0] * um
    funcs, sq = machine.sensitivities(*readings)
    posterior = copy.deepcopy(machine)
    for name, (axis, g) in funcs.items():
        posterior.f[name].weight = machine.f[name].features(readings[0][:, axis]).T @ (g * alpha)
    for name in SQUARENESS:
        posterior.sq[name] = machine.sq_sd**2 * float(sq[name] @ alpha)
    through = posterior.projected(*ends) - posterior.projected(*starts)
    # To the picometre per unit of `--amplitude`: the rounding grows with the errors' size.
    tol = 1e-12 * max(1.0, machine.sq_sd / SQUARENESS_SD)
    assert np.allclose(through, mean / um, rtol=0, atol=tol), np.max(np.abs(through - mean / um))
    return out, posterior


def relinearised(machine, seen, ranges, beams, targets, predicted, posterior):
    """The oracle with the ranges linearised at its own posterior mean instead of the nominal
    positions, again until its validation lines settle to a picometre (Gauss-Newton: a range
    `l = |X + p + e - S| + c` reads `n . e + c` with `n` the direction at `X + p + e_hat` and the
    reading less `|X + p + e_hat - S| - n . e_hat`). At the usual errors the nominal linearisation
    is already this; at thirty times them (a millimetre) it is off by a micrometre. With rigid
    carriages (`--composition rigid`) every reading also carries what the oracle's linear map
    leaves out, the posterior's rigid error less its first-order error (`e_hat - e1_hat`): each
    beam's reading (`beams`: their indices in `seen`) is taken less it along the beam, and each
    range is linearised about the first-order error."""
    rigid = machine.composition == "rigid"
    # With the small-angle sum the linear map is the machine's error and leaves nothing out.
    beams = beams if rigid else []
    nominal = {k: seen[k][3] for k in beams}
    for _ in range(8):
        # The posterior's errors at each track's points, once per round.
        e_hats = [posterior.error(seen[k][0], seen[k][1]) for k, _, _ in ranges]
        first = [posterior.first_order_error(seen[k][0], seen[k][1]) for k, _, _ in ranges] if rigid else e_hats
        # Along each beam, what the linear map leaves out (its mean is the beam's origin's).
        rest = {}
        for k in beams:
            x, p, n = seen[k][0], seen[k][1], seen[k][2]
            rest[k] = np.einsum("ij,ij->i", n, posterior.error(x, p) - posterior.first_order_error(x, p))
        # What the nominal linearisation leaves out of each range, `|e_hat|^2 / r` at most: at the
        # usual errors a nanometre or two, below a tenth of the tracer's noise, and the oracle
        # stands as it is; at ten times the errors a tenth of a micrometre.
        left_out = 0.0
        for (k, q, _), e_hat in zip(ranges, e_hats):
            x, p = seen[k][0], seen[k][1]
            left_out = max(left_out, np.max(np.sum(e_hat**2, axis=1) / np.linalg.norm(x + p - q, axis=1)))
        for (k, _, _), e_hat, e1_hat in zip(ranges, e_hats, first):
            left_out = max(left_out, np.max(np.abs(e_hat - e1_hat)))
        for k in beams:
            left_out = max(left_out, np.max(np.abs(rest[k] - rest[k].mean())))
        if left_out < 0.1 * TRACER_M:
            break
        for (k, q, l), e_hat, e1_hat in zip(ranges, e_hats, first):
            x, p, _, _, group, var = seen[k]
            v = x + p + e_hat - q
            r = np.linalg.norm(v, axis=1)
            n = v / r[:, None]
            seen[k] = (x, p, n, l - r + np.einsum("ij,ij->i", n, e1_hat), group, var)
        for k in beams:
            x, p, n, _, group, var = seen[k]
            seen[k] = (x, p, n, nominal[k] - rest[k], group, var)
        before = predicted
        predicted, posterior = oracle(machine, seen, targets)
        moved = max(np.max(np.abs(m - b)) for (m, _), (b, _) in zip(predicted, before))
        if moved < 1e-12:
            break
    return predicted, posterior


def aligned_deviation(x, p, err):
    """The positioning deviations an interferometer reads along the targets `x` (the first the
    line's start, the last its end) with its beam aligned with the reflector's motion, through the
    reflector's actual positions at the start and the end, as it is set up: `n' . (P(X_s) - P(A))
    - s`. To first order `n . (e(X_s, p) - e(A, p))`; unlike that, it does not depend on the frame
    the errors are given in, which at errors of a millimetre differs by half a micrometre."""
    actual = x + p + err
    beam = actual[-1] - actual[0]
    return (actual - actual[0]) @ (beam / np.linalg.norm(beam)) - np.linalg.norm(x - x[0], axis=1)


def grid(travel, step):
    """The grid of `volcal map --step` (volcal's `predict::grid`): per axis the travel in
    `span / step` equal intervals (rounded), ends included; X fastest, then Y, then Z."""
    axes = []
    for lo, hi in travel:
        # Rust's `round` (half away from zero), not Python's (half to even).
        n = max(int(np.floor((hi - lo) / step + 0.5)), 1)
        axes.append([lo + (hi - lo) * i / n for i in range(n + 1)])
    return np.array([(x, y, z) for z in axes[2] for y in axes[1] for x in axes[0]])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--method", choices=["beams", "tracer", "joint"], required=True)
    ap.add_argument("--topology", default="FXYZ")
    ap.add_argument("--travel", default="0,1;0,0.8;-0.6,0", help="lo,hi per axis in metres, X;Y;Z")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--points", type=int, default=25, help="per beam, or stops per edge of the tracer")
    ap.add_argument("--stops", type=int, default=11, help="stops per edge of the tracer in a joint campaign")
    ap.add_argument("--sparse", action="store_true", help="12 beams instead of 45 (--method beams)")
    ap.add_argument("--beam-alignment", choices=["commanded", "motion"], default="commanded", help="each beam along its commanded line in the errors' frame, or along the reflector's actual motion (least-squares line)")
    ap.add_argument("--oracle", action="store_true", help="also the oracle's prediction of each validation line")
    ap.add_argument("--map-step", type=float, help="with --oracle: the truth's and the oracle's map on volcal's grid of this step (map.csv)")
    ap.add_argument("--amplitude", type=float, default=1.0, help="scales every error of the machine (1: 10 um positioning, 4 um straightness, 8 urad rotations, squareness spread 12.5 urad)")
    ap.add_argument("--length-scale", default="0.15,0.4", help="lo,hi of the functions' length scales, fractions of the travel")
    ap.add_argument("--bump", help="HEIGHT,WLO,WHI: every function also has a Gaussian bump (height N(0, (HEIGHT x its largest excursion)^2), standard width WLO..WHI of the travel, anywhere on it), which the oracle is told the place and width of")
    ap.add_argument("--composition", choices=["first", "rigid"], default="first", help="the errors as the small-angle sum, or composed as rigid carriages (finite rotations turning what they carry)")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    travel = [tuple(float(v) for v in t.split(",")) for t in a.travel.split(";")]
    bump = tuple(float(v) for v in a.bump.split(",")) if a.bump else None
    machine = Machine(a.topology, travel, a.seed, a.amplitude, tuple(float(v) for v in a.length_scale.split(",")), a.composition, bump)
    rng = np.random.default_rng(a.seed + 7_000_000)
    rows = []
    # What the oracle sees of each block of readings: positions, probe, the direction the
    # reading measures e along, the reading less its nominal value, its origin's group, variance.
    seen = []
    beams_seen = []
    val_offsets = []
    if a.method in ("beams", "joint"):
        offsets = [np.array([0.0, 0.0, 0.0]), np.array([0.15, 0.0, -0.1]), np.array([0.0, 0.15, -0.1])]
        beam = 0
        for p in offsets:
            for s, e in beam_lines(travel, a.sparse):
                n = (e - s) / np.linalg.norm(e - s)
                x = s + np.outer(np.linspace(0.0, 1.0, a.points), e - s)
                err = machine.error(x, p)
                if a.beam_alignment == "motion":
                    # The principal direction of the reflector's actual positions (no noise: the
                    # alignment is made before the readings, by the beam's walk on the target).
                    moved = x + p + err
                    n = np.linalg.svd(moved - moved.mean(axis=0))[2][0]
                    n = n if n @ (e - s) > 0 else -n
                actual = x + p + err + rng.normal(0.0, REPEATABILITY_M, x.shape)
                l = actual @ n + rng.uniform(-0.5, 0.5) + rng.normal(0.0, INTERFEROMETER_M, len(x))
                for xi, li in zip(x, l):
                    rows.append(("beam", 0, beam, li, xi, p))
                seen.append((x, p, np.tile(n, (len(x), 1)), l - (x + p) @ n, np.full(len(x), beam), np.full(len(x), REPEATABILITY_M**2 + INTERFEROMETER_M**2)))
                beams_seen.append(len(seen) - 1)
                beam += 1
        val_offsets = offsets
    ranges = []
    if a.method in ("tracer", "joint"):
        stops = a.points if a.method == "tracer" else a.stops
        lo = np.array([t[0] for t in travel])
        hi = np.array([t[1] for t in travel])
        span = hi - lo
        p = np.array([0.0, 0.0, 0.0])
        # Beside the corners of the volume, at four heights (coplanar stations weaken the method).
        stations = [
            np.array([lo[0] + u * span[0], lo[1] + v * span[1], lo[2] + w * span[2]])
            for u, v, w in ((-0.1, -0.1, -0.2), (1.1, -0.1, 0.3), (1.1, 1.1, -0.1), (-0.1, 1.1, 0.6))
        ]
        cs = corners(travel)
        edges = [(i, j) for i in range(8) for j in range(i + 1, 8) if np.count_nonzero(cs[i] != cs[j]) == 1]
        track = []
        for i, j in edges:
            for t in np.linspace(0.0, 1.0, stops):
                track.append(cs[i] + t * (cs[j] - cs[i]))
        x = np.array(track)
        for st, q in enumerate(stations):
            actual = x + p + machine.error(x, p) + rng.normal(0.0, REPEATABILITY_M, x.shape)
            r = np.linalg.norm(actual - q, axis=1)
            sigma = np.sqrt(TRACER_M**2 + (TRACER_PPM * 1e-6 * r) ** 2)
            l = r + rng.uniform(0.1, 0.3) + rng.normal(0.0, 1.0, len(r)) * sigma
            for xi, li in zip(x, l):
                rows.append(("range", st, 0, li, xi, p))
            nominal = np.linalg.norm(x + p - q, axis=1)
            # To first order in the errors at the nominal positions (|e|^2 / r is a nanometre or
            # two at the usual errors); beyond, the oracle linearises again at its posterior
            # (`relinearised`).
            seen.append((x, p, (x + p - q) / nominal[:, None], l - nominal, np.full(len(x), 1000 + st), REPEATABILITY_M**2 + sigma**2))
            ranges.append((len(seen) - 1, q, l))
        if not val_offsets:
            val_offsets = [p]
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, "campaign.csv"), "w") as fh:
        fh.write(f"# independent_campaign.py --method {a.method} --topology {a.topology} --seed {a.seed}\n")
        fh.write("kind,station,beam,t_s,l_m,x_m,y_m,z_m,px_m,py_m,pz_m\n")
        for i, (kind, st, b, l, x, p) in enumerate(rows):
            fh.write(f"{kind},{st},{b},{i * 0.5:.1f},{l:.12f},{x[0]:.9f},{x[1]:.9f},{x[2]:.9f},{p[0]:.6f},{p[1]:.6f},{p[2]:.6f}\n")
    lines, targets = [], []
    for p in val_offsets:
        for name, s, e in validation_lines(travel):
            n = (e - s) / np.linalg.norm(e - s)
            x = s + np.outer(np.linspace(0.0, 1.0, 11), e - s)
            dev = aligned_deviation(x, p, machine.error(x, p))
            lines.append({"name": name, "start": s.tolist(), "end": e.tolist(), "probe": p.tolist(), "deviation_m": dev.tolist()})
            targets.append((x, p, np.tile(n, (len(x), 1))))
    if a.oracle:
        predicted, posterior = oracle(machine, seen, targets)
        predicted, posterior = relinearised(machine, seen, ranges, beams_seen, targets, predicted, posterior)
        for line, (mean, sd), (x, p, _) in zip(lines, predicted, targets):
            # The posterior mean machine's reading with the beam aligned (its first-order part is
            # `mean`, which the oracle's own check holds to the picometre).
            line["oracle_m"], line["oracle_sd_m"] = aligned_deviation(x, p, posterior.error(x, p)).tolist(), sd.tolist()
    if a.oracle and a.map_step:
        x = grid(travel, a.map_step)
        with open(os.path.join(a.out, "map.csv"), "w") as fh:
            fh.write("x_m,y_m,z_m,px_m,py_m,pz_m,truth_x_m,truth_y_m,truth_z_m,oracle_x_m,oracle_y_m,oracle_z_m\n")
            for p in val_offsets:
                truth, mean = machine.error(x, p), posterior.error(x, p)
                for xi, ti, mi in zip(x, truth, mean):
                    fh.write(",".join(f"{v:.12g}" for v in (*xi, *p, *ti, *mi)) + "\n")
    with open(os.path.join(a.out, "validation.json"), "w") as fh:
        json.dump({"method": a.method, "topology": a.topology, "travel": travel, "seed": a.seed, "lines": lines}, fh, indent=1)


if __name__ == "__main__":
    main()
