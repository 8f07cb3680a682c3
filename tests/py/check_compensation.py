"""Independent reader of volcal's compensation exports (standard library only).

LinuxCNC's rule for a COMP_FILE: each line three numbers `nominal forward reverse`, read until
the first line that is not three numbers (silently: so every line must be three numbers, or the
rest of the table is lost), at most 256 lines, nominal ascending. COMP_FILE_TYPE 1: the offset
added to the command is the column; TYPE 0: offset = nominal - column.

usage:
  check_compensation.py points DIR X,Y,Z OUT.csv        points (metres) of every node of x/y/z.comp
  check_compensation.py linuxcnc DIR TYPE PRED.csv      tables against `volcal predict` at those points
  check_compensation.py grid DIR PRED.csv               grid.csv against `volcal predict` at its nodes
  check_compensation.py gridpoints DIR OUT.csv          the nodes of grid.csv (metres)
"""

import csv
import json
import sys
from pathlib import Path


def read_comp(path: Path):
    rows = []
    lines = [l for l in path.read_text().splitlines()]
    for n, line in enumerate(lines, 1):
        f = line.split()
        try:
            assert len(f) == 3
            rows.append(tuple(float(v) for v in f))
        except (AssertionError, ValueError):
            raise SystemExit(f'{path}:{n}: not three numbers; LinuxCNC would drop this line and the rest: {line!r}')
    if not 2 <= len(rows) <= 256:
        raise SystemExit(f'{path}: {len(rows)} lines (LinuxCNC reads 2..256)')
    if any(b[0] <= a[0] for a, b in zip(rows, rows[1:])):
        raise SystemExit(f'{path}: nominal positions not strictly ascending')
    return rows


def main():
    cmd = sys.argv[1]
    d = Path(sys.argv[2])
    if cmd == 'points':
        point = [float(v) for v in sys.argv[3].split(',')]
        with open(sys.argv[4], 'w', newline='') as f:
            w = csv.writer(f)
            w.writerow(['x_m', 'y_m', 'z_m'])
            for a, name in enumerate('xyz'):
                for nominal, _, _ in read_comp(d / f'{name}.comp'):
                    x = list(point)
                    x[a] = nominal / 1000.0
                    w.writerow(x)
    elif cmd == 'linuxcnc':
        kind = int(sys.argv[3])
        pred = list(csv.DictReader(open(sys.argv[4])))
        i = 0
        worst = 0.0
        for a, name in enumerate('xyz'):
            rows = read_comp(d / f'{name}.comp')
            offsets = []
            for nominal, fwd, rev in rows:
                if fwd != rev:
                    raise SystemExit(f'{name}.comp: forward {fwd} != reverse {rev} (the model has no reversal error)')
                offset_mm = fwd if kind == 1 else nominal - fwd
                offsets.append(offset_mm)
                e_mm = float(pred[i]['e' + name + '_m']) * 1000.0
                if abs(float(pred[i][name + '_m']) * 1000.0 - nominal) > 1e-6:
                    raise SystemExit(f'{name}.comp: row order differs from the predicted points')
                worst = max(worst, abs(offset_mm + e_mm))
                i += 1
            print(f'{name}.comp: {len(rows)} lines, type {kind}, offsets {min(offsets) * 1e3:.3f} .. {max(offsets) * 1e3:.3f} um')
        if worst > 2e-8:
            raise SystemExit(f'offset differs from minus the predicted error by {worst} mm')
        print(f'every node: offset = -(predicted error along its axis) to {worst:.1e} mm ok')
    elif cmd == 'gridpoints':
        with open(sys.argv[3], 'w', newline='') as f:
            w = csv.writer(f)
            w.writerow(['x_m', 'y_m', 'z_m'])
            for r in csv.DictReader(open(d / 'grid.csv')):
                w.writerow([float(r['x_mm']) / 1000.0, float(r['y_mm']) / 1000.0, float(r['z_mm']) / 1000.0])
    elif cmd == 'grid':
        rows = list(csv.DictReader(open(d / 'grid.csv')))
        pred = list(csv.DictReader(open(sys.argv[3])))
        assert len(rows) == len(pred), (len(rows), len(pred))
        worst = max(
            max(abs(float(r['e' + c + '_um']) - float(p['e' + c + '_m']) * 1e6) for c in 'xyz') for r, p in zip(rows, pred)
        )
        worst_u = max(abs(float(r['u95_um']) - float(p['u95_m']) * 1e6) for r, p in zip(rows, pred))
        j = json.loads((d / 'grid.json').read_text())
        n = len(j['x_mm']) * len(j['y_mm']) * len(j['z_mm'])
        assert n == len(rows) == len(j['error_um']) == len(j['u95_um']), 'grid.json disagrees with grid.csv'
        if worst > 1e-6 or worst_u > 1e-6:
            raise SystemExit(f'grid differs from volcal predict by {worst} um (U95 {worst_u} um)')
        print(f'grid.csv: {len(rows)} nodes, error and U95 equal to volcal predict to {max(worst, worst_u):.1e} um ok')
    else:
        raise SystemExit(__doc__)


if __name__ == '__main__':
    main()
