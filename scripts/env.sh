# shellcheck shell=bash
# The environment every gripper_sim process runs in: source it, don't execute it.
#
#   source scripts/env.sh        # then: gripper-sim ..., sim_node, python -m pytest ...
#
# Keeps ROS 2 traffic on this machine's loopback, on a domain of its own, with the
# venv's ROS (pip wheels) and faster discovery. Safe to source more than once.
# GRIPPER_SIM_VENV overrides the venv (default: <repo>/.venv).

# Find the repo from this file's own path (bash, zsh); other shells: run from the repo.
if [ -n "${BASH_VERSION:-}" ]; then
  eval '_gs_root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)'
elif [ -n "${ZSH_VERSION:-}" ]; then
  eval '_gs_root=$(cd "$(dirname "${(%):-%x}")/.." && pwd)'
else
  _gs_root=$(pwd)
fi
if [ ! -f "$_gs_root/config/fastdds_localhost.xml" ]; then
  echo "scripts/env.sh: cannot find the gripper_sim repo (from $_gs_root); source it from bash or from the repo root" >&2
fi
export GRIPPER_SIM_ROOT="$_gs_root"
export GRIPPER_SIM_VENV="${GRIPPER_SIM_VENV:-$_gs_root/.venv}"

# ROS from the venv's wheels (ament_index looks packages up under $VENV/share).
export AMENT_PREFIX_PATH="$GRIPPER_SIM_VENV"
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
# Discovery on loopback only: no multicast, 127.0.0.1 the only initial peer.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
# Static peers would be contacted even in the LOCALHOST range; the deprecated
# ROS_LOCALHOST_ONLY overrides the range with a warning.
unset ROS_STATIC_PEERS ROS_LOCALHOST_ONLY
# More initial discovery announcements and loopback-only transports (see the file).
export FASTRTPS_DEFAULT_PROFILES_FILE="$_gs_root/config/fastdds_localhost.xml"
# A domain of its own so parallel runs don't see each other: kept when already set,
# else derived from this shell's process id, in 1..101.
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( $$ % 101 + 1 ))}"

case ":$PATH:" in
  *":$GRIPPER_SIM_VENV/bin:"*) ;;
  *) export PATH="$GRIPPER_SIM_VENV/bin:$PATH" ;;
esac
unset _gs_root
