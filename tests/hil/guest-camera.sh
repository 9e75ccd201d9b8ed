#!/bin/bash
# Guest side of hil.camera: the libcamera camera pair on the two vimc instances (vimc.0, vimc.1).
#
#   guest-camera.sh HIL_CAMERA_BINARY
set -u
export LIBCAMERA_LOG_LEVELS='*:ERROR'
cam --list
ids=$(cam --list 2>/dev/null | sed -n 's/^[0-9]*: .* (\(.*\))$/\1/p')
EDGETRACK_CAMERA0=$(echo "$ids" | grep 'vimc\.0' || true)
EDGETRACK_CAMERA1=$(echo "$ids" | grep 'vimc\.1' || true)
if [ -z "$EDGETRACK_CAMERA0" ] || [ -z "$EDGETRACK_CAMERA1" ]; then
    echo "FAILED: libcamera does not list both vimc cameras"
    exit 1
fi
export EDGETRACK_CAMERA0 EDGETRACK_CAMERA1
"$1" --gtest_filter='-*Removed*:*Missing*' || exit 1
# The camera removed while streaming (vimc.1 unbound) stays abandoned in that process, so the
# return of the camera is tested by a new one, as systemd's restart would.
"$1" --gtest_filter='*RemovedWhileStreaming*' || exit 1
exec "$1" --gtest_filter='*MissingAtStart*'
