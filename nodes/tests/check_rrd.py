"""Independent check of a recording from `volcal solve --rerun`, with the official Rerun SDK.

usage: check_rrd.py SOLVE.rrd CAMPAIGN.csv [--series ROOT]... [--entity PATH]...

`--series ROOT`: one more per-reading series per line is expected under ROOT (e.g. the
residuals before and after a diagnosis, an effect's signature); `--entity PATH`: one more
entity path is expected (e.g. the diagnosis report).

Reads the campaign CSV itself (the standard csv module) to know which stations, beams and
readings there are, then checks that the recording holds the entity paths the views rely on,
one residual per reading on the expected timelines, and a default blueprint.
"""

import csv
import sys
from collections import Counter

import rerun as rr
from rerun.experimental import RrdReader

rrd, campaign = sys.argv[1], sys.argv[2]
series_roots, extra_entities = ["fit/residuals"], set()
rest = sys.argv[3:]
while rest:
    flag, value, rest = rest[0], rest[1], rest[2:]
    {"--series": series_roots.append, "--entity": extra_entities.add}[flag](value)

readings = Counter()
with open(campaign, newline="") as f:
    rows = csv.DictReader(line for line in f if not line.startswith("#"))
    for row in rows:
        kind = {"beam": "beams", "range": "paths"}[row["kind"]]
        readings[(row["station"], kind, row["beam"])] += 1

reader = RrdReader(rrd)
recordings = reader.recordings()
blueprints = reader.blueprints()
problems = []
if len(recordings) != 1:
    problems.append(f"expected one recording, found {len(recordings)}")
if not blueprints:
    problems.append("no blueprint (default layout) in the recording")

rows_at = Counter()
timelines_at = {}
static_at = set()
for chunk in reader.stream().to_chunks():
    path = chunk.entity_path.strip("/")
    rows_at[path] += chunk.num_rows
    timelines_at.setdefault(path, set()).update(chunk.timeline_names)
    if chunk.is_static:
        static_at.add(path)
paths = set(rows_at)

expected = {"machine/volume", "machine/axes", "fit/summary", "map/volumetric", "map/volumetric/max", "map/volumetric/scale"}
for (station, kind, line), n in readings.items():
    expected |= {f"stations/{station}", f"stations/{station}/{kind}/{line}", f"fit/residual_rms/stations/{station}"}
    for root in series_roots:
        res = f"{root}/stations/{station}/{kind}/{line}"
        expected.add(res)
        # One scalar row per reading, plus the static series style row.
        if res in rows_at and rows_at[res] - (1 if res in static_at else 0) != n:
            problems.append(f"{res}: {rows_at[res]} rows for {n} readings")
        want = {"campaign_time", "position_mm", "beam_index"}
        if res in timelines_at and not want <= timelines_at[res]:
            problems.append(f"{res}: timelines {sorted(timelines_at[res])}, expected {sorted(want)}")
expected |= extra_entities
for axis in "XYZ":
    for comp in "XYZ":
        for kind, letter in (("translation", comp), ("rotation", {"X": "A", "Y": "B", "Z": "C"}[comp])):
            expected.add(f"functions/{axis}/{kind}/E{letter}{axis}")
for sq, axis in (("EC0Y", "Y"), ("EB0Z", "Z"), ("EA0Z", "Z")):
    expected.add(f"functions/{axis}/rotation/{sq}")

missing = sorted(expected - paths)
if missing:
    problems.append(f"{len(missing)} expected entity paths missing, e.g. {missing[:8]}")

print(
    f"rerun-sdk {rr.__version__}: {len(paths)} entity paths, {len(expected)} expected, "
    f"{sum(readings.values())} readings on {len(readings)} lines, {len(blueprints)} blueprint(s)"
)
if problems:
    print("\n".join("FAIL: " + p for p in problems))
    sys.exit(1)
print("OK")
