#!/usr/bin/env python3
"""Independent check of a tracer solve: recompute every range from the model file.

Usage: check_tracer_model.py campaign.csv model.json [truth.json]

Reads the campaign (volcal CSV) and the model (volcal JSON), evaluates the rigid-body error
model from the file's coefficients with its own code (piecewise-linear tables, small-angle
rotations about the lever arms of the axis stacking, explicit squareness), predicts every range
reading |Q_i - (X + p + e)| from the model's station positions, removes each path's dead path
(mean residual) and prints, per station, the residual RMS next to the RMS the model file
reports. With a truth file, does the same with the true model and stations. Exits non-zero when
the recomputed and reported RMS disagree by more than 5 % or the residuals exceed 1 um.

Only the Python standard library is used.
"""
import csv
import json
import math
import sys

AXES = "XYZ"


def table_value(coeffs, lo, hi, q):
    n = len(coeffs)
    u = min(max((q - lo) / (hi - lo), 0.0), 1.0) * (n - 1)
    i = min(int(math.floor(u)), n - 2)
    t = u - i
    return coeffs[i] * (1.0 - t) + coeffs[i + 1] * t


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


class Model:
    def __init__(self, m):
        self.chain = [c for c in m["topology"] if c in AXES]
        self.travel = m["travel"]
        self.f = {}
        for fn in m["functions"]:
            rep = fn["representation"]
            if rep["kind"] != "table":
                raise SystemExit(f"this checker evaluates table representations only, got {rep}")
            self.f[fn["name"]] = fn["coefficients"]
        self.sq = dict((k, v) for k, v in m["squareness"])

    def value(self, name, axis, q):
        lo, hi = self.travel[AXES.index(axis)]
        return table_value(self.f[name], lo, hi, q)

    def error(self, x, p):
        e = [0.0, 0.0, 0.0]
        for k, a in enumerate(self.chain):
            q = x[AXES.index(a)]
            t = [self.value(f"E{c}{a}", a, q) for c in AXES]
            r = [self.value(f"E{c}{a}", a, q) for c in "ABC"]
            h = list(p)
            for b in self.chain[k + 1:]:
                h[AXES.index(b)] += x[AXES.index(b)]
            rh = cross(r, h)
            for i in range(3):
                e[i] += t[i] + rh[i]
        # EC0Y: Y rotated about Z; EB0Z: Z about Y; EA0Z: Z about X (error per metre: about x axis).
        e[0] += -x[1] * self.sq["EC0Y"]
        e[0] += x[2] * self.sq["EB0Z"]
        e[1] += -x[2] * self.sq["EA0Z"]
        return e


def read_campaign(path):
    rows = []
    with open(path) as fh:
        lines = [l for l in fh if not l.startswith("#") and l.strip()]
    for r in csv.DictReader(lines):
        if r["kind"] != "range":
            continue
        rows.append((int(r["station"]), int(r["beam"]), float(r["l_m"]),
                     [float(r["x_m"]), float(r["y_m"]), float(r["z_m"])],
                     [float(r["px_m"]), float(r["py_m"]), float(r["pz_m"])]))
    return rows


def residual_rms(model, stations, rows):
    groups = {}
    for st, line, l, x, p in rows:
        e = model.error(x, p)
        pa = [x[i] + p[i] + e[i] for i in range(3)]
        q = stations[st]
        rng = math.sqrt(sum((pa[i] - q[i]) ** 2 for i in range(3)))
        groups.setdefault((st, line), []).append(l - rng)
    out = {}
    for key, r in groups.items():
        m = sum(r) / len(r)
        out[key] = math.sqrt(sum((v - m) ** 2 for v in r) / len(r))
    return out


def main():
    campaign, model_path = sys.argv[1], sys.argv[2]
    rows = read_campaign(campaign)
    m = json.load(open(model_path))
    model = Model(m)
    stations = {s["station"]: s["position_m"] for s in m["stations"]}
    got = residual_rms(model, stations, rows)
    reported = {(l["station"], l["line"]): l["rms_m"] for l in m["residuals"]["lines"] if l["kind"] == "range"}
    ok = True
    for key in sorted(got):
        g, r = got[key], reported.get(key, float("nan"))
        agree = abs(g - r) <= 0.05 * r and g < 1e-6
        ok &= agree
        print(f"model: station {key[0]} path {key[1]}: recomputed RMS {g * 1e6:.4f} um, reported {r * 1e6:.4f} um {'ok' if agree else 'MISMATCH'}")
    if len(sys.argv) > 3:
        t = json.load(open(sys.argv[3]))
        truth = Model(t["model"])
        tst = {s: pos for s, pos in t["stations"]}
        for key, g in sorted(residual_rms(truth, tst, rows).items()):
            agree = g < 1e-6
            ok &= agree
            print(f"truth: station {key[0]} path {key[1]}: residual RMS {g * 1e6:.4f} um {'ok' if agree else 'MISMATCH'}")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
