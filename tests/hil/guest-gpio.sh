#!/bin/bash
# Guest side of hil.gpio: a gpio-sim chip with the board's three lines, then the GPIO backends.
#
#   guest-gpio.sh HIL_GPIO_BINARY
set -u
sim=/sys/kernel/config/gpio-sim/edgetrack
mkdir "$sim" "$sim/bank0" || exit 1
echo 4 > "$sim/bank0/num_lines"
offset=0
for name in IR_LED BUTTON STATUS_LED; do
    mkdir "$sim/bank0/line$offset"
    echo "$name" > "$sim/bank0/line$offset/name"
    offset=$((offset + 1))
done
echo 1 > "$sim/live" || exit 1
EDGETRACK_GPIO_CHIP=$(cat "$sim/bank0/chip_name")
EDGETRACK_GPIO_SYSFS=/sys/devices/platform/$(cat "$sim/dev_name")/$EDGETRACK_GPIO_CHIP
export EDGETRACK_GPIO_CHIP EDGETRACK_GPIO_SYSFS
gpioinfo "$EDGETRACK_GPIO_CHIP"
exec "$1"
