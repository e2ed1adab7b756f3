# Sourced by the Makefile and scripts/rrtq: the venv, the built workspace, DDS on loopback.
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck disable=SC1091
source "$root/.venv/bin/activate"
# setup.bash reads unset variables; relax nounset around it.
case $- in *u*) _rrtq_u=1; set +u;; *) _rrtq_u=;; esac
# shellcheck disable=SC1091
source "$root/ros2_ws/install/setup.bash"
[ -n "$_rrtq_u" ] && set -u
# The ROS wheels install into the venv prefix: make it an ament prefix too.
export AMENT_PREFIX_PATH="${AMENT_PREFIX_PATH}:$VIRTUAL_ENV"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
export RRTQ_ROOT="$root"
# One BLAS thread per process: the nodes are separate processes on few cores, and OpenBLAS's
# threads then contend (small dense solves measured 7x to 17x slower on 2 busy cores).
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
