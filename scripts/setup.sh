#!/usr/bin/env bash
# One-command set-up: venv, pinned ROS 2 Jazzy wheels, the CMake path fix, colcon build.
# Idempotent: each step leaves a stamp keyed on its inputs and is skipped when they are unchanged.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
stamps=.stamps
mkdir -p "$stamps"
python=${PYTHON:-python3}

step() { echo "[setup] $*" >&2; }
digest() { cat "$@" | sha256sum | cut -c1-16; }

if [ ! -x .venv/bin/python ]; then
  step "creating .venv with $($python --version)"
  "$python" -m venv .venv
fi

req=$(digest requirements.txt)
if [ "$(cat $stamps/pip 2>/dev/null)" != "$req" ]; then
  step "installing pinned packages (requirements.txt), about a minute"
  .venv/bin/python -m pip install --quiet --upgrade pip
  .venv/bin/python -m pip install --quiet -r requirements.txt
  rm -f $stamps/cmakefix $stamps/colcon
  echo "$req" > $stamps/pip
fi

if [ ! -f $stamps/cmakefix ]; then
  # docs/design.md, Setup, quirk 1: the wheels' CMake exports name the wheel builder's Python.
  step "rewriting the wheels' CMake include paths to this Python"
  .venv/bin/python scripts/fix_cmake_paths.py .venv
  touch $stamps/cmakefix
fi

src=$(find ros2_ws/src \( -name package.xml -o -name setup.py -o -name setup.cfg -o -name CMakeLists.txt -o -name '*.msg' \) -print0 | sort -z | xargs -0 cat | sha256sum | cut -c1-16)
if [ "$(cat $stamps/colcon 2>/dev/null)" != "$src" ] || [ ! -f ros2_ws/install/setup.bash ]; then
  step "building ros2_ws with colcon"
  (
    # shellcheck disable=SC1091
    source .venv/bin/activate
    export AMENT_PREFIX_PATH="$VIRTUAL_ENV" CMAKE_PREFIX_PATH="$VIRTUAL_ENV"
    cd ros2_ws
    colcon --log-base log build --symlink-install --event-handlers console_direct- \
      --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$VIRTUAL_ENV/bin/python" >&2
  )
  echo "$src" > $stamps/colcon
fi
step "ready"
