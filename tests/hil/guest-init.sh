#!/bin/bash
# PID 1 of the hardware-test VM: brings up the simulated devices, runs the test, powers off.
#
# Run by initramfs-init.sh after switch_root into the overlay of the host's root. The test's
# command and the directory of out-of-tree modules come from the results share; the command's exit
# code goes back there as "rc".
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
results=/hil-results

power_off() {
    sync
    echo o > /proc/sysrq-trigger
    sleep 30
}

mount -t proc proc /proc
mount -t sysfs sysfs /sys
mkdir -p /dev/pts /dev/shm
mount -t devpts devpts /dev/pts
mount -t tmpfs tmpfs /dev/shm
mount -t tmpfs tmpfs /run
mount -t configfs configfs /sys/kernel/config 2> /dev/null || {
    modprobe configfs && mount -t configfs configfs /sys/kernel/config
}
hostname edgetrack-hil

setup() {
    local modules_dir
    modules_dir=$(cat "$results/modules_dir")
    # UDP: the loopback interface (no other network: -nic none).
    ip link set lo up || return 1
    # CAN: the virtual bus and raw sockets.
    modprobe -a can can-raw vcan || return 1
    # GPIO: the simulator and its interrupt helper (out of tree, see build-modules.sh).
    insmod "$modules_dir/irq_sim.ko" || return 1
    insmod "$modules_dir/gpio-sim.ko" || return 1
    # Camera: vimc and the media modules it uses from Debian's kernel.
    # shellcheck disable=SC2046 # one module name per word
    modprobe -a $(modinfo -F depends "$modules_dir/vimc.ko" | tr , ' ') || return 1
    insmod "$modules_dir/vimc.ko" || return 1
    # libcamera finds cameras through udev.
    /lib/systemd/systemd-udevd --daemon --resolve-names=never || return 1
    udevadm trigger --action=add
    udevadm settle --timeout=30
}

rc=1
if setup; then
    mapfile -t command < "$results/command"
    echo "guest: running ${command[*]}"
    "${command[@]}"
    rc=$?
else
    echo "guest: FAILED to bring up the simulated devices"
fi
echo "$rc" > "$results/rc"
power_off
