#!/bin/bash
# Guest helpers, sourced by the guest-*.sh scripts: the board's simulated devices in the VM.

# A gpio-sim chip "edgetrack" with the board's lines IR_LED, BUTTON and STATUS_LED at offsets
# 0, 1, 2; exports EDGETRACK_GPIO_CHIP (gpiochipN) and EDGETRACK_GPIO_SYSFS (its sim_gpioN dir).
make_gpio_chip() {
    local sim=/sys/kernel/config/gpio-sim/edgetrack offset=0 name
    mkdir "$sim" "$sim/bank0" || return 1
    echo 4 > "$sim/bank0/num_lines"
    for name in IR_LED BUTTON STATUS_LED; do
        mkdir "$sim/bank0/line$offset"
        echo "$name" > "$sim/bank0/line$offset/name"
        offset=$((offset + 1))
    done
    echo 1 > "$sim/live" || return 1
    EDGETRACK_GPIO_CHIP=$(cat "$sim/bank0/chip_name")
    EDGETRACK_GPIO_SYSFS=/sys/devices/platform/$(cat "$sim/dev_name")/$EDGETRACK_GPIO_CHIP
    export EDGETRACK_GPIO_CHIP EDGETRACK_GPIO_SYSFS
    gpioinfo "$EDGETRACK_GPIO_CHIP"
}

# vcan0 with the CAN FD MTU.
make_vcan() {
    ip link add dev vcan0 type vcan && ip link set vcan0 mtu 72 && ip link set vcan0 up
}

# The libcamera ids of the two vimc instances (vimc.0, vimc.1) as EDGETRACK_CAMERA0/1.
find_vimc_cameras() {
    local ids
    ids=$(cam --list 2>/dev/null | sed -n 's/^[0-9]*: .* (\(.*\))$/\1/p')
    EDGETRACK_CAMERA0=$(echo "$ids" | grep 'vimc\.0' || true)
    EDGETRACK_CAMERA1=$(echo "$ids" | grep 'vimc\.1' || true)
    if [ -z "$EDGETRACK_CAMERA0" ] || [ -z "$EDGETRACK_CAMERA1" ]; then
        echo "FAILED: libcamera does not list both vimc cameras:"
        cam --list
        return 1
    fi
    export EDGETRACK_CAMERA0 EDGETRACK_CAMERA1
}
