#!/usr/bin/env bash
# Build one interface package (msg/srv/action) into a venv with plain CMake and check
# that every type it defines imports and loads its type support.
#
#   scripts/build_interface.sh VENV interfaces/PKG
#
# For the ROS 2 standard packages we carry (tf2_msgs, control_msgs,
# simulation_interfaces: not among the pip wheels) nothing is built when the real
# package is installed in VENV already (its package.xml is not ours): it is used as it is.
set -euo pipefail

venv=$(cd "$1" && pwd)
src=$(cd "$2" && pwd)
pkg=$(basename "$src")
py="$venv/bin/python"
ours='<maintainer email="gripper-sim@example.com">'
installed="$venv/share/$pkg/package.xml"
if [ -f "$installed" ] && ! grep -q "$ours" "$installed"; then
  echo "== interfaces: $pkg is installed (the real package): using it"
  exit 0
fi

echo "== interfaces: building $pkg into $venv (plain CMake)"
"$py" "$(dirname "$0")/fix_ros_cmake_exports.py"
build="$venv/build/$pkg"
mkdir -p "$build"
export PATH="$venv/bin:$PATH" AMENT_PREFIX_PATH="$venv"
{ cmake -S "$src" -B "$build" -Wno-dev \
    -DCMAKE_PREFIX_PATH="$venv" -DCMAKE_INSTALL_PREFIX="$venv" \
    -DPython3_EXECUTABLE="$py" -DBUILD_TESTING=OFF \
  && cmake --build "$build" -j2 && cmake --install "$build"; } > "$build/make.log" 2>&1 \
  || { tail -n 40 "$build/make.log" >&2
       echo "error: building $pkg failed, see $build/make.log" >&2; exit 1; }

"$py" - "$pkg" "$src" <<'PY'
import importlib
import sys
from pathlib import Path

package, source = sys.argv[1], Path(sys.argv[2])
count = 0
for kind, suffix in (('msg', '.msg'), ('srv', '.srv'), ('action', '.action')):
    for definition in sorted((source / kind).glob(f'*{suffix}')):
        cls = getattr(importlib.import_module(f'{package}.{kind}'), definition.stem)
        cls.__class__.__import_type_support__()
        count += 1
print(f'interfaces ok: {package} ({count} types)')
PY
