# Source this file (bash): puts the workspace's venv and colcon install space on the environment,
# as `source /opt/ros/jazzy/setup.bash && source install/setup.bash` would on a Jazzy machine.
_inflarm_root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
if [ ! -f "$_inflarm_root/install/setup.bash" ]; then
  echo "inflarm: no install/ yet; run scripts/setup.sh first" >&2
  return 1 2>/dev/null || exit 1
fi
# colcon's setup.bash reads unset variables: source it without nounset, then restore.
case $- in *u*) _inflarm_nounset=1 ;; *) _inflarm_nounset= ;; esac
set +u
# shellcheck disable=SC1091
source "$_inflarm_root/.venv/bin/activate"
# shellcheck disable=SC1091
source "$_inflarm_root/install/setup.bash"
[ -n "$_inflarm_nounset" ] && set -u
# The ROS wheels keep their ament resource index inside the venv.
case ":${AMENT_PREFIX_PATH:-}:" in
  *":$VIRTUAL_ENV:"*) ;;
  *) export AMENT_PREFIX_PATH="${AMENT_PREFIX_PATH:+$AMENT_PREFIX_PATH:}$VIRTUAL_ENV" ;;
esac
export INFLARM_ROOT="$_inflarm_root"
unset _inflarm_root _inflarm_nounset
