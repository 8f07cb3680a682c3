"""Independent check of volcal's Rerun recordings, with the official Rerun SDK.

usage: check_rrd.py SOLVE.rrd CAMPAIGN.csv [--series ROOT]... [--entity PATH]... [--band-open PATH]...
                                             a recording of `volcal solve --rerun`
       check_rrd.py --live LIVE.rrd BAG [--entity PATH]...
                                             a recording of the viz node watching the campaign
                                             recorded in the rosbag2 BAG

`--series ROOT`: one more per-reading series per line is expected under ROOT (e.g. the
residuals before and after a diagnosis, an effect's signature); `--entity PATH`: one more
entity path is expected (e.g. the diagnosis report); `--band-open PATH`: the error function at
PATH is drawn everywhere but has no band (NaN) where the model does not determine it and a finite
band elsewhere (a function determined only at its measured positions).

Reads the campaign itself, without volcal (the CSV with the standard csv module; the bag's
/campaign/pairs with rosbags), to know which stations, lines and readings there are, then
checks that the recording holds the entity paths the views rely on, one residual per reading
on the expected timelines, and a default blueprint.
"""

import csv
import sys
from collections import Counter

import rerun as rr
from rerun.experimental import RrdReader


def campaign_lines(campaign):
    """Readings per (station, "beams"|"paths", line) of a campaign CSV."""
    readings = Counter()
    with open(campaign, newline="") as f:
        rows = csv.DictReader(line for line in f if not line.startswith("#"))
        for row in rows:
            kind = {"beam": "beams", "range": "paths"}[row["kind"]]
            readings[(row["station"], kind, row["beam"])] += 1
    return readings


def bag_lines(bag):
    """Readings per (station, "beams"|"paths", line) of a bag's /campaign/pairs (rosbags)."""
    from pathlib import Path

    from rosbags.highlevel import AnyReader

    readings = Counter()
    with AnyReader([Path(bag)]) as reader:
        conns = [c for c in reader.connections if c.topic == "/campaign/pairs"]
        for conn, _, raw in reader.messages(connections=conns):
            m = reader.deserialize(raw, conn.msgtype)
            kind = "beams" if m.kind == 0 else "paths"
            readings[(str(m.station), kind, str(m.line))] += 1
    return readings


class Recording:
    """Rows, timelines and static-ness per entity path of one .rrd file."""

    def __init__(self, rrd, sampled=()):
        """`sampled`: entity paths whose scalar samples are kept (`samples_at`)."""
        reader = RrdReader(rrd)
        self.recordings = reader.recordings()
        self.blueprints = reader.blueprints()
        self.rows_at = Counter()
        self.timelines_at = {}
        self.static_at = set()
        self.samples_at = {path: [] for path in sampled}
        for chunk in reader.stream().to_chunks():
            path = chunk.entity_path.strip("/")
            self.rows_at[path] += chunk.num_rows
            self.timelines_at.setdefault(path, set()).update(chunk.timeline_names)
            if chunk.is_static:
                self.static_at.add(path)
            elif path in self.samples_at:
                batch = chunk.to_record_batch()
                column = batch.column(batch.schema.get_field_index("Scalars:scalars"))
                self.samples_at[path].extend(tuple(row) for row in column.to_pylist())
        self.paths = set(self.rows_at)

    def problems(self):
        out = []
        if len(self.recordings) != 1:
            out.append(f"expected one recording, found {len(self.recordings)}")
        if not self.blueprints:
            out.append("no blueprint (default layout) in the recording")
        return out

    def series_rows(self, path):
        """Rows of a series and of its segments (`path/segment_<k>`), without the static style row."""
        total = 0
        for p in self.paths:
            if p == path or p.startswith(path + "/segment_"):
                total += self.rows_at[p] - (1 if p in self.static_at else 0)
        return total


def check_series(rec, res, n, timelines, problems):
    """One scalar row per reading on `res` (and its segments), on the given timelines."""
    rows = rec.series_rows(res)
    if res in rec.rows_at and rows != n:
        problems.append(f"{res}: {rows} rows for {n} readings")
    if res in rec.timelines_at and not timelines <= rec.timelines_at[res]:
        problems.append(f"{res}: timelines {sorted(rec.timelines_at[res])}, expected {sorted(timelines)}")


def check_solve(rec, readings, series_roots=("fit/residuals",), extra_entities=()):
    problems = []
    expected = {"machine/volume", "machine/axes", "fit/summary", "map/volumetric", "map/volumetric/max", "map/volumetric/scale"}
    for (station, kind, line), n in readings.items():
        expected |= {f"stations/{station}", f"stations/{station}/{kind}/{line}", f"fit/residual_rms/stations/{station}"}
        for root in series_roots:
            res = f"{root}/stations/{station}/{kind}/{line}"
            expected.add(res)
            check_series(rec, res, n, {"campaign_time", "position_mm", "beam_index"}, problems)
    expected |= set(extra_entities)
    for axis in "XYZ":
        for comp in "XYZ":
            for kind, letter in (("translation", comp), ("rotation", {"X": "A", "Y": "B", "Z": "C"}[comp])):
                expected.add(f"functions/{axis}/{kind}/E{letter}{axis}")
    for sq, axis in (("EC0Y", "Y"), ("EB0Z", "Z"), ("EA0Z", "Z")):
        expected.add(f"functions/{axis}/rotation/{sq}")
    return expected, problems


def check_band_open(rec, path, problems):
    """The function at `path` (value, value + U, value - U per sample) has a value at every
    sample, and a band at some but not all."""
    samples = rec.samples_at[path]
    nan = lambda v: v != v
    if not samples or any(len(s) != 3 or nan(s[0]) for s in samples):
        problems.append(f"{path}: expected (value, upper, lower) with a value at every sample")
        return
    open_ = sum(1 for s in samples if nan(s[1]) and nan(s[2]))
    banded = sum(1 for s in samples if not nan(s[1]) and not nan(s[2]) and s[1] >= s[0] >= s[2])
    print(f"{path}: {len(samples)} samples, {open_} without a band, {banded} with one")
    if open_ == 0 or banded == 0 or open_ + banded != len(samples):
        problems.append(f"{path}: {open_} samples without a band and {banded} with one of {len(samples)}")


def check_live(rec, readings):
    problems = []
    expected = {
        "machine/volume",
        "machine/axes",
        "live/status",
        "live/current_point",
        "live/deflector",
        "live/running_rms",
    }
    for (station, kind, line), n in readings.items():
        expected |= {
            f"stations/{station}",
            f"stations/{station}/{kind}/{line}",
            f"stations/{station}/{kind}/{line}/indicated",
        }
        if kind == "beams":
            # Commanded by the deflector; the live line fits are those of beams.
            expected |= {f"stations/{station}/beams/{line}/commanded", f"live/residual_rms/stations/{station}"}
            res = f"live/residuals/stations/{station}/beams/{line}"
            expected.add(res)
            check_series(rec, res, n, {"campaign_time", "beam_index"}, problems)
    for p in ("live/current_point", "live/deflector", "live/running_rms"):
        if p in rec.timelines_at and "campaign_time" not in rec.timelines_at[p]:
            problems.append(f"{p}: not on the campaign_time timeline")
    return expected, problems


def main(argv):
    live = argv[:1] == ["--live"]
    if live:
        argv = argv[1:]
    if len(argv) < 2 or len(argv) % 2 != 0:
        sys.exit(__doc__)
    rrd, campaign = argv[:2]
    series_roots, extra_entities, band_open = ["fit/residuals"], set(), []
    rest = argv[2:]
    while rest:
        flag, value, rest = rest[0], rest[1], rest[2:]
        if flag not in ("--series", "--entity", "--band-open") or (live and flag != "--entity"):
            sys.exit(__doc__)
        {"--series": series_roots.append, "--entity": extra_entities.add, "--band-open": band_open.append}[flag](value)
    readings = bag_lines(campaign) if live else campaign_lines(campaign)
    if not readings:
        sys.exit(f"FAIL: no readings in {campaign}")
    rec = Recording(rrd, band_open)
    if live:
        expected, problems = check_live(rec, readings)
        expected |= extra_entities
    else:
        expected, problems = check_solve(rec, readings, series_roots, extra_entities)
    problems = rec.problems() + problems
    for path in band_open:
        check_band_open(rec, path, problems)
    missing = sorted(expected - rec.paths)
    if missing:
        problems.append(f"{len(missing)} expected entity paths missing, e.g. {missing[:8]}")
    print(
        f"rerun-sdk {rr.__version__}: {len(rec.paths)} entity paths, {len(expected)} expected, "
        f"{sum(readings.values())} readings on {len(readings)} lines, {len(rec.blueprints)} blueprint(s)"
    )
    if problems:
        print("\n".join("FAIL: " + p for p in problems))
        sys.exit(1)
    print("OK")


if __name__ == "__main__":
    main(sys.argv[1:])
