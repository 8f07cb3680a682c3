#!/usr/bin/env bash
# Regenerates the sample bags in bags/ by running the simulated node set over DDS on this
# host (ROS_LOCALHOST_ONLY). Run from the repository root; takes about a minute. With
# --concealed it also remakes the concealed-effect campaigns (bags/concealed/regenerate.sh, CSV)
# and node-set recordings (bags/concealed/regenerate_node_set.sh, about 17 minutes).
#
#   bags/regenerate.sh [--concealed] [DOMAIN]
set -euo pipefail
cd "$(dirname "$0")/.."
concealed=false
if [ "${1:-}" = "--concealed" ]; then
  concealed=true
  shift
fi
domain="${1:-117}"
cargo build -q --release -p volcal_cli -p volcal_nodes --bins
volcal="${CARGO_TARGET_DIR:-target}/release/volcal"
rm -rf bags/sim_short bags/sim_tracer_short bags/sim_otf_batched

# Fixed-beam campaign, static points paired by trigger: 3 positions x 16 beams x 20 points.
"$volcal" launch launch_configs/sim_campaign_short.yaml --bag bags/sim_short --domain "$domain"

# Laser-tracer campaign (the paper's method): 4 stations, the 12 cuboid edges.
"$volcal" launch launch_configs/sim_tracer_short.yaml --bag bags/sim_tracer_short --domain "$domain"

# On the fly, instruments sampling at 2 kHz in batches of 20, pairs by timestamp interpolation.
"$volcal" launch launch_configs/sim_campaign_short.yaml --bag bags/sim_otf_batched --domain "$domain" \
  plan:=launch_configs/plans/otf_sample.yaml speed_mps:=0.5 \
  sample_rate_hz:=2000 machine_rate_hz:=2000 batch:=20

for b in bags/sim_short bags/sim_tracer_short bags/sim_otf_batched; do
  "$volcal" bag info "$b"
done

if $concealed; then
  bags/concealed/regenerate.sh
  bags/concealed/regenerate_node_set.sh "$((domain + 1))"
fi
