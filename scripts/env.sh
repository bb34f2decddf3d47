# Source this to get the project's ROS 2 environment: the venv and the colcon install space.
# Used by the Makefile; `source scripts/env.sh` works in an interactive shell too.
_ssi_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck disable=SC1091
source "$_ssi_root/.venv/bin/activate"
export AMENT_PREFIX_PATH="$_ssi_root/.venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export CMAKE_PREFIX_PATH="$_ssi_root/.venv${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
if [ -f "$_ssi_root/install/setup.bash" ]; then
  # colcon's setup scripts read unset variables; relax nounset while sourcing them.
  case $- in *u*) _ssi_nounset=1; set +u;; *) _ssi_nounset=0;; esac
  # shellcheck disable=SC1091
  source "$_ssi_root/install/setup.bash"
  [ "$_ssi_nounset" = 1 ] && set -u
fi
export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"
# what /opt/ros/jazzy/setup.bash sets: the venv holds Jazzy's wheels, and tools read these
# (`ros2 doctor` fails its distribution checks without ROS_DISTRO)
export ROS_DISTRO=jazzy ROS_VERSION=2 ROS_PYTHON_VERSION=3
unset _ssi_root _ssi_nounset
