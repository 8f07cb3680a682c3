#!/usr/bin/env python3
"""Honesty of `volcal`'s validation lines against a simulated interferometer (a study, not a test).

For each seed: `volcal simulate` a campaign on a machine file (its simulation section is the
truth), `volcal solve` it with the two-line machine file (topology and travel: `representation:
auto`) or with the machine file itself (`--explicit`), then `volcal validate` the four body
diagonals and the X, Y and Z lines through the centre (21 targets each) against the simulated
interferometer (`--truth`). z is the difference over the combined standard uncertainty
(prediction and interferometer) at the targets the model determines, each line's start left out
(the deviations are referred to it).

Plans: `tracer:N` (the paper's tracer plan without its stations, the plan's default four for the
travel, N stops per edge) or `beams:S,D,P` (S stations x D beams x P points, the patent's three
probe offsets).

    python3 tests/py/validation_lines_study.py --volcal target/release/volcal \
        --machine launch_configs/machines/demo_cmm.yaml --plan beams:3,25,100 --seeds 1-10

Prints RMS difference, RMS stated standard uncertainty, RMS z, the share beyond 3 sigma, the
largest |z|, and RMS z by tenth of the line's length. docs/representation-auto.md ("Too few
positions to smooth", "The patent's plan over the simulator's own machines") has its figures.
"""

import argparse
import csv
import math
import os
import subprocess
import sys
import tempfile

import yaml


def plan_text(plan, travel):
    kind, _, arg = plan.partition(":")
    if kind == "tracer":
        n = int(arg)
        step = [(travel[a][1] - travel[a][0]) / (n - 1) for a in "xyz"]
        return (
            "method: tracer\nprobe_offsets: [[0.0, 0.0, 0.0]]\n"
            f"path_step_m: [{step[0]!r}, {step[1]!r}, {step[2]!r}]\n"
            "acquisition: {mode: static, speed_mps: 0.05, dwell_s: 5.0}\n"
        )
    if kind == "beams":
        s, d, p = (int(v) for v in arg.split(","))
        return (
            f"n_stations: {s}\ndirections_per_station: {d}\npoints_per_beam: {p}\n"
            "probe_offsets:\n  - [0.12, 0.0, -0.10]\n  - [0.0, 0.12, -0.10]\n  - [0.0, 0.0, -0.25]\n"
            "acquisition: {mode: static, speed_mps: 0.05, dwell_s: 1.0}\n"
        )
    sys.exit(f"unknown plan {plan!r} (tracer:N or beams:S,D,P)")


def seeds(text):
    a, _, b = text.partition("-")
    return range(int(a), int(b or a) + 1)


def run(volcal, args, check=True):
    r = subprocess.run([volcal, *args], capture_output=True, text=True)
    if check and r.returncode != 0:
        sys.exit(f"volcal {' '.join(args)} exited {r.returncode}:\n{r.stderr}")
    return r.returncode


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--volcal", required=True)
    ap.add_argument("--machine", required=True)
    ap.add_argument("--plan", required=True)
    ap.add_argument("--seeds", default="1-10")
    ap.add_argument("--explicit", action="store_true", help="solve with the machine file itself")
    ap.add_argument("--workdir", default=None)
    a = ap.parse_args()
    machine = yaml.safe_load(open(a.machine))
    travel = machine["travel"]
    work = a.workdir or tempfile.mkdtemp(prefix="volcal-lines-")
    two_line = os.path.join(work, "two_line.yaml")
    with open(two_line, "w") as f:
        f.write(f"topology: {machine['topology']}\n")
        f.write("travel: {x: %s, y: %s, z: %s}\n" % (travel["x"], travel["y"], travel["z"]))
    plan = os.path.join(work, "plan.yaml")
    with open(plan, "w") as f:
        f.write(plan_text(a.plan, travel))
    zs, diffs, us, bins, total, codes = [], [], [], {}, 0, {}
    for seed in seeds(a.seeds):
        d = os.path.join(work, f"s{seed}")
        os.makedirs(d, exist_ok=True)
        c, t, m = (os.path.join(d, n) for n in ("c.csv", "truth.json", "m.json"))
        run(a.volcal, ["simulate", "--machine", a.machine, "--plan", plan, "--seed", str(seed), "--out", c, "--truth", t])
        code = run(a.volcal, ["solve", c, "--machine", a.machine if a.explicit else two_line, "--out", m], check=False)
        codes[code] = codes.get(code, 0) + 1
        if not os.path.exists(m):
            continue
        for line in (["--diagonals"], ["--axis", "x"], ["--axis", "y"], ["--axis", "z"]):
            out = os.path.join(d, f"v{line[-1]}.csv")
            run(a.volcal, ["validate", m, *line, "--truth", t, "--machine", a.machine, "--points", "21",
                           "--seed", str(seed), "--out", out])
            rows = list(csv.DictReader(open(out)))
            length = {}
            for r in rows:
                length[r["line"]] = max(length.get(r["line"], 0.0), float(r["s_m"]))
            for r in rows:
                if float(r["s_m"]) == 0.0:
                    continue
                total += 1
                if r["predicted_m"] == "":
                    continue
                u = math.hypot(float(r["u_predicted_m"]), float(r["u_measured_m"]))
                z = float(r["difference_m"]) / u
                zs.append(z)
                diffs.append(float(r["difference_m"]))
                us.append(float(r["u_predicted_m"]))
                bins.setdefault(round(10 * float(r["s_m"]) / length[r["line"]]), []).append(z)
    rms = lambda v: math.sqrt(sum(x * x for x in v) / len(v)) if v else float("nan")
    print(f"{a.machine} {a.plan} seeds {a.seeds} {'explicit' if a.explicit else 'auto'}; solve exit codes {codes}")
    print(f"targets {total}, determined {len(zs)}")
    if zs:
        beyond = sum(abs(z) > 3 for z in zs)
        print(f"RMS difference {rms(diffs) * 1e6:.3f} um, RMS stated u {rms(us) * 1e6:.3f} um, RMS z {rms(zs):.2f}, "
              f"beyond 3 sigma {beyond} ({100 * beyond / len(zs):.2f} %), largest |z| {max(map(abs, zs)):.2f}")
        print("RMS z by tenth of the line: " + " ".join(f"{b}:{rms(v):.2f}" for b, v in sorted(bins.items())))


if __name__ == "__main__":
    main()
