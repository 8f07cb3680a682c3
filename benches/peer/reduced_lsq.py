#!/usr/bin/env python3
"""Benchmark peer: the patent's reduced least squares (EP 1 990 605, eq. 2) in NumPy/SciPy.

An independent implementation of what `volcal solve` computes for a fixed-beam campaign, used
to check our result and to compare speed on the same data:

- the rigid-body error model of patent eq. (3)-(7) for any axis stacking, small-angle form,
  18 functions as clamped cubic B-splines (scipy.interpolate.BSpline) plus 3 squareness terms;
- per beam: the least-squares line of the actual machine points (direction re-estimated after
  each solve) and barycentre reduction (the unknown interferometer origin);
- the patent's gauge (eq. 8-10): zero mean of every function, zero mean slope of every
  straightness function, as linear functionals by Gauss-Legendre quadrature;
- the constrained weighted least squares solved through the null space of the constraints
  (scipy.linalg.null_space) and a Cholesky factorisation of the reduced normal equations
  (scipy.linalg.cho_factor), the normal equations assembled with scipy.sparse.

The timed part is the solve (everything after reading the CSV). Usage:

    reduced_lsq.py campaign.csv --topology FXYZ --travel 0,1 0,0.8 -0.6,0 --intervals 12 \
        [--compare model.json] [--json out.json]
"""

import argparse
import json
import time

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.interpolate import BSpline

AXES = "XYZ"


def read_campaign(path):
    cols = None
    rows = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            fields = line.split(",")
            if cols is None:
                cols = {name: i for i, name in enumerate(fields)}
                continue
            rows.append(fields)
    get = lambda name: np.array([float(r[cols[name]]) for r in rows])
    beams = np.array([(int(r[cols["station"]]), int(r[cols["beam"]])) for r in rows if r[cols["kind"]] == "beam"])
    keep = np.array([r[cols["kind"]] == "beam" for r in rows])
    x = np.stack([get("x_m"), get("y_m"), get("z_m")], axis=1)[keep]
    p = np.stack([get("px_m"), get("py_m"), get("pz_m")], axis=1)[keep]
    l = get("l_m")[keep]
    _, group = np.unique(beams, axis=0, return_inverse=True)
    return x, p, l, group.ravel()


class Layout:
    """Clamped uniform cubic B-splines on each axis, 18 functions + 3 squareness terms."""

    def __init__(self, topology, travel, intervals):
        self.chain = [AXES.index(c) for c in topology if c != "F"]
        self.travel = travel
        self.m = intervals
        self.nc = intervals + 3
        self.knots = []
        for lo, hi in travel:
            inner = np.linspace(lo, hi, intervals + 1)
            self.knots.append(np.concatenate([[lo] * 3, inner, [hi] * 3]))
        self.n = 18 * self.nc + 3

    def offset(self, axis, m):
        """Offset of function m (0..6: EX, EY, EZ, EA, EB, EC) of an axis."""
        return (axis * 6 + m) * self.nc

    def basis(self, axis, q):
        lo, hi = self.travel[axis]
        return BSpline.design_matrix(np.clip(q, lo, hi), self.knots[axis], 3).tocsr()

    def lever(self, axis, x, p):
        """Lever arm of the rotations of `axis`: the axes it carries plus the probe offset."""
        h = p.copy()
        pos = self.chain.index(axis)
        for b in self.chain[pos + 1:]:
            h[:, b] += x[:, b]
        return h


def design(layout, x, p, n, bases):
    """Rows n_i . de/du for every reading, as a sparse matrix (readings x parameters)."""
    blocks = []
    for a in range(3):
        h = layout.lever(a, x, p)
        hxn = np.cross(h, n)  # (e_c x h) . n = (h x n)_c
        scal = [n[:, 0], n[:, 1], n[:, 2], hxn[:, 0], hxn[:, 1], hxn[:, 2]]
        for m in range(6):
            blocks.append(sp.diags(scal[m]) @ bases[a])
    # Squareness: EC0Y (Y about Z), EB0Z (Z about Y), EA0Z (Z about X).
    sq = np.stack([-n[:, 0] * x[:, 1], n[:, 0] * x[:, 2], -n[:, 1] * x[:, 2]], axis=1)
    blocks.append(sp.csr_matrix(sq))
    return sp.hstack(blocks).tocsr()


def error(layout, u, x, p, bases):
    """Small-angle volumetric error e(X, p) for coefficients u (patent eq. 4)."""
    e = np.zeros_like(x)
    for a in range(3):
        h = layout.lever(a, x, p)
        t = np.stack([bases[a] @ u[layout.offset(a, m):layout.offset(a, m) + layout.nc] for m in range(3)], axis=1)
        r = np.stack([bases[a] @ u[layout.offset(a, m):layout.offset(a, m) + layout.nc] for m in range(3, 6)], axis=1)
        e += t + np.cross(r, h)
    s = u[-3:]
    e[:, 0] += -s[0] * x[:, 1] + s[1] * x[:, 2]
    e[:, 1] += -s[2] * x[:, 2]
    return e


def constraints(layout):
    """The patent's gauge: mean of each function, mean slope of each straightness function."""
    gx, gw = np.polynomial.legendre.leggauss(8)
    rows = []
    straight = []
    for a in range(3):
        lo, hi = layout.travel[a]
        edges = np.linspace(lo, hi, layout.m * 4 + 1)
        q = np.concatenate([(e0 + e1) / 2 + (e1 - e0) / 2 * gx for e0, e1 in zip(edges[:-1], edges[1:])])
        w = np.concatenate([(e1 - e0) / 2 * gw for e0, e1 in zip(edges[:-1], edges[1:])])
        b = BSpline.design_matrix(q, layout.knots[a], 3).toarray()
        mean = (w[:, None] * b).sum(axis=0) / (hi - lo)
        slope = (w[:, None] * (q - (lo + hi) / 2)[:, None] * b).sum(axis=0) / ((hi - lo) ** 3 / 12)
        for m in range(6):
            r = np.zeros(layout.n)
            r[layout.offset(a, m):layout.offset(a, m) + layout.nc] = mean
            rows.append(r)
            if m < 3 and m != a:
                r = np.zeros(layout.n)
                r[layout.offset(a, m):layout.offset(a, m) + layout.nc] = slope
                straight.append(r)
    return np.array(rows + straight)


def solve(layout, x, p, l, group, iterations=3):
    bases = [layout.basis(a, x[:, a]) for a in range(3)]
    ng = group.max() + 1
    counts = np.bincount(group, minlength=ng).astype(float)
    z = sla.null_space(constraints(layout))
    u = np.zeros(layout.n)
    onehot = sp.csr_matrix((np.ones(len(group)), (group, np.arange(len(group)))), shape=(ng, len(group)))
    for _ in range(iterations):
        # Beam directions: principal axis of the actual points of each beam.
        actual = x + p + error(layout, u, x, p, bases)
        n = np.empty_like(x)
        for g in range(ng):
            idx = group == g
            pts = actual[idx] - actual[idx].mean(axis=0)
            d = np.linalg.svd(pts, full_matrices=False)[2][0]
            if np.dot(pts @ d, l[idx] - l[idx].mean()) < 0:
                d = -d
            n[idx] = d
        a = design(layout, x, p, n, bases)
        r = l - np.einsum("ij,ij->i", n, actual)
        # Barycentre reduction: N = A^T A - sum_g s_g s_g^T / n_g, b = A^T r - s_g rbar_g.
        s = (onehot @ a).toarray()
        rs = onehot @ r
        nmat = (a.T @ a).toarray() - s.T @ (s / counts[:, None])
        b = a.T @ r - s.T @ (rs / counts)
        red = z.T @ nmat @ z
        y = sla.cho_solve(sla.cho_factor(red), z.T @ b)
        u = u + z @ y
    return u, bases


def load_model(path, layout):
    m = json.load(open(path))
    u = np.concatenate([np.array(f["coefficients"]) for f in m["functions"]] + [np.array([v for _, v in m["squareness"]])])
    assert len(u) == layout.n, "the model's layout differs from the peer's"
    return u


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("campaign")
    ap.add_argument("--topology", default="FXYZ")
    ap.add_argument("--travel", nargs=3, default=["0,1", "0,0.8", "-0.6,0"])
    ap.add_argument("--intervals", type=int, default=12)
    ap.add_argument("--compare", help="volcal model.json to compare with")
    ap.add_argument("--json", help="write the peer's result here")
    args = ap.parse_args()
    travel = [tuple(float(v) for v in t.split(",")) for t in args.travel]
    layout = Layout(args.topology, travel, args.intervals)
    x, p, l, group = read_campaign(args.campaign)
    t0 = time.perf_counter()
    u, _ = solve(layout, x, p, l, group)
    dt = time.perf_counter() - t0
    result = {"readings": int(len(l)), "parameters": layout.n, "solve_s": dt}
    print(f"peer (NumPy {np.__version__}, SciPy {__import__('scipy').__version__}): {len(l)} readings, {layout.n} parameters, solve {dt * 1e3:.1f} ms")
    if args.compare:
        v = load_model(args.compare, layout)
        # Volumetric difference between the two models on a grid, for the campaign's offsets.
        g = [np.linspace(lo, hi, 6) for lo, hi in travel]
        grid = np.array(np.meshgrid(*g, indexing="ij")).reshape(3, -1).T
        offs = np.unique(p, axis=0)
        diffs = []
        for off in offs:
            pp = np.tile(off, (len(grid), 1))
            bases = [layout.basis(a, grid[:, a]) for a in range(3)]
            d = error(layout, u, grid, pp, bases) - error(layout, v, grid, pp, bases)
            diffs.append(np.linalg.norm(d, axis=1))
        diffs = np.concatenate(diffs)
        result["max_volumetric_difference_m"] = float(diffs.max())
        result["rms_volumetric_difference_m"] = float(np.sqrt((diffs ** 2).mean()))
        print(f"volumetric difference from {args.compare}: max {diffs.max() * 1e9:.2f} nm, RMS {np.sqrt((diffs ** 2).mean()) * 1e9:.2f} nm")
    if args.json:
        json.dump(result, open(args.json, "w"), indent=2)


if __name__ == "__main__":
    main()
