#!/usr/bin/env bash
# Builds Python type support for volcal_msgs (msgs/msg/*.msg) so that rclpy (Fast DDS) can
# publish and subscribe to volcal's topics, without a ROS installation and without cmake:
# the rosidl generators of the venv (the Python-registry ROS packages installed by .ci/run)
# generate C, type support (rosidl_typesupport_c, _fastrtps_c, _introspection_c, with the
# type description and hash) and Python sources, gcc/g++ compile them against the venv's
# headers and libraries, and the result is installed as an overlay prefix laid out like a
# colcon install of the package:
#
#   OUT/lib/libvolcal_msgs__rosidl_{generator_c,typesupport_c,typesupport_fastrtps_c,
#           typesupport_introspection_c,generator_py}.so
#   OUT/lib/python3.11/site-packages/volcal_msgs/   (msg/*.py, volcal_msgs_s__rosidl_*.so)
#   OUT/share/ament_index/resource_index/{packages,rosidl_interfaces}/volcal_msgs
#   OUT/share/volcal_msgs/{package.xml,msg/*.msg,*.idl,*.json}   OUT/include/volcal_msgs/...
#
# Usage: .ci/build_rclpy_msgs.sh [VENV] [OUT]   (defaults: .venv and .rclpy_msgs in the repo)
# Then:  AMENT_PREFIX_PATH=OUT:VENV PYTHONPATH=OUT/lib/python3.11/site-packages \
#        LD_LIBRARY_PATH=OUT/lib:VENV/lib RMW_IMPLEMENTATION=rmw_fastrtps_cpp VENV/bin/python ...
#
# Idempotent: it does nothing when OUT was built from the same .msg files, script and venv
# (FORCE=1 rebuilds); otherwise it builds in a temporary directory and replaces OUT at the end.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
venv=${1:-.venv}
out=${2:-.rclpy_msgs}
case $venv in /*) ;; *) venv=$repo/$venv ;; esac
case $out in /*) ;; *) out=$repo/$out ;; esac
pkg=volcal_msgs
msgdir=$repo/msgs
py=$venv/bin/python

die() { echo "build_rclpy_msgs: error: $*" >&2; exit 1; }

# --- tools ------------------------------------------------------------------------------------
[ -x "$py" ] || die "no Python at $py (create the venv first: .ci/run installs .ci/requirements.txt)"
command -v gcc >/dev/null || die "gcc not found (apt-get install gcc)"
command -v g++ >/dev/null || die "g++ not found (apt-get install g++)"
ls "$msgdir"/msg/*.msg >/dev/null 2>&1 || die "no message definitions in $msgdir/msg"
export AMENT_PREFIX_PATH=$venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}
"$py" - <<'EOF' || die "the venv lacks a ROS package the build needs (see the ImportError above; .ci/requirements.txt pins them)"
import rosidl_adapter.msg, rosidl_generator_c.cli, rosidl_generator_py.cli, numpy
import rosidl_generator_type_description, rosidl_cli.command.hash.api
import rosidl_typesupport_c.cli, rosidl_typesupport_fastrtps_c.cli
import rosidl_typesupport_introspection_c.cli, rclpy
EOF
pyinc=$("$py" -c "import sysconfig; print(sysconfig.get_paths()['include'])")
[ -f "$pyinc/Python.h" ] || pyinc=/usr/include/python3.11
[ -f "$pyinc/Python.h" ] || die "Python.h not found (apt-get install python3-dev)"
npinc=$("$py" -c "import numpy; print(numpy.get_include())")
ext=$("$py" -c "import sysconfig; print(sysconfig.get_config_var('EXT_SUFFIX'))")
pyver=$("$py" -c "import sys; print(f'python{sys.version_info[0]}.{sys.version_info[1]}')")
for l in rosidl_runtime_c rcutils rosidl_typesupport_c rosidl_typesupport_fastrtps_c \
         rosidl_typesupport_introspection_c fastcdr std_msgs__rosidl_generator_py; do
  ls "$venv"/lib/lib$l.so* >/dev/null 2>&1 || die "lib$l.so not in $venv/lib"
done

# --- up to date? --------------------------------------------------------------------------------
stamp=$( (cat "$msgdir"/msg/*.msg "$0"; "$py" -m pip freeze 2>/dev/null | grep -i '^ros-') | sha256sum | cut -c1-64)
if [ "${FORCE:-0}" != 1 ] && [ -f "$out/.stamp" ] && [ "$(cat "$out/.stamp")" = "$stamp" ]; then
  echo "build_rclpy_msgs: $out is up to date ($(ls "$msgdir"/msg/*.msg | wc -l) types of $pkg); FORCE=1 rebuilds"
  exit 0
fi

start=$(date +%s)
work=$(mktemp -d "${TMPDIR:-/tmp}/rclpy_msgs.XXXXXX")
trap 'rm -rf "$work"' EXIT
gen=$work/gen
stage=$work/out

# --- generate -----------------------------------------------------------------------------------
# The generators' Python entry points, called directly: the `rosidl` CLI refuses to run in this
# venv (each ROS package is registered twice, egg-info and dist-info, and the CLI treats the
# duplicate entry points as an error) and its .msg -> .idl step needs catkin_pkg, which we do
# not need: rosidl_adapter converts .msg to .idl without it.
"$py" - "$pkg" "$msgdir" "$venv/share" "$gen" <<'EOF' > "$work/generate.log" 2>&1 || { cat "$work/generate.log" >&2; die "code generation failed"; }
import logging, pathlib, sys
logging.getLogger('rosidl_cli.entry_points').setLevel(logging.ERROR)
from rosidl_adapter.msg import convert_msg_to_idl
from rosidl_cli.command.hash.api import generate_type_hashes
from rosidl_generator_c.cli import GenerateC
from rosidl_generator_py.cli import GeneratePython
from rosidl_typesupport_c.cli import GenerateCTypesupport
from rosidl_typesupport_fastrtps_c.cli import GenerateFastRTPSCTypesupport
from rosidl_typesupport_introspection_c.cli import GenerateIntrospectionCTypesupport

pkg, msgdir, inc, out = sys.argv[1], pathlib.Path(sys.argv[2]), sys.argv[3], pathlib.Path(sys.argv[4])
idldir = out / 'idl' / pkg
idl = []
for f in sorted((msgdir / 'msg').glob('*.msg')):
    p = convert_msg_to_idl(msgdir, pkg, pathlib.Path('msg') / f.name, idldir / 'msg')
    idl.append(f'{idldir}:{p.relative_to(idldir).as_posix()}')
# Type descriptions (msg/*.json) with their RIHS01 hashes, which the C code embeds.
hashes = generate_type_hashes(package_name=pkg, interface_files=idl, include_paths=[inc],
                              output_path=out / 'type_description' / pkg)
for name, gen, kw in [
        ('c', GenerateC('c'), dict(type_description_files=hashes)),
        ('typesupport_c', GenerateCTypesupport('c'), {}),
        ('typesupport_fastrtps_c', GenerateFastRTPSCTypesupport('fastrtps_c'), {}),
        ('typesupport_introspection_c', GenerateIntrospectionCTypesupport('introspection_c'), {}),
        ('py', GeneratePython('py'), {})]:
    files = gen.generate(pkg, idl, [inc], output_path=out / name / pkg, **kw)
    print(f'generated {name}: {len(files)} files')
EOF
grep '^generated' "$work/generate.log" | sed 's/^/build_rclpy_msgs: /'

# --- compile ------------------------------------------------------------------------------------
incs=(-I"$gen/c" -I"$gen/typesupport_c" -I"$gen/typesupport_fastrtps_c"
      -I"$gen/typesupport_introspection_c")
incs+=(-I"$venv/include")  # fastcdr/, fastdds/ (not nested per package)
for d in "$venv"/include/*/; do incs+=(-I"$d"); done
lib=$stage/lib
mkdir -p "$lib"
# RUNPATH: the overlay's own lib and the venv's, so that the libraries load without
# LD_LIBRARY_PATH too. rosidl_typesupport_c dlopen()s the per-RMW type support library by its
# bare name (libvolcal_msgs__rosidl_typesupport_fastrtps_c.so), which the loader finds without
# LD_LIBRARY_PATH only when it is already loaded: so every library gets its SONAME, and the
# Python extension rclpy imports (volcal_msgs_s__rosidl_typesupport_c) links all of them.
ldflags=(-shared -L"$lib" -L"$venv/lib" -Wl,-rpath,"$out/lib:$venv/lib" -Wl,--no-as-needed)
cflags=(-O1 -fPIC -w "${incs[@]}")
deps=(std_msgs builtin_interfaces)
deplibs() { local s; for d in "${deps[@]}"; do for s in "$@"; do echo "-l${d}__$s"; done; done; }

so() {  # so NAME compiler sources... -- libs...
  local name=$1 cc=$2; shift 2
  local srcs=() libs=()
  while [ $# -gt 0 ] && [ "$1" != -- ]; do srcs+=("$1"); shift; done
  [ $# -gt 0 ] && shift
  libs=("$@")
  local t0=$(date +%s)
  "$cc" "${cflags[@]}" "${srcs[@]}" "${ldflags[@]}" -Wl,-soname,"$(basename "$name")" -o "$name" "${libs[@]}" \
    || die "compiling $(basename "$name") failed"
  local n=0 f; for f in "${srcs[@]}"; do case $f in -*) ;; *) n=$((n + 1)) ;; esac; done
  echo "build_rclpy_msgs: built $(basename "$name") ($n sources, $(( $(date +%s) - t0 )) s)"
}

so "$lib/lib${pkg}__rosidl_generator_c.so" gcc "$gen"/c/$pkg/msg/detail/*.c -- \
  $(deplibs rosidl_generator_c) -lrosidl_runtime_c -lrcutils
so "$lib/lib${pkg}__rosidl_typesupport_introspection_c.so" gcc \
  "$gen"/typesupport_introspection_c/$pkg/msg/detail/*.c -- \
  -l${pkg}__rosidl_generator_c $(deplibs rosidl_typesupport_introspection_c rosidl_generator_c) \
  -lrosidl_typesupport_introspection_c -lrosidl_runtime_c -lrcutils
so "$lib/lib${pkg}__rosidl_typesupport_fastrtps_c.so" g++ \
  "$gen"/typesupport_fastrtps_c/$pkg/msg/detail/*.cpp -- \
  -l${pkg}__rosidl_generator_c $(deplibs rosidl_typesupport_fastrtps_c rosidl_generator_c) \
  -lrosidl_typesupport_fastrtps_c -lrosidl_typesupport_fastrtps_cpp -lrosidl_dynamic_typesupport \
  -lrmw -lfastcdr -lrosidl_runtime_c -lrcutils
so "$lib/lib${pkg}__rosidl_typesupport_c.so" g++ "$gen"/typesupport_c/$pkg/msg/*.cpp -- \
  -l${pkg}__rosidl_generator_c $(deplibs rosidl_typesupport_c) -lrosidl_typesupport_c \
  -lrosidl_runtime_c -lrcutils
so "$lib/lib${pkg}__rosidl_generator_py.so" gcc -I"$pyinc" -I"$npinc" "$gen"/py/$pkg/msg/*_s.c -- \
  -l${pkg}__rosidl_generator_c -l${pkg}__rosidl_typesupport_c \
  $(deplibs rosidl_generator_py rosidl_generator_c rosidl_typesupport_c) -lrosidl_runtime_c -lrcutils

site=$lib/$pyver/site-packages/$pkg
mkdir -p "$site/msg"
for ts in rosidl_typesupport_c rosidl_typesupport_fastrtps_c rosidl_typesupport_introspection_c; do
  extra=()
  [ $ts = rosidl_typesupport_c ] && extra=(-l${pkg}__rosidl_typesupport_fastrtps_c -l${pkg}__rosidl_typesupport_introspection_c)
  so "$site/${pkg}_s__$ts$ext" gcc -I"$pyinc" -I"$npinc" "$gen/py/$pkg/_${pkg}_s.ep.$ts.c" -- \
    -l${pkg}__rosidl_generator_py -l${pkg}__$ts "${extra[@]}" -l${pkg}__rosidl_generator_c \
    $(deplibs rosidl_generator_py) -lrosidl_runtime_c -lrcutils
done

# --- install (staged, then moved into place) ----------------------------------------------------
cp "$gen"/py/$pkg/msg/*.py "$site/msg/"
[ -f "$gen/py/$pkg/__init__.py" ] && cp "$gen/py/$pkg/__init__.py" "$site/" || : > "$site/__init__.py"
share=$stage/share
mkdir -p "$share/$pkg/msg" "$share/ament_index/resource_index/packages" \
  "$share/ament_index/resource_index/rosidl_interfaces" "$stage/include/$pkg"
cp "$msgdir"/msg/*.msg "$gen"/idl/$pkg/msg/*.idl "$gen"/type_description/$pkg/msg/*.json "$share/$pkg/msg/"
: > "$share/ament_index/resource_index/packages/$pkg"
(cd "$share/$pkg" && ls msg/*.idl msg/*.msg | sort) > "$share/ament_index/resource_index/rosidl_interfaces/$pkg"
echo "rosidl_typesupport_c;rosidl_typesupport_fastrtps_c;rosidl_typesupport_introspection_c" \
  > "$share/$pkg/typesupports"
cat > "$share/$pkg/package.xml" <<EOF
<?xml version="1.0"?>
<package format="3">
  <name>$pkg</name>
  <version>0.0.0</version>
  <description>volcal's messages (built by .ci/build_rclpy_msgs.sh from msgs/msg/*.msg)</description>
  <maintainer email="volcal@example.invalid">volcal</maintainer>
  <license>see the volcal repository</license>
  <depend>std_msgs</depend>
  <depend>builtin_interfaces</depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
</package>
EOF
for g in c typesupport_fastrtps_c typesupport_introspection_c; do
  cp -r "$gen/$g/$pkg" "$stage/include/$pkg/" 2>/dev/null || true
done
find "$stage/include" -type f ! -name '*.h' ! -name '*.hpp' -delete

# Smoke test from the staged tree (before replacing OUT): import, type support, type hash.
LD_LIBRARY_PATH="$stage/lib:$venv/lib" "$py" - <<EOF || die "the built overlay does not load (see above)"
import sys
sys.path.insert(0, "$stage/lib/$pyver/site-packages")
from $pkg.msg import ErrorModel
from rclpy.type_support import check_for_type_support
check_for_type_support(ErrorModel)
assert ErrorModel._TYPE_SUPPORT is not None
EOF
echo "$stamp" > "$stage/.stamp"
rm -rf "$out.old"
[ -e "$out" ] && mv "$out" "$out.old"
mkdir -p "$(dirname "$out")"
mv "$stage" "$out"
rm -rf "$out.old"
# And once more from where it is installed.
PYTHONPATH="$out/lib/$pyver/site-packages" LD_LIBRARY_PATH="$out/lib:$venv/lib" \
  AMENT_PREFIX_PATH="$out:$venv" "$py" -c "from $pkg.msg import ErrorModel; import rclpy.type_support as t; t.check_for_type_support(ErrorModel)" \
  || die "the installed overlay at $out does not load"
ntypes=$(ls "$out/share/$pkg/msg/"*.msg | wc -l)
echo "build_rclpy_msgs: installed $pkg ($ntypes message types) into $out in $(( $(date +%s) - start )) s"
echo "build_rclpy_msgs: use AMENT_PREFIX_PATH=$out:$venv PYTHONPATH=$out/lib/$pyver/site-packages LD_LIBRARY_PATH=$out/lib:$venv/lib"
