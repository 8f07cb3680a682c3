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
  check_compensation.py isgpoints DIR OUT.csv           points whose coordinates are nodes of isg_*.csv
  check_compensation.py isg DIR TOPOLOGY PRED.csv       ISG CSV tables, composed, against `volcal predict`
  check_compensation.py sinumerikpoints DIR X,Y,Z OUT.csv  the point, then every node of the reference lines
  check_compensation.py sinumerik DIR PRED.csv          eec.mpf / cec.mpf against `volcal predict` there

ISG CSV (Beckhoff TF5280 "ISG CSV format", "Units of measure"): `//` line comments, a header naming
the columns, records of numbers, a line `#` starts a new header; positions and translational
errors in mm, angles in rad. The ISG kernel composes the ISO 230-1 component errors through the
kinematic chain; this reader composes them with the rigid-body small-angle model (a rotation
error of an axis acts on the lever arm to the tool: the coordinates of the axes it carries plus
the probe offset) and the ISO 230-1 squareness signs (C0Y: angle(+X, +Y) = 90 deg + C0Y, so
e_x = -C0Y y; B0Z: angle(+X, +Z) = 90 deg - B0Z, e_x = +B0Z z; A0Z: angle(+Y, +Z) = 90 deg + A0Z,
e_y = -A0Z z).

SINUMERIK (K3 Compensations): `%_N_..._INI`, `CHANDATA(1)`, `$NAME[i,...]=value` lines or `;`
comments, `M17`; EEC `$AA_ENC_COMP[0,N,AXi]`, CEC `$AN_CEC[t,N]`, points 0..k contiguous, at most
200 (828D CEC; 808D EEC), MAX = MIN + k STEP, values in mm; EEC holds the error (a positive value
moves the axis negative), CEC the correction added to the output axis (here: minus the error of
its line relative to the reference point, where the line starts: the first predicted point).
"""

import csv
import json
import re
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


ISO = {f'E{c}{a}' for a in 'XYZ' for c in 'XYZABC'} | {'C0Y', 'B0Z', 'A0Z'}


def read_isg(path: Path):
    """Blocks of (header, records) of an ISG CSV file, enforcing the format's rules."""
    blocks, header = [], None
    for n, raw in enumerate(path.read_text().splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith('//'):
            continue
        if line == '#':
            header = None
            continue
        f = line.split()
        if header is None:
            bad = [c for c in f if c not in ISO | set('XYZ')]
            if bad:
                raise SystemExit(f'{path}:{n}: header names {bad}, not ISO 230-1 parameters or axis arguments')
            header = f
            blocks.append((header, []))
            continue
        try:
            rec = [float(v) for v in f]
        except ValueError:
            raise SystemExit(f'{path}:{n}: not a record of numbers: {raw!r}')
        if len(rec) != len(header):
            raise SystemExit(f'{path}:{n}: {len(rec)} values for {len(header)} columns')
        blocks[-1][1].append(dict(zip(header, rec)))
    return blocks


def isg_tables(d: Path):
    comp, square = {}, {}
    for a in 'XYZ':
        for header, recs in read_isg(d / f'isg_{a.lower()}.csv'):
            if header[0] == a:
                want = [a] + [f'E{c}{a}' for c in 'XYZABC']
                if header != want:
                    raise SystemExit(f'isg_{a.lower()}.csv: header {header}, expected {want}')
                q = [r[a] for r in recs]
                if len(q) < 2 or any(b <= x for x, b in zip(q, q[1:])):
                    raise SystemExit(f'isg_{a.lower()}.csv: {a} not ascending over at least two records')
                comp[a] = recs
            else:
                if len(recs) != 1:
                    raise SystemExit(f'isg_{a.lower()}.csv: position errors {header} need exactly one record')
                square.update(recs[0])
    if set(comp) != set('XYZ') or set(square) != {'C0Y', 'B0Z', 'A0Z'}:
        raise SystemExit(f'component tables {sorted(comp)}, squareness {sorted(square)}: incomplete')
    return comp, square


def lookup(recs, a, q):
    """The record of `recs` at node `q` (mm) of axis `a` (nodes only: no interpolation here)."""
    for r in recs:
        if abs(r[a] - q) < 1e-6:
            return r
    raise SystemExit(f'{q} mm is not a node of {a}')


def compose(comp, square, topology, x_mm, probe_mm):
    """ISO 230-1 rigid-body composition (small angles), mm."""
    chain = [c for c in topology if c != 'F']
    e = [0.0, 0.0, 0.0]
    for i, a in enumerate(chain):
        r = lookup(comp[a], a, x_mm['XYZ'.index(a)])
        h = list(probe_mm)
        for b in chain[i + 1:]:
            h['XYZ'.index(b)] += x_mm['XYZ'.index(b)]
        t = [r[f'E{c}{a}'] for c in 'XYZ']
        w = [r[f'E{c}{a}'] for c in 'ABC']
        cross = [w[1] * h[2] - w[2] * h[1], w[2] * h[0] - w[0] * h[2], w[0] * h[1] - w[1] * h[0]]
        for k in range(3):
            e[k] += t[k] + cross[k]
    e[0] += -square['C0Y'] * x_mm[1] + square['B0Z'] * x_mm[2]
    e[1] += -square['A0Z'] * x_mm[2]
    return e


ASSIGN = re.compile(r'^\$(A[AN]_[A-Z_]+)\[([^\]]+)\]=(\S+)$')


def read_mpf(path: Path, ini: str):
    lines = [l.strip() for l in path.read_text().splitlines() if l.strip()]
    if lines[0] != f'%_N_{ini}_INI' or lines[-1] != 'M17':
        raise SystemExit(f'{path}: must start with %_N_{ini}_INI and end with M17')
    body = [l for l in lines[1:-1] if not l.startswith(';')]
    if body[0] != 'CHANDATA(1)':
        raise SystemExit(f'{path}: CHANDATA(1) must precede the assignments')
    out = []
    for l in body[1:]:
        m = ASSIGN.match(l)
        if not m:
            raise SystemExit(f'{path}: not an assignment $NAME[index]=value: {l!r}')
        out.append((m.group(1), [i.strip() for i in m.group(2).split(',')], m.group(3)))
    return out


def sinumerik_tables(d: Path):
    """{('EEC', axis) or ('CEC', t): dict(values, step, min, max, input, output)} in mm."""
    tables = {}
    for name, idx, v in read_mpf(d / 'eec.mpf', 'AX_EEC'):
        if idx[0] != '0':
            raise SystemExit(f'eec.mpf: encoder index {idx[0]} (volcal writes measuring system 0)')
        ax = idx[-1]
        if not re.fullmatch(r'AX[1-3]', ax):
            raise SystemExit(f'eec.mpf: axis {ax}')
        t = tables.setdefault(('EEC', ax), {'values': {}, 'input': ax, 'output': ax})
        if name == 'AA_ENC_COMP':
            t['values'][int(idx[1])] = float(v)
        elif name in ('AA_ENC_COMP_STEP', 'AA_ENC_COMP_MIN', 'AA_ENC_COMP_MAX'):
            t[name.split('_')[-1].lower()] = float(v)
        elif name == 'AA_ENC_COMP_IS_MODULO':
            assert v == '0'
        else:
            raise SystemExit(f'eec.mpf: unknown variable ${name}')
    for name, idx, v in read_mpf(d / 'cec.mpf', 'NC_CEC'):
        t = tables.setdefault(('CEC', int(idx[0])), {'values': {}})
        if int(idx[0]) >= 8:
            raise SystemExit(f'cec.mpf: table {idx[0]} (a SINUMERIK 828D has tables 0..7)')
        if name == 'AN_CEC':
            t['values'][int(idx[1])] = float(v)
        elif name in ('AN_CEC_INPUT_AXIS', 'AN_CEC_OUTPUT_AXIS'):
            if not re.fullmatch(r'\(AX[1-3]\)', v):
                raise SystemExit(f'cec.mpf: axis {v} must be (AXn)')
            t[name.split('_')[-2].lower()] = v[1:-1]
        elif name in ('AN_CEC_STEP', 'AN_CEC_MIN', 'AN_CEC_MAX'):
            t[name.split('_')[-1].lower()] = float(v)
        elif name in ('AN_CEC_DIRECTION', 'AN_CEC_MULT_BY_TABLE', 'AN_CEC_IS_MODULO'):
            assert v == '0', (name, v)
        else:
            raise SystemExit(f'cec.mpf: unknown variable ${name}')
    for key, t in tables.items():
        n = len(t['values'])
        if sorted(t['values']) != list(range(n)) or not 2 <= n <= 200:
            raise SystemExit(f'{key}: points {sorted(t["values"])[:3]}...: must be 0..k contiguous, 2..200 of them')
        if not all(k in t for k in ('step', 'min', 'max', 'input', 'output')):
            raise SystemExit(f'{key}: STEP, MIN, MAX or an axis missing')
        if t['step'] <= 0 or abs(t['min'] + (n - 1) * t['step'] - t['max']) > 1e-6:
            raise SystemExit(f'{key}: MIN {t["min"]} + {n - 1} x STEP {t["step"]} != MAX {t["max"]}')
        if key[0] == 'CEC' and t['input'] == t['output']:
            raise SystemExit(f'{key}: input and output axis are both {t["input"]}')
    return tables


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
    elif cmd == 'isgpoints':
        comp, _ = isg_tables(d)
        nodes = {a: [r[a] for r in comp[a]] for a in 'XYZ'}
        n = max(len(v) for v in nodes.values())
        with open(sys.argv[3], 'w', newline='') as f:
            w = csv.writer(f)
            w.writerow(['x_m', 'y_m', 'z_m'])
            for i in range(n):
                w.writerow([nodes['X'][i % len(nodes['X'])] / 1000.0, nodes['Y'][(3 * i + 1) % len(nodes['Y'])] / 1000.0,
                            nodes['Z'][(7 * i + 2) % len(nodes['Z'])] / 1000.0])
    elif cmd == 'isg':
        comp, square = isg_tables(d)
        topology = sys.argv[3]
        pred = list(csv.DictReader(open(sys.argv[4])))
        worst = 0.0
        for p in pred:
            x_mm = [float(p[c + '_m']) * 1000.0 for c in 'xyz']
            e = compose(comp, square, topology, x_mm, [0.0, 0.0, 0.0])
            worst = max(worst, max(abs(e[k] - float(p['e' + c + '_m']) * 1000.0) for k, c in enumerate('xyz')))
        big = max(abs(r[f'E{c}{a}']) for a in 'XYZ' for r in comp[a] for c in 'XYZ')
        if not 1e-5 < big < 1.0:
            raise SystemExit(f'largest translational error {big}: not millimetres of a machine error')
        if worst > 1e-5:
            raise SystemExit(f'composed ISG tables differ from volcal predict by {worst} mm')
        print(f'isg_x/y/z.csv: {sum(len(v) for v in comp.values())} records, squareness {square}; composed at {len(pred)} points = volcal predict to {worst:.1e} mm ok')
    elif cmd == 'sinumerikpoints':
        point = [float(v) for v in sys.argv[3].split(',')]
        tables = sinumerik_tables(d)
        with open(sys.argv[4], 'w', newline='') as f:
            w = csv.writer(f)
            w.writerow(['x_m', 'y_m', 'z_m'])
            w.writerow(point)
            for k in range(3):
                t = tables[('EEC', f'AX{k + 1}')]
                for i in range(len(t['values'])):
                    x = list(point)
                    x[k] = (t['min'] + i * t['step']) / 1000.0
                    w.writerow(x)
    elif cmd == 'sinumerik':
        tables = sinumerik_tables(d)
        pred = list(csv.DictReader(open(sys.argv[3])))
        e_at = lambda row: [float(row['e' + c + '_m']) * 1000.0 for c in 'xyz']
        at_point = e_at(pred[0])
        lines, i = {}, 1
        for k in range(3):
            n = len(tables[('EEC', f'AX{k + 1}')]['values'])
            lines[f'AX{k + 1}'] = [e_at(r) for r in pred[i:i + n]]
            i += n
        worst = 0.0
        for key, t in tables.items():
            k_out = int(t['output'][2]) - 1
            line = lines[t['input']]
            if len(line) != len(t['values']):
                raise SystemExit(f'{key}: {len(t["values"])} points, its base axis has {len(line)}')
            for n, v in t['values'].items():
                want = line[n][k_out] if key[0] == 'EEC' else -(line[n][k_out] - at_point[k_out])
                worst = max(worst, abs(v - want))
        if worst > 2e-8:
            raise SystemExit(f'SINUMERIK tables differ from volcal predict by {worst} mm')
        eec = sum(1 for k in tables if k[0] == 'EEC')
        print(f'eec.mpf: {eec} tables, cec.mpf: {len(tables) - eec} tables; EEC = error, CEC = -(error - error at the point) to {worst:.1e} mm ok')
    else:
        raise SystemExit(__doc__)


if __name__ == '__main__':
    main()
