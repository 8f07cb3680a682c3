#!/usr/bin/env python3
"""How well the measured long waves of a machine's face-diagonal pairs tell the size of the
long wave that fixed beams leave open (docs/representation-auto.md, "Nine measured long waves").

A study of the independent simulator's truth, not a check of volcal's output: for each of the
three face pairs (EXY and EYX, EXZ and EZX, EYZ and EZY) of machines drawn by
`independent_campaign.Machine`, the Legendre coefficients over each travel of the pair's
lever-weighted sum `s = (L_P EPQ + L_Q EQP) / 2` (which the face diagonals measure) and
difference `d` (whose odd part they leave open). It prints, per odd degree `k` (3 and 5) and per
way of taking a scale from what is measured, how often the open `d_k` lies beyond 2 and 3 times
that scale and the mean and median of `(d_k / scale)^2` (1 where the scale is the right size):

- `sums`: the mean square over the three pairs of `s_k` (volcal's scale at stop 67);
- `sums and differences' even neighbours`: the mean square over the three pairs of `s_k`,
  `d_(k-1)` and `d_(k+1)` (volcal's since stop 68, `model/src/open_pairs.rs`).

Usage: open_long_wave_probe.py LO,HI FIRST_SEED LAST_SEED   (length scales, fractions of the travel)
"""
import sys

import numpy as np
from numpy.polynomial import legendre

from independent_campaign import Machine

TRAVEL = [(0.0, 1.0), (0.0, 0.8), (-0.6, 0.0)]
AXES = "XYZ"
NODES, WEIGHTS = legendre.leggauss(60)


def coefficients(f, lo, hi, kmax=7):
    """Legendre coefficients 0..kmax of f over [lo, hi] (mapped onto -1 to 1)."""
    v = f(lo + (NODES + 1.0) * 0.5 * (hi - lo))
    return np.array([(2 * k + 1) / 2 * np.sum(WEIGHTS * legendre.legval(NODES, [0] * k + [1]) * v) for k in range(kmax + 1)])


def pairs(machine):
    """(sum, difference) coefficients of each face pair, lever-weighted."""
    out = []
    for p, q in [("X", "Y"), ("X", "Z"), ("Y", "Z")]:
        (p_lo, p_hi), (q_lo, q_hi) = TRAVEL[AXES.index(p)], TRAVEL[AXES.index(q)]
        a = coefficients(machine.f[f"E{p}{q}"], q_lo, q_hi) * (p_hi - p_lo)
        b = coefficients(machine.f[f"E{q}{p}"], p_lo, p_hi) * (q_hi - q_lo)
        out.append(((a + b) / 2, (a - b) / 2))
    return out


def main():
    length_scale = tuple(float(v) for v in sys.argv[1].split(","))
    seeds = range(int(sys.argv[2]), int(sys.argv[3]) + 1)
    drawn = [pairs(Machine("FXYZ", TRAVEL, s, 1.0, length_scale)) for s in seeds]
    s = np.array([[p[0] for p in m] for m in drawn])  # seeds x pairs x degrees
    d = np.array([[p[1] for p in m] for m in drawn])
    print(f"length scales {length_scale}, seeds {seeds.start}-{seeds.stop - 1}, {d.shape[0] * d.shape[1]} pairs")
    for k in (3, 5):
        ways = {
            "sums": s[:, :, k] ** 2,
            "sums and differences' even neighbours": np.concatenate([s[:, :, k] ** 2, d[:, :, k - 1] ** 2, d[:, :, k + 1] ** 2], axis=1),
        }
        for name, measured in ways.items():
            scale2 = measured.mean(axis=1, keepdims=True)
            z = d[:, :, k] / np.sqrt(scale2)
            print(
                f"  degree {k}, {name:38s}: beyond 3 {np.mean(np.abs(z) > 3) * 100:4.1f} %, beyond 2 "
                f"{np.mean(np.abs(z) > 2) * 100:4.1f} %, mean z^2 {np.mean(z ** 2):5.2f}, median {np.median(z ** 2):4.2f}, "
                f"largest |z| {np.max(np.abs(z)):4.1f}"
            )


if __name__ == "__main__":
    main()
