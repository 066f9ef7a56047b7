#!/usr/bin/env bash
# The ball tracker alone on a USB camera: frames from cv2.VideoCapture -> /ball_state.
# Ctrl-C stops it.
#
#   scripts/tracker_usb.sh                                   # /dev/video0 (index 0), 640x480 @ 30 Hz
#   scripts/tracker_usb.sh --device /dev/video2 --calibration config/usb_camera.yaml
#   scripts/tracker_usb.sh --size 960x540 --fps 60 --debug   # + overlay on /ball_tracker/debug_image
#   scripts/tracker_usb.sh --param hsv_lower=[0,90,60]       # any tracker parameter
#
# Calibrate first (optional, better accuracy):
#   python -m ball_balance.tools.calibrate_camera 'shots/*.png' --pattern 9x6 --square-m 0.025 --out config/usb_camera.yaml
# Tune the ball colour on a saved frame:
#   python -m ball_balance.tools.tune_hsv frame.png --out /tmp/hsv --pick U V
# Watch: ros2 topic echo /ball_state (or ros2py topic echo /ball_state without ROS installed).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [[ -z "${BALL_BALANCE_ROOT:-}" ]]; then
  # shellcheck disable=SC1091
  source "$ROOT/env.sh"
fi

DEVICE=0
SIZE=640x480
FPS=30
CALIBRATION=""
DEBUG=false
PARAMS=()
usage() { sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//'; }
source "$ROOT/scripts/lib/args.sh"   # needs, require_*
while (($#)); do
  case "$1" in
    --device) needs 1 "$@"; DEVICE="$2"; shift 2 ;;
    --size) needs 1 "$@"; SIZE="$2"; shift 2 ;;
    --fps) needs 1 "$@"; FPS="$2"; shift 2 ;;
    --calibration) needs 1 "$@"; CALIBRATION="$2"; shift 2 ;;
    --debug) DEBUG=true; shift ;;
    --param) needs 1 "$@"; PARAMS+=(-p "$2"); shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "tracker_usb.sh: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done
require_ros_domain tracker_usb.sh
require_number tracker_usb.sh --fps "$FPS"
require_size tracker_usb.sh --size "$SIZE"

[[ "$FPS" == *.* ]] || FPS="$FPS.0"          # a float parameter
if [[ -n "$CALIBRATION" ]]; then
  PARAMS=(-p "calibration_file:=$CALIBRATION" ${PARAMS[@]+"${PARAMS[@]}"})
fi

exec ball_tracker --ros-args --params-file "$ROOT/config/ball_tracker.yaml" \
  -p source:=camera -p "camera_device:='$DEVICE'" \
  -p "camera_width:=${SIZE%x*}" -p "camera_height:=${SIZE#*x}" -p "camera_fps:=$FPS" \
  -p "publish_debug_image:=$DEBUG" ${PARAMS[@]+"${PARAMS[@]}"}
