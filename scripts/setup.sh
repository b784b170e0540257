#!/usr/bin/env bash
# Create .venv with the pinned packages and build ros_ws. Idempotent: each stage re-runs only
# when its inputs changed, so a second run takes a few seconds.
#   --venv-only   stop after the virtualenv (the container image installs the wheels in a layer
#                 of their own, before the code is copied in)
# ROBOT_SIM_NO_BROWSER=1 leaves out the browser the control panel's test drives (the image).
set -euo pipefail

VENV_ONLY=0
for arg in "$@"; do
  case "$arg" in
    --venv-only) VENV_ONLY=1 ;;
    *) printf '[setup] error: unknown argument %s (known: --venv-only)\n' "$arg" >&2; exit 2 ;;
  esac
done

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
WS="$ROOT/ros_ws"
STAMPS="$VENV/.stamps"
PYTHON="${PYTHON:-python3}"

log() { printf '[setup] %s\n' "$*"; }
die() { printf '[setup] error: %s\n' "$*" >&2; exit 1; }

hash_of() { sha256sum | cut -c1-32; }

# --- 1. system prerequisites --------------------------------------------------------------
# A C/C++ compiler builds the rosidl type support of ros_ws/src/sim_interfaces; venv and
# ensurepip are split out of python3 on Debian and Ubuntu.
missing=()
command -v "$PYTHON" >/dev/null || die "$PYTHON not found; install Python 3.10-3.13"
"$PYTHON" - <<'PY' || die "Python 3.10-3.13 is required"
import sys
sys.exit(0 if (3, 10) <= sys.version_info[:2] <= (3, 13) else 1)
PY
command -v cc >/dev/null || missing+=(gcc)
command -v c++ >/dev/null || missing+=(g++)
command -v make >/dev/null || missing+=(make)
"$PYTHON" -c 'import ensurepip, venv' 2>/dev/null || missing+=("python3-venv")
# Python.h: rosidl's Python type support compiles against it.
"$PYTHON" -c 'import os, sysconfig, sys
sys.exit(0 if os.path.isfile(os.path.join(sysconfig.get_paths()["include"], "Python.h")) else 1)' \
  || missing+=("python3-dev")
if [ ${#missing[@]} -gt 0 ]; then
  pkgs="build-essential python3-venv python3-dev"
  if command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
    log "installing system packages: $pkgs"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $pkgs >/dev/null
  elif command -v apt-get >/dev/null && sudo -n true 2>/dev/null; then
    log "installing system packages with sudo: $pkgs"
    sudo apt-get update -qq && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $pkgs
  else
    die "missing ${missing[*]}; run: sudo apt-get install $pkgs"
  fi
fi

# --- 1a. a browser for the control panel's test -------------------------------------------
# The browser test (tests/graph/test_control_panel_graph.py) drives Debian's chromium through
# its chromium-driver with Selenium; nothing downloads a browser. Installed where we can.
if [ "${ROBOT_SIM_NO_BROWSER:-0}" = 1 ]; then
  :
elif ! command -v chromium >/dev/null || ! command -v chromedriver >/dev/null; then
  if command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
    log "installing chromium and chromium-driver (the control panel's browser test)"
    { apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
        apt-get install -y -qq chromium chromium-driver >/dev/null; } \
      || log "warning: apt-get could not install chromium chromium-driver: the browser test will fail"
  else
    log "note: no chromium/chromedriver; the browser test is skipped (install them with:" \
        "sudo apt-get install chromium chromium-driver)"
  fi
fi

# --- 1b. a ROS 2 sourced in this shell ---------------------------------------------------------
# The project installs ROS 2 Jazzy as wheels into .venv. A system ROS 2 (/opt/ros/<distro>)
# sourced in the same shell would put its own Python packages and libraries beside those:
# two rclpy builds in one process. Stop, and say what to do, rather than mix them silently.
sourced=""
[ -n "${ROS_DISTRO:-}" ] && sourced="ROS_DISTRO=$ROS_DISTRO"
for var in AMENT_PREFIX_PATH PYTHONPATH LD_LIBRARY_PATH; do
  case ":${!var:-}:" in
    *:/opt/ros/*) [ -n "$sourced" ] || sourced="$var has /opt/ros" ;;
  esac
done
if [ -n "$sourced" ] && [ -z "${ROBOT_SIM_IGNORE_SOURCED_ROS:-}" ]; then
  die "a system ROS 2 is sourced in this shell ($sourced): run this from a shell that has not sourced /opt/ros/*/setup.bash (on a full install, build ros_ws with colcon against it instead: see README, \"On a full ROS 2 install\")"
fi

# --- 2. virtualenv with exact pins ------------------------------------------------------------
pyver="$("$PYTHON" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
if [ -x "$VENV/bin/python" ]; then
  venv_ver="$("$VENV/bin/python" -c 'import sys; print("%d.%d" % sys.version_info[:2])' \
    2>/dev/null || echo none)"
  if [ "$venv_ver" != "$pyver" ]; then
    log ".venv was made with Python $venv_ver, rebuilding with $pyver"
    rm -rf "$VENV"
  fi
fi
if [ ! -x "$VENV/bin/python" ]; then
  log "creating .venv with $("$PYTHON" --version)"
  "$PYTHON" -m venv "$VENV"
fi
mkdir -p "$STAMPS"
LOCK="$ROOT/requirements/py$pyver.txt"
[ -f "$LOCK" ] || die "no lock file requirements/py$pyver.txt for Python $pyver"
req_hash="$(cat "$LOCK" | hash_of)"
if [ "$(cat "$STAMPS/requirements" 2>/dev/null)" != "$req_hash" ]; then
  log "installing pinned packages (requirements/py$pyver.txt)"
  case "$pyver" in 3.12|3.13) log "pybullet has no wheel for Python $pyver: compiling it takes minutes" ;; esac
  "$VENV/bin/python" -m pip install -q --disable-pip-version-check --upgrade pip==24.3.1
  "$VENV/bin/python" -m pip install -q --disable-pip-version-check -r "$LOCK"
  # The ROS wheels were built on a manylinux host: their CMake exports name that host's Python.
  "$VENV/bin/python" "$ROOT/scripts/fix_wheel_cmake_paths.py" "$VENV"
  echo "$req_hash" > "$STAMPS/requirements"
  rm -f "$STAMPS/workspace"
fi

if [ "$VENV_ONLY" = 1 ]; then
  log "virtualenv ready (--venv-only: ros_ws not built)"
  exit 0
fi

# --- 3. colcon workspace ----------------------------------------------------------------------
# Rebuild when anything but Python modules changed (the build is --symlink-install, so edits of
# existing modules are live); setup.py, data files, new or removed files trigger a build.
ws_hash="$(cd "$WS/src" && {
  find -L . -type f ! -path '*/__pycache__/*' ! -name '*.pyc' | LC_ALL=C sort
  find -L . -type f ! -path '*/__pycache__/*' \( ! -name '*.py' -o -name setup.py \) \
    ! -name '*.pyc' -print0 | LC_ALL=C sort -z | xargs -0 cat
} | hash_of)"
# tf2_msgs, control_msgs and simulation_interfaces (ros_ws/src/std_interfaces) are built only
# where the environment has none: the ROS wheels in .venv, or an install on the
# AMENT_PREFIX_PATH this ran with.
provided=()
for pkg in tf2_msgs control_msgs simulation_interfaces; do
  for prefix in "$VENV" $(printf '%s' "${AMENT_PREFIX_PATH:-}" | tr ':' ' '); do
    case "$prefix" in "$WS"/*) continue ;; esac
    if [ -f "$prefix/share/$pkg/package.xml" ]; then provided+=("$pkg"); break; fi
  done
done
ws_hash="$(printf '%s %s' "$ws_hash" "${provided[*]:-}" | hash_of)"
if [ "$(cat "$STAMPS/workspace" 2>/dev/null)" != "$ws_hash" ] || [ ! -f "$WS/install/setup.bash" ]; then
  log "building ros_ws with colcon"
  if [ ${#provided[@]} -gt 0 ]; then
    log "the environment provides ${provided[*]}: not building ours"
    rm -rf "${provided[@]/#/$WS/install/}" "${provided[@]/#/$WS/build/}"
  fi
  # An interface package whose set of .msg/.srv/.action files changed is built from scratch:
  # rosidl leaves a removed interface's generated code behind, and the type support then fails
  # to load ("undefined symbol ..._convert_from_py").
  interface_lists=()
  for pkg_dir in "$WS"/src/sim_interfaces "$WS"/src/std_interfaces/*/; do
    pkg="$(basename "$pkg_dir")"
    list="$(cd "$pkg_dir" && find . -name '*.msg' -o -name '*.srv' -o -name '*.action' \
      | LC_ALL=C sort | hash_of)"
    if [ -f "$STAMPS/interfaces_$pkg" ] && [ "$(cat "$STAMPS/interfaces_$pkg")" != "$list" ]; then
      log "$pkg: its interfaces changed, building it afresh"
      rm -rf "$WS/build/$pkg" "$WS/install/$pkg"
    fi
    interface_lists+=("$pkg=$list")
  done
  # A Python package's executables are made afresh: one that moved to another package (the
  # study tools, from coordinator to studies) would otherwise linger in the old package's lib/
  # and, first on the PATH, fail to import.
  for setup_py in "$WS"/src/*/setup.py; do
    pkg="$(basename "$(dirname "$setup_py")")"
    rm -rf "${WS:?}/install/$pkg/lib/$pkg"
  done
  mkdir -p "$WS/log"
  (
    cd "$WS"
    export AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV"
    export PATH="$VENV/bin:$PATH"
    # shellcheck disable=SC1091
    source "$VENV/bin/activate"
    colcon --log-base log build --symlink-install \
      ${provided[@]:+--packages-skip "${provided[@]}"} \
      --event-handlers console_cohesion+ status- \
      --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$VENV/bin/python" \
      > "$WS/log/last_build_output.txt" 2>&1 || {
        tail -60 "$WS/log/last_build_output.txt" >&2
        die "colcon build failed (full output: ros_ws/log/last_build_output.txt)"; }
  )
  for entry in "${interface_lists[@]}"; do
    echo "${entry#*=}" > "$STAMPS/interfaces_${entry%%=*}"
  done
  echo "$ws_hash" > "$STAMPS/workspace"
fi
log "ready: source scripts/env.sh to use the workspace"
