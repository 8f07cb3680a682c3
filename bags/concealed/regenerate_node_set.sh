#!/usr/bin/env bash
# Records the concealed-effect bags of the node set (bags/concealed/node_set/): the diagnosis
# plan on the fly through the simulated nodes over DDS (this host only), one clean recording per
# machine and one per catalogue effect, each hidden with conceal:=true. The bags have neutral names (a bag's
# name goes into its metadata.yaml); the key (which bag hides what) and the truth files are in
# tests/fixtures/concealed/node_set/, outside the bags. The magnitudes are those of
# bags/concealed/regenerate.sh (SNR >= 3 in tests/tests/diagnose_catalogue.rs) except the latency,
# which acts here on the nodes' own timing (0.175 us at 2 m/s) and the cyclic error and probe
# offset, which act on the precision machine. About 16 minutes (each recording 80 s).
#
#   bags/concealed/regenerate_node_set.sh [DOMAIN]
set -euo pipefail
cd "$(dirname "$0")/../.."
domain="${1:-118}"
cargo build -q --release -p volcal_cli -p volcal_nodes --bins
volcal="${CARGO_TARGET_DIR:-target}/release/volcal"
out=bags/concealed/node_set
key=tests/fixtures/concealed/node_set
rm -rf "$out" "$key"
mkdir -p "$out" "$key"
std=launch_configs/machines/diagnosis_cmm.yaml
prec=launch_configs/machines/diagnosis_cmm_precision.yaml
# The launch of cli/tests/concealed_node_set.rs: the diagnosis plan 40 times faster, the machine
# at 2 kHz in batches, the interferometer at 200 Hz, the air every 2 s of the campaign.
otf=(plan:=launch_configs/plans/diagnosis.yaml speed_mps:=2 sample_rate_hz:=200 machine_rate_hz:=2000
  batch:=20 time_scale:=40 environment_rate_hz:=20)
echo '{' >"$key/key.json"
n=0
record() { # EFFECT SEED MACHINE SPEC [launch args...]
  local effect=$1 seed=$2 machine=$3 spec=$4
  shift 4
  n=$((n + 1))
  local name
  name=$(printf 'recording_%02d' "$n")
  "$volcal" launch launch_configs/sim_campaign_short.yaml --bag "$out/$name" --domain "$domain" \
    machine:="$machine" seed:="$seed" inject:="$spec" conceal:=true truth:="$key/$name.truth.json" \
    "${otf[@]}" "$@" >"$key/$name.log" 2>&1 || { cat "$key/$name.log" >&2; exit 1; }
  rm "$key/$name.log"
  [ "$n" -gt 1 ] && echo ',' >>"$key/key.json"
  printf '  "%s": {"effect": "%s", "machine": "%s", "seed": %s}' "$name" "$effect" "$machine" "$seed" >>"$key/key.json"
  echo "$name: $effect"
}
record clean               11 "$std"  ""
record clean               22 "$prec" ""
record setup_drift         14 "$std"  setup_drift:vx_m_per_s=2e-8,vy_m_per_s=0,vz_m_per_s=2e-8
record latency             15 "$std"  latency:latency_s=1.75e-7
record reversal            16 "$std"  reversal:backlash_x_m=1.5e-6,backlash_y_m=0,backlash_z_m=0
record air_refraction      12 "$std"  air_refraction air_rate_k_per_h:=30
record material_expansion  13 "$std"  material_expansion:rate_k_per_h=2.5
record beam_break          20 "$std"  beam_break:station=1,beam=4,index=60,step_m=-1.3e-6
record periodic_pitch      17 "$std"  periodic_pitch:axis=0,period_m=0.016,amplitude_m=1.0e-6
record nonrigid            18 "$std"  nonrigid:coefficient_m=1.4e-5
record probe_offset        19 "$prec" probe_offset:dx_m=0,dy_m=0,dz_m=-0.004
record cyclic_nonlinearity 21 "$prec" cyclic_nonlinearity:amplitude_m=2e-8
printf '\n}\n' >>"$key/key.json"
du -sh "$out"
