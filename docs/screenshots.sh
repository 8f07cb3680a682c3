#!/usr/bin/env bash
# Regenerates the README pictures of the Rerun views, rendered by the real Rerun viewer (the
# rerun-sdk pinned in .ci/requirements.txt, same version as the `rerun` crate) headless under
# Xvfb with Mesa's software Vulkan, at 1920x1080:
#   docs/solve.png  first screen of `volcal solve --rerun` on the demo campaign (seed 7)
#
# usage: docs/screenshots.sh
# needs: xvfb-run and a Vulkan driver (apt-get install xvfb mesa-vulkan-drivers libvulkan1).
set -euo pipefail
cd "$(dirname "$0")/.."
size=1920x1080
[ -x .venv/bin/rerun ] || { python3 -m venv .venv && .venv/bin/pip install -q -r .ci/requirements.txt; }
cargo build -q --bin volcal
volcal() { cargo run -q --bin volcal -- "$@"; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# Renders a recording to a PNG (the viewer writes a HiDPI picture; it is scaled to $size).
render() {
  local rrd=$1 out=$2
  XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$work} timeout 180 xvfb-run -a -s "-screen 0 ${size}x24" \
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

machine=launch_configs/machines/demo_cmm.yaml
volcal simulate --machine "$machine" --seed 7 --out "$work/campaign.csv"
volcal solve "$work/campaign.csv" --machine "$machine" --out "$work/model.json" --rerun "$work/solve.rrd" >/dev/null || [ $? -eq 3 ]
render "$work/solve.rrd" docs/solve.png
