"""Counts the endpoints that the rclpy cell never discovered, or discovered late, in the campaigns
of tests/stress/endpoint_announcements.sh (README, "Endpoint announcements that Fast DDS loses").

    python3 tests/py/endpoint_losses.py OUT [LATE_S]

A campaign directory is LANE_RUN_ARM; ARM is the position of the `volcal` binary on the
script's command line. Its endpoints.csv says when the cell's discovery first knew each endpoint
(our nodes' and its own). Expected: the endpoints of our nodes that most campaigns show (by kind
and topic). Missing: expected but never discovered. Late: discovered more than LATE_S (0.5 s)
after the first endpoint of its participant (the node announces all its endpoints at start-up;
one known that much later was lost and announced again).
"""

import collections
import csv
import glob
import os
import sys


def ours(rows):
    return [r for r in rows if not r["node"].endswith("gantry_cell")]


def main():
    out = sys.argv[1]
    late_s = float(sys.argv[2]) if len(sys.argv) > 2 else 0.5
    runs = []
    for d in sorted(glob.glob(os.path.join(out, "*_*_*"))):
        log = os.path.join(d, "launch.log")
        eps = os.path.join(d, "endpoints.csv")
        if not (os.path.exists(log) and os.path.exists(eps)):
            continue
        if "[launch] started sequencer" not in open(log).read():
            continue  # the campaign did not start
        rows = ours(list(csv.DictReader(open(eps))))
        runs.append((os.path.basename(d), d.rsplit("_", 1)[1], rows))
    if not runs:
        sys.exit(f"no campaign in {out}")
    multiset = lambda rows: frozenset(collections.Counter((r["kind"], r["topic"]) for r in rows).items())
    expected = collections.Counter(dict(collections.Counter(multiset(r) for _, _, r in runs).most_common(1)[0][0]))
    print(f"expected: {sum(expected.values())} endpoints of our nodes per campaign")
    for arm in sorted({a for _, a, _ in runs}):
        mine = [(n, r) for n, a, r in runs if a == arm]
        missing, late, delays = collections.Counter(), collections.Counter(), []
        runs_missing = runs_late = 0
        for name, rows in mine:
            first = collections.defaultdict(lambda: float("inf"))
            for r in rows:
                first[r["gid"][:24]] = min(first[r["gid"][:24]], float(r["t_s"]))
            m = expected - collections.Counter((r["kind"], r["topic"]) for r in rows)
            lt = [(r, float(r["t_s"]) - first[r["gid"][:24]]) for r in rows if float(r["t_s"]) - first[r["gid"][:24]] > late_s]
            runs_missing += bool(m)
            runs_late += bool(lt)
            missing.update({f"{k} {t}": n for (k, t), n in m.items()})
            late.update(f"{r['kind']} {r['topic']}" for r, _ in lt)
            delays += [d for _, d in lt]
        print(f"arm {arm}: {len(mine)} campaigns")
        print(f"  never discovered: {sum(missing.values())} endpoints in {runs_missing} campaigns {dict(missing.most_common())}")
        print(f"  discovered late:  {sum(late.values())} endpoints in {runs_late} campaigns {dict(late.most_common())}")
        if delays:
            print(f"  late by {min(delays):.2f} to {max(delays):.2f} s (median {sorted(delays)[len(delays) // 2]:.2f} s)")


if __name__ == "__main__":
    main()
