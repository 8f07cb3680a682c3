#!/usr/bin/env bash
# Regenerates the concealed-effect campaigns: each hides one effect of the diagnosis catalogue
# (one hides an effect outside it, one hides nothing). The campaign files say nothing about what
# was injected (--conceal); the truth goes to tests/fixtures/concealed/. Strengths are those
# that give a signal-to-noise ratio of at least 3 in the diagnosis tests
# (tests/tests/diagnose_catalogue.rs), rounded up. Run from the repository root.
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build -q --release -p volcal_cli --bin volcal
volcal="${CARGO_TARGET_DIR:-target}/release/volcal"
plan=launch_configs/plans/diagnosis.yaml
std=launch_configs/machines/diagnosis_cmm.yaml
prec=launch_configs/machines/diagnosis_cmm_precision.yaml

make() { # NAME SEED MACHINE [simulate options...]
  local name=$1 seed=$2 machine=$3
  shift 3
  "$volcal" simulate --machine "$machine" --plan "$plan" --seed "$seed" --conceal \
    --out "bags/concealed/$name.csv" --truth "tests/fixtures/concealed/$name.truth.json" "$@"
}

make clean               11 "$std"
make air_refraction      12 "$std"  --air-rate 30 --inject air_refraction
make material_expansion  13 "$std"  --inject material_expansion:rate_k_per_h=2.5
make setup_drift         14 "$std"  --inject setup_drift:vx_m_per_s=2e-8,vy_m_per_s=0,vz_m_per_s=2e-8
make latency             15 "$std"  --inject latency:latency_s=7e-6
make reversal            16 "$std"  --inject reversal:backlash_x_m=1.5e-6,backlash_y_m=0,backlash_z_m=0
make periodic_pitch      17 "$std"  --inject periodic_pitch:axis=0,period_m=0.016,amplitude_m=1.0e-6
make nonrigid            18 "$std"  --inject nonrigid:coefficient_m=1.4e-5
make probe_offset        19 "$prec" --inject probe_offset:dx_m=0,dy_m=0,dz_m=-0.035
make beam_break          20 "$std"  --inject beam_break:station=1,beam=4,index=30,step_m=-1.3e-6
make cyclic_nonlinearity 21 "$prec" --inject cyclic_nonlinearity:amplitude_m=2e-8
make unmodelled_bump     22 "$std"  --inject unmodelled_bump:amplitude_m=5e-6
