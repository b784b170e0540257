# Source this file to use the workspace: the venv, the ROS packages installed in it, and ros_ws.
# (bash or zsh)  source scripts/env.sh
_rs_root="$(cd "$(dirname "${BASH_SOURCE[0]:-$0}")/.." && pwd)"
# shellcheck disable=SC1091
source "$_rs_root/.venv/bin/activate"
# The pip-installed ROS packages live in the venv prefix; the ament index must see them.
case ":${AMENT_PREFIX_PATH:-}:" in
  *":$_rs_root/.venv:"*) ;;
  *) export AMENT_PREFIX_PATH="$_rs_root/.venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;;
esac
# colcon's setup scripts read unset variables: relax `set -u` while sourcing them.
case $- in *u*) _rs_nounset=1; set +u ;; *) _rs_nounset= ;; esac
# shellcheck disable=SC1091
source "$_rs_root/ros_ws/install/setup.bash"
[ -n "$_rs_nounset" ] && set -u
# ros2cli is not pip-installable: put each package's lib/<pkg> (where `ros2 run` looks) on PATH.
for _rs_dir in "$_rs_root"/ros_ws/install/*/lib/*/; do
  _rs_pkg="$(basename "$(dirname "$(dirname "$_rs_dir")")")"
  if [ "$(basename "$_rs_dir")" = "$_rs_pkg" ]; then
    _rs_abs="$(cd "$_rs_dir" && pwd)"
    case ":$PATH:" in *":$_rs_abs:"*) ;; *) PATH="$_rs_abs:$PATH" ;; esac
  fi
done
export PATH
# The project's Fast DDS profile (ros_common/config/fastdds.xml: a shared-memory segment that
# holds camera frames), unless a profile or another middleware is chosen already.
case "${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}" in
  rmw_fastrtps*)
    _rs_profile="$_rs_root/ros_ws/install/ros_common/share/ros_common/config/fastdds.xml"
    if [ -z "${FASTRTPS_DEFAULT_PROFILES_FILE:-}${FASTDDS_DEFAULT_PROFILES_FILE:-}" ] \
        && [ -f "$_rs_profile" ]; then
      export FASTRTPS_DEFAULT_PROFILES_FILE="$_rs_profile" FASTDDS_DEFAULT_PROFILES_FILE="$_rs_profile"
    fi ;;
esac
unset _rs_root _rs_dir _rs_pkg _rs_abs _rs_nounset _rs_profile
