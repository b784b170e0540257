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
# The project's Fast DDS profile, unless a profile or another middleware is chosen already:
# ros_common/config/fastdds.xml (DDS on the loopback interface only, and a shared-memory
# segment that holds camera frames), or fastdds_network.xml (open to other machines) when
# ROS_AUTOMATIC_DISCOVERY_RANGE is SUBNET or SYSTEM_DEFAULT or ROS_STATIC_PEERS is set
# (ros_common/dds.py decides the same for the launchers).
case "${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}" in
  rmw_fastrtps*)
    _rs_profile="$_rs_root/ros_ws/install/ros_common/share/ros_common/config/fastdds.xml"
    case "${ROS_AUTOMATIC_DISCOVERY_RANGE:-}" in
      [Ss][Uu][Bb][Nn][Ee][Tt]|[Ss][Yy][Ss][Tt][Ee][Mm]_[Dd][Ee][Ff][Aa][Uu][Ll][Tt])
        _rs_profile="${_rs_profile%.xml}_network.xml" ;;
      *) _rs_peers="${ROS_STATIC_PEERS:-}"
         if [ -n "${_rs_peers// /}" ]; then _rs_profile="${_rs_profile%.xml}_network.xml"; fi ;;
    esac
    if [ -z "${FASTRTPS_DEFAULT_PROFILES_FILE:-}${FASTDDS_DEFAULT_PROFILES_FILE:-}" ] \
        && [ -f "$_rs_profile" ]; then
      export FASTRTPS_DEFAULT_PROFILES_FILE="$_rs_profile" FASTDDS_DEFAULT_PROFILES_FILE="$_rs_profile"
    fi ;;
esac
unset _rs_root _rs_dir _rs_pkg _rs_abs _rs_nounset _rs_profile _rs_peers
