#!/bin/bash
# Guest side of hil.firmware: `edgetrack run --board linux` on vimc, gpio-sim and vcan0.
#
#   guest-firmware.sh HIL_FIRMWARE_BINARY EDGETRACK_BINARY
set -u
source "$(dirname "$0")/guest-devices.sh"
export LIBCAMERA_LOG_LEVELS='*:ERROR'
make_gpio_chip || exit 1
make_vcan || exit 1
find_vimc_cameras || exit 1
export EDGETRACK_BINARY=$2
exec "$1"
