#!/bin/bash
# Guest side of hil.gpio: a gpio-sim chip with the board's three lines, then the GPIO backends.
#
#   guest-gpio.sh HIL_GPIO_BINARY
set -u
source "$(dirname "$0")/guest-devices.sh"
make_gpio_chip || exit 1
exec "$1"
