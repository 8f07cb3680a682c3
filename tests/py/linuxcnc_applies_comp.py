#!/usr/bin/python3
"""The real LinuxCNC 2.9 controller (headless sim, shared/tools/linuxcnc-sim) applies a volcal
COMP_FILE: it loads DIR/x.comp as [JOINT_0] COMP_FILE (type TYPE), moves X with MDI to positions
on and between the nodes, up and down, and reads the HAL pins in-process (full double precision;
`halcmd getp` prints only 1e-5 mm). The correction it applies, joint.0.motor-pos-cmd -
joint.0.pos-cmd, must equal the one volcal's model asks for: minus the
predicted error along X, linearly interpolated between the nodes (PRED.csv: `volcal predict` at
the nodes of x.comp, other axes at the table's reference point), plus, with DIAG.json (a
`volcal diagnose --json` file naming a reversal error), half the X backlash moving up and minus
half moving down: LinuxCNC uses the forward column moving +X, the reverse column moving -X, and
holds the last one when stopped.

Run with Debian's /usr/bin/python3 (LinuxCNC's modules live there).

usage: linuxcnc_applies_comp.py SIM_DIR DIR TYPE PRED.csv [DIAG.json]
"""
import csv
import json
import sys
import time

sim_dir, out_dir, kind, pred_csv = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
backlash_mm = 0.0
if len(sys.argv) > 5:
    effects = json.load(open(sys.argv[5]))['effects']
    rev = [e for e in effects if e['id'] == 'reversal']
    assert rev, 'the diagnosis names no reversal error'
    backlash_mm = rev[0]['parameters']['backlash_x_m'] * 1000.0
sys.path.insert(0, sim_dir)
from lcnc_sim import LinuxCNCSim  # noqa: E402

# What volcal's model asks for at each node of x.comp (mm), from `volcal predict`.
pred = [r for r in csv.DictReader(open(pred_csv))]
nodes = [(float(r['x_m']) * 1000.0, -float(r['ex_m']) * 1000.0) for r in pred]
nodes.sort()


def wanted(x):
    """The model's correction at x, interpolated linearly between nodes (what a table can hold)."""
    if x <= nodes[0][0]:
        return nodes[0][1]
    if x >= nodes[-1][0]:
        return nodes[-1][1]
    for (x0, y0), (x1, y1) in zip(nodes, nodes[1:]):
        if x0 <= x <= x1:
            return y0 + (y1 - y0) * (x - x0) / (x1 - x0)


lo, hi = max(nodes[0][0], -250.0), min(nodes[-1][0], 250.0)  # the sim's X limits are +-254 mm
step = nodes[1][0] - nodes[0][0]
on = [x for x, _ in nodes if lo <= x <= hi]
targets = []
for x in on[1:6]:
    targets += [x, x + 0.37 * step]  # on a node, then between two
up = sorted(set(round(t, 3) for t in targets if lo <= t <= hi))
moves = up + sorted(up, reverse=True)[1:]

worst = 0.0
rows = 0
prev = 0.0  # homed at X 0
with LinuxCNCSim(comp_file=f'{out_dir}/x.comp', comp_type=kind, quiet=True) as sim:
    sim.machine_on_and_home()
    for t in moves:
        sim.mdi(f'G0 X{t:.4f}')
        time.sleep(0.3)
        pos = sim.hal_fast('joint.0.pos-cmd')
        motor = sim.hal_fast('joint.0.motor-pos-cmd')
        got = motor - pos
        up = t > prev
        prev = t
        want = wanted(pos) + (0.5 if up else -0.5) * backlash_mm
        worst = max(worst, abs(got - want))
        rows += 1
        print(f'X {t:9.3f} mm {"up  " if up else "down"} pos-cmd {pos:10.5f}  applied {got * 1000:9.4f} um  model {want * 1000:9.4f} um')
print(f'{rows} moves (up and down, on and between nodes, backlash {backlash_mm * 1000:.3f} um): largest difference {worst * 1000:.2e} um')
if worst > 1e-6:
    sys.exit(f'LinuxCNC applies a correction that differs from the model by {worst * 1000:.4f} um')
