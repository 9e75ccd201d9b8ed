#!/bin/bash
# Guest side of hil.camera: the libcamera camera pair on the two vimc instances (vimc.0, vimc.1).
#
#   guest-camera.sh HIL_CAMERA_BINARY
set -u
source "$(dirname "$0")/guest-devices.sh"
export LIBCAMERA_LOG_LEVELS='*:ERROR'
find_vimc_cameras || exit 1
"$1" --gtest_filter='-*Removed*:*Missing*' || exit 1
# The camera removed while streaming (vimc.1 unbound) stays abandoned in that process, so the
# return of the camera is tested by a new one, as systemd's restart would.
"$1" --gtest_filter='*RemovedWhileStreaming*' || exit 1
exec "$1" --gtest_filter='*MissingAtStart*'
