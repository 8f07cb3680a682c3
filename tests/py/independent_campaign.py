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
- The errors compose as ISO 230-1 and patent eq. (7) say: along the chain from workpiece to tool,
  each axis's translation errors plus its rotation errors acting on the lever arm to the tool
  (the coordinates of the axes it carries plus the probe offset), and the squareness errors
  `EC0Y` (Y rotated about Z: x gains -y EC0Y), `EB0Z` (x gains z EB0Z), `EA0Z` (y gains -z EA0Z).
  `e(X, p) = actual reflector position - (X + p)`.
- Fixed beams (`--method beams`): lines through the working volume (axis-parallel lines on a
  3 x 3 grid of each cross-section, and the 18 face diagonals of the mid planes and the faces),
  each read at `--points` positions for each of three probe offsets. A reading is the
  reflector's displacement along the beam from an arbitrary origin per beam:
  `l = n . (X + p + e(X, p) + d) + c + w`, `d` the machine's repeatability (a displacement
  N(0, repeatability) per axis), `w` the interferometer's noise. With `--sparse`, 12 of the
  lines (two axis lines per axis and the mid planes' face diagonals): a plan whose beams leave
  the rolls of the three axes and the squareness EB0Z open in combination.
- Laser tracer (`--method tracer`): 4 stations beside the corners of the volume, at four
  heights; the reflector at
  the tool (zero probe offset) visits the 12 edges of the working cuboid, `--points` stops per
  edge, in one continuous track per station (one dead path per station):
  `l = |X + p + e(X, p) + d - S| + c + w`, with `w` of the tracer's noise model.
- Both (`--method joint`): the 45 beams and the tracer's 4 tracks (`--stops` per edge) on one
  machine, in one campaign.
- Validation lines, none of them a beam of the campaign: three axis lines off the beams' grid,
  the four body diagonals (the paper's Table 4) and two face diagonals, 11 targets each, at the campaign's probe offsets: the
  positioning deviation an interferometer zeroed at the start reads,
  `n . (e(X_s, p) - e(A, p))`, from the true errors (noise-free).

Usage:
    independent_campaign.py --method beams|tracer --topology FXYZ --travel "0,1;0,0.8;-0.6,0" \
        --seed N --points 25 --out DIR

writes DIR/campaign.csv (volcal's campaign CSV) and DIR/validation.json. Noise as volcal's
defaults (interferometer 0.05 um, repeatability 0.2 um, tracer 0.1 um + 0.2 ppm), so that the
two-line machine file states it. Needs NumPy.
"""

import argparse
import json
import os

import numpy as np

AXES = "XYZ"
INTERFEROMETER_M = 0.05e-6
REPEATABILITY_M = 0.2e-6
TRACER_M = 0.1e-6
TRACER_PPM = 0.2


def smooth_draw(rng, lo, hi, amplitude):
    """A squared-exponential Gaussian-process draw on [lo, hi], largest excursion `amplitude`."""
    length = (hi - lo) * rng.uniform(0.15, 0.4)
    m = 400
    omega = rng.normal(0.0, 1.0 / length, m)
    phase = rng.uniform(0.0, 2.0 * np.pi, m)
    weight = rng.normal(0.0, 1.0, m)
    grid = np.linspace(lo, hi, 2001)
    raw = (weight[None, :] * np.cos(np.outer(grid - lo, omega) + phase[None, :])).sum(axis=1)
    scale = amplitude / max(np.max(np.abs(raw - raw.mean())), 1e-30)

    def f(q):
        q = np.asarray(q, dtype=float)
        return scale * (weight * np.cos(np.multiply.outer(q - lo, omega) + phase)).sum(axis=-1)

    return f


class Machine:
    def __init__(self, topology, travel, seed):
        self.chain = [c for c in topology if c in AXES]
        self.travel = travel
        rng = np.random.default_rng(seed)
        self.f = {}
        for a in AXES:
            lo, hi = travel[AXES.index(a)]
            for c in "XYZABC":
                if c in AXES:
                    amp = 10e-6 if c == a else 4e-6
                else:
                    amp = 8e-6
                self.f[f"E{c}{a}"] = smooth_draw(rng, lo, hi, amp)
        self.sq = {s: float(np.clip(rng.normal(0.0, 12.5e-6), -25e-6, 25e-6)) for s in ("EC0Y", "EB0Z", "EA0Z")}

    def error(self, x, p):
        """e(X, p) for arrays x, p of shape (n, 3)."""
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


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--method", choices=["beams", "tracer", "joint"], required=True)
    ap.add_argument("--topology", default="FXYZ")
    ap.add_argument("--travel", default="0,1;0,0.8;-0.6,0", help="lo,hi per axis in metres, X;Y;Z")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--points", type=int, default=25, help="per beam, or stops per edge of the tracer")
    ap.add_argument("--stops", type=int, default=11, help="stops per edge of the tracer in a joint campaign")
    ap.add_argument("--sparse", action="store_true", help="12 beams instead of 45 (--method beams)")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    travel = [tuple(float(v) for v in t.split(",")) for t in a.travel.split(";")]
    machine = Machine(a.topology, travel, a.seed)
    rng = np.random.default_rng(a.seed + 7_000_000)
    rows = []
    val_offsets = []
    if a.method in ("beams", "joint"):
        offsets = [np.array([0.0, 0.0, 0.0]), np.array([0.15, 0.0, -0.1]), np.array([0.0, 0.15, -0.1])]
        beam = 0
        for p in offsets:
            for s, e in beam_lines(travel, a.sparse):
                n = (e - s) / np.linalg.norm(e - s)
                x = s + np.outer(np.linspace(0.0, 1.0, a.points), e - s)
                actual = x + p + machine.error(x, p) + rng.normal(0.0, REPEATABILITY_M, x.shape)
                l = actual @ n + rng.uniform(-0.5, 0.5) + rng.normal(0.0, INTERFEROMETER_M, len(x))
                for xi, li in zip(x, l):
                    rows.append(("beam", 0, beam, li, xi, p))
                beam += 1
        val_offsets = offsets
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
        if not val_offsets:
            val_offsets = [p]
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, "campaign.csv"), "w") as fh:
        fh.write(f"# independent_campaign.py --method {a.method} --topology {a.topology} --seed {a.seed}\n")
        fh.write("kind,station,beam,t_s,l_m,x_m,y_m,z_m,px_m,py_m,pz_m\n")
        for i, (kind, st, b, l, x, p) in enumerate(rows):
            fh.write(f"{kind},{st},{b},{i * 0.5:.1f},{l:.12f},{x[0]:.9f},{x[1]:.9f},{x[2]:.9f},{p[0]:.6f},{p[1]:.6f},{p[2]:.6f}\n")
    lines = []
    for p in val_offsets:
        for name, s, e in validation_lines(travel):
            n = (e - s) / np.linalg.norm(e - s)
            x = s + np.outer(np.linspace(0.0, 1.0, 11), e - s)
            err = machine.error(x, p)
            dev = (err - err[0]) @ n
            lines.append({"name": name, "start": s.tolist(), "end": e.tolist(), "probe": p.tolist(), "deviation_m": dev.tolist()})
    with open(os.path.join(a.out, "validation.json"), "w") as fh:
        json.dump({"method": a.method, "topology": a.topology, "travel": travel, "seed": a.seed, "lines": lines}, fh, indent=1)


if __name__ == "__main__":
    main()
