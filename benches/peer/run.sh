#!/usr/bin/env bash
# Runs the SciPy peer and `volcal solve` on the same simulated campaigns and prints both solve
# times, their ratio, and the volumetric difference between the two results.
#   benches/peer/run.sh [path/to/volcal]     (default: target/release/volcal, built if missing)
set -euo pipefail
cd "$(dirname "$0")/../.."
VOLCAL=${1:-target/release/volcal}
[ -x "$VOLCAL" ] || cargo build --release --bin volcal
VENV=${PEER_VENV:-.venv-peer}
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install -q -r benches/peer/requirements.txt
fi
OUT=$(mktemp -d)
run_case() {
  local name=$1 machine=$2 plan=$3 intervals=$4
  "$VOLCAL" simulate --machine "$machine" --plan "$plan" --seed 1 --out "$OUT/$name.csv" >/dev/null 2>&1
  local ours
  ours=$("$VOLCAL" solve "$OUT/$name.csv" --machine "$machine" --out "$OUT/$name.json" 2>&1 >/dev/null | grep -o 'in [0-9.]* ms' | grep -o '[0-9.]*')
  echo "== $name: volcal solve ${ours} ms"
  local peer
  peer=$("$VENV/bin/python" benches/peer/reduced_lsq.py "$OUT/$name.csv" --intervals "$intervals" --compare "$OUT/$name.json" --json "$OUT/$name.peer.json")
  echo "$peer"
  python3 -c "import json; p=json.load(open('$OUT/$name.peer.json')); print(f'   speed ratio (peer / volcal): {p[\"solve_s\"]*1e3/$ours:.1f}')"
}
run_case patent launch_configs/machines/demo_cmm.yaml launch_configs/plans/patent_example.yaml 12
run_case large benches/peer/large_machine.yaml benches/peer/large_plan.yaml 52
rm -rf "$OUT"
