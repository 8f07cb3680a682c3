#!/usr/bin/env bash
# Regenerates the README pictures of the Rerun views, rendered by the real Rerun viewer (the
# rerun-sdk pinned in .ci/requirements.txt, same version as the `rerun` crate) headless under
# Xvfb with Mesa's software Vulkan, at 1920x1080:
#   docs/solve.png  first screen of `volcal solve --rerun` on the demo campaign (seed 7)
#   docs/live.png   first screen of the viz node watching the short simulated campaign over DDS
#                   (launch_configs/sim_campaign_short.yaml on a ROS domain of its own, this host
#                   only), its recording stopped during the third station
#   docs/diagnose.png first screen of `volcal diagnose --rerun` on bags/concealed/setup_drift.csv
#   docs/live_diagnosis.png the viz node at the end of a short campaign with a beam break
#                   concealed (station 1 beam 4), diagnosed live by the solver node
#                   (launch_configs/live_diagnosis.yaml): the flagged beam, the residual RMS per
#                   beam before and after the refit, the RMS history
#
# usage: docs/screenshots.sh [solve|diagnose|live|live_diagnosis]   (default: all four)
# needs: xvfb-run and a Vulkan driver (apt-get install xvfb mesa-vulkan-drivers libvulkan1).
set -euo pipefail
cd "$(dirname "$0")/.."
size=1920x1080
[ -x .venv/bin/rerun ] || { python3 -m venv .venv && .venv/bin/pip install -q -r .ci/requirements.txt; }
cargo build -q --release -p volcal_cli -p volcal_nodes --bins
bin=${CARGO_TARGET_DIR:-target}/release
volcal() { "$bin/volcal" "$@"; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# Renders a recording to a PNG (the viewer writes a HiDPI picture; it is scaled to $size).
render() {
  local rrd=$1 out=$2
  # A fresh HOME: the viewer restores its window state from earlier sessions otherwise, which
  # can put an error notification over the picture.
  mkdir -p "$work/home"
  HOME="$work/home" XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$work} timeout 180 xvfb-run -a -s "-screen 0 ${size}x24" \
    .venv/bin/rerun "$rrd" --screenshot-to "$work/shot.png" --window-size "$size" >/dev/null 2>&1 || true
  [ -s "$work/shot.png" ] || { echo "no picture rendered for $rrd" >&2; exit 1; }
  .venv/bin/python - "$work/shot.png" "$out" "$size" <<'PY'
import sys
from PIL import Image
src, out, size = sys.argv[1], sys.argv[2], tuple(int(v) for v in sys.argv[3].split("x"))
Image.open(src).convert("RGB").resize(size, Image.LANCZOS).save(out, optimize=True)
PY
  echo "wrote $out"
}

which=${1:-all}
machine=launch_configs/machines/demo_cmm.yaml
if [ "$which" = all ] || [ "$which" = solve ]; then
volcal simulate --machine "$machine" --seed 7 --out "$work/campaign.csv"
volcal solve "$work/campaign.csv" --machine "$machine" --out "$work/model.json" --rerun "$work/solve.rrd" >/dev/null || [ $? -eq 3 ]
render "$work/solve.rrd" docs/solve.png
fi
if [ "$which" = all ] || [ "$which" = diagnose ]; then
volcal diagnose bags/concealed/setup_drift.csv --machine launch_configs/machines/diagnosis_cmm.yaml \
  --rerun "$work/diagnose.rrd" >/dev/null
render "$work/diagnose.rrd" docs/diagnose.png
fi
[ "$which" = all ] || [ "$which" = live ] || [ "$which" = live_diagnosis ] || exit 0

# The live view: the viz node (saving its view) and the campaign, on a ROS domain leased as the
# tests lease theirs (a lock file per id), so that nothing else on this host joins.
exec 9>/dev/null
for id in $(seq 101 232); do
  exec 9>"${TMPDIR:-/tmp}/volcal-ros-domain-$id.lock"
  if flock -n 9; then domain=$id; break; fi
done
[ -n "${domain:-}" ] || { echo "no free ROS domain id in 101..232" >&2; exit 1; }
if [ "$which" = all ] || [ "$which" = live_diagnosis ]; then
dm=launch_configs/machines/diagnosis_cmm.yaml
"$bin/volcal" launch launch_configs/live_diagnosis.yaml --domain "$domain" machine:="$dm" >"$work/solver.log" 2>&1 &
solver=$!
"$bin/volcal" launch launch_configs/viz.yaml --domain "$domain" machine:="$dm" rerun:="$work/live_diagnosis.rrd" >"$work/viz.log" 2>&1 &
viz=$!
for _ in $(seq 600); do grep -q "showing the campaign live" "$work/viz.log" && break; sleep 0.1; done
sleep 2
"$bin/volcal" launch launch_configs/sim_campaign_short.yaml --bag "$work/bag_diag" --domain "$domain" machine:="$dm" \
  seed:=20 inject:=beam_break:station=1,beam=4,index=10,step_m=-1.3e-6 conceal:=true station_setup_s:=3 \
  >"$work/campaign.log" 2>&1
for _ in $(seq 600); do grep -q "published the final diagnosis" "$work/solver.log" && break; sleep 0.1; done
sleep 2
kill -INT "$viz" "$solver"
wait "$viz" || { cat "$work/viz.log" >&2; exit 1; }
wait "$solver" || true
grep "published the" "$work/solver.log" || true
render "$work/live_diagnosis.rrd" docs/live_diagnosis.png
fi
[ "$which" = all ] || [ "$which" = live ] || exit 0
"$bin/volcal" launch launch_configs/viz.yaml --domain "$domain" rerun:="$work/live.rrd" >"$work/viz.log" 2>&1 &
viz=$!
for _ in $(seq 600); do grep -q "showing the campaign live" "$work/viz.log" && break; sleep 0.1; done
sleep 2
# 960 points with a 20 ms dwell each (about 40 s): the view is saved a few seconds after the
# sequencer moved to the third station (about 100 of its 320 points).
"$bin/volcal" launch launch_configs/sim_campaign_short.yaml --bag "$work/bag" --domain "$domain" \
  dwell_s:=0.02 station_setup_s:=0.5 >"$work/campaign.log" 2>&1 &
campaign=$!
for _ in $(seq 1200); do grep -q "station 2: waiting" "$work/campaign.log" && break; sleep 0.1; done
sleep 4.5
kill -INT "$viz"
wait "$viz" || { cat "$work/viz.log" >&2; exit 1; }
grep -q "station 2: waiting" "$work/campaign.log" || { cat "$work/campaign.log" >&2; exit 1; }
kill -INT "$campaign"   # the rest of the campaign is not needed
wait "$campaign" || true
grep "viz:" "$work/viz.log" || true
render "$work/live.rrd" docs/live.png
