#!/usr/bin/env bash
# Endpoint announcements that Fast DDS loses (README): how often the rclpy cell never discovers
# one of our endpoints, with and without the RustDDS patch (third_party/rustdds/VOLCAL_PATCH.md).
#
#   tests/stress/endpoint_announcements.sh OUT LANES MINUTES VOLCAL_A [VOLCAL_B]
#
# Runs LANES lanes side by side (domains 81, 82, ...) for MINUTES minutes. Each lane repeats the
# stuck-cell campaign (the rclpy cell of tests/py/ros2_cell.py, `volcal launch
# launch_configs/cell_dry_run.yaml`, the cell stuck after 2 s so that a campaign takes about
# 10 s), alternating the two `volcal` binaries given (each must be named `volcal`: `launch`
# runs the nodes built into it). The cell logs when its discovery first knew each endpoint
# (--log-endpoints); tests/py/endpoint_losses.py OUT counts the endpoints never discovered and
# those discovered late. Needs .venv (.ci/run makes it). Not a CI test: losses are rare, and the
# load is the point.
set -uo pipefail
out=$1; lanes=$2; minutes=$3; shift 3
root=$(cd "$(dirname "$0")/../.." && pwd)
mkdir -p "$out"
campaign() { # campaign DIR DOMAIN VOLCAL
  local w=$1 d=$2 volcal=$3
  mkdir -p "$w"
  ( export AMENT_PREFIX_PATH=$root/.venv RMW_IMPLEMENTATION=rmw_fastrtps_cpp ROS_DOMAIN_ID=$d ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
    unset ROS_LOCALHOST_ONLY
    exec "$root/.venv/bin/python" "$root/tests/py/ros2_cell.py" --log-endpoints "$w/endpoints.csv" --ready "$w/ready" \
      --fault stuck --fault-after 2 2> "$w/cell.err" ) &
  local cell=$!
  while [ ! -f "$w/ready" ]; do sleep 0.05; done
  sleep 2
  ROS_LOCALHOST_ONLY=1 RUST_LOG="info,rustdds=off,ros2_client=error,mio=warn" timeout 120 "$volcal" launch \
    "$root/launch_configs/cell_dry_run.yaml" --domain "$d" --bag "$w/bag" \
    joint_names:=x=gantry_x_joint,y=gantry_y_joint,z=quill_joint plan:="$root/tests/data/plans/cell_faults.yaml" \
    speed_mps:=1.0 acceleration_mps2:=100 motion_timeout_s:=2.0 > "$w/launch.log" 2>&1
  sleep 1
  kill -TERM $cell 2>/dev/null; wait $cell # the cell may have ended on its own (its error is in cell.err)
  rm -rf "$w/bag"
}
end=$(( $(date +%s) + 60 * minutes ))
for l in $(seq 1 "$lanes"); do
  ( n=0
    while [ "$(date +%s)" -lt $end ]; do
      n=$((n + 1)); a=0
      for volcal in "$@"; do
        a=$((a + 1))
        campaign "$out/${l}_${n}_$a" $((80 + l)) "$volcal"
      done
    done ) &
done
wait
echo "done: $(ls -d "$out"/*_*_* | wc -l) campaigns in $out"
