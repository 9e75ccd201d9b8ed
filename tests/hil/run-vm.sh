#!/usr/bin/env bash
# Runs one hardware test inside a qemu virtual machine on Debian's kernel, with real drivers.
#
#   tests/hil/run-vm.sh WORK_DIR GUEST_SCRIPT [ARGS...]
#
# The guest boots Debian's own kernel under qemu (TCG: KVM does not work on our CI machines),
# mounts the host's / read-only over 9p with a tmpfs overlay on top (so it runs the binaries just
# built, at their host paths, without a disk image), loads vcan, gpio-sim and vimc, starts udev
# and runs GUEST_SCRIPT ARGS as root. The script's exit code comes back through a second,
# writable 9p share and becomes this script's exit code; a guest that hangs is killed after
# EDGETRACK_HIL_TIMEOUT seconds (default 240) and fails. Exits 77 with the reason when qemu,
# the kernel image or its modules are missing (toolchain/install-deps.sh hil installs them).
set -euo pipefail

if [ $# -lt 2 ]; then
    echo "usage: $0 WORK_DIR GUEST_SCRIPT [ARGS...]" >&2
    exit 2
fi
work_dir=$(realpath -m "$1")
shift
here=$(cd "$(dirname "$0")" && pwd)
timeout_s=${EDGETRACK_HIL_TIMEOUT:-240}

skip() {
    echo "SKIP: $*"
    exit 77
}

command -v qemu-system-x86_64 > /dev/null || skip "qemu-system-x86_64 not installed (qemu-system-x86)"
[ "$(uname -m)" = x86_64 ] || skip "the VM suite runs on x86-64 hosts only"
command -v busybox > /dev/null || skip "busybox not installed (busybox-static)"
command -v cpio > /dev/null || skip "cpio not installed"
# The kernel whose modules are installed, not the running one (a container's kernel has none).
kernel_version=""
for dir in /lib/modules/*/; do
    version=$(basename "$dir")
    if [ -r "/boot/vmlinuz-$version" ] && [ -d "$dir/kernel" ]; then
        kernel_version=$version
    fi
done
[ -n "$kernel_version" ] || skip "no readable /boot/vmlinuz-* with modules (linux-image-amd64)"

mkdir -p "$work_dir"
# Tests run two at a time: the first prepares the modules and the initramfs, the other waits
# for it here (the lock goes with this script's exit too).
exec 9> "$work_dir/prepare.lock"
flock 9
modules_dir=$work_dir/modules-$kernel_version
status=0
"$here/build-modules.sh" "$kernel_version" "$modules_dir" || status=$?
[ "$status" -eq 0 ] || exit "$status"

# The initramfs: busybox and the modules that mount the 9p shares and the overlay.
initramfs=$work_dir/initramfs-$kernel_version.cpio.gz
initramfs_stamp="$kernel_version $(sha256sum "$here/initramfs-init.sh" | cut -c1-16)"
if [ ! -f "$initramfs" ] || [ "$(cat "$initramfs.stamp" 2>/dev/null)" != "$initramfs_stamp" ]; then
    tree=$(mktemp -d)
    mkdir -p "$tree"/{bin,dev,proc,sys,lower,upper,newroot,modules}
    cp "$(command -v busybox)" "$tree/bin/busybox"
    cp "$here/initramfs-init.sh" "$tree/init"
    chmod +x "$tree/init"
    modprobe -S "$kernel_version" --show-depends -a virtio_pci 9pnet_virtio 9p overlay |
        awk '$1 == "insmod" { print $2 }' | awk '!seen[$0]++' > "$tree/modules/order.full"
    while read -r module; do
        cp "$module" "$tree/modules/"
        basename "$module" >> "$tree/modules/order"
    done < "$tree/modules/order.full"
    (cd "$tree" && find . | cpio -o -H newc --quiet | gzip -1) > "$initramfs"
    rm -rf "$tree"
    echo "$initramfs_stamp" > "$initramfs.stamp"
fi
flock -u 9

results=$(mktemp -d "$work_dir/results.XXXXXX")
trap 'rm -rf "$results"' EXIT
# The guest's command, one argument per line (paths with spaces survive).
printf '%s\n' "$@" > "$results/command"
echo "$modules_dir" > "$results/modules_dir"

echo "hil: booting $kernel_version under qemu (TCG) for: $*"
qemu_status=0
timeout -s KILL "$timeout_s" qemu-system-x86_64 \
    -accel tcg -cpu max -smp 1 -m 1024 -nographic -nic none -no-reboot -monitor none -serial stdio \
    -kernel "/boot/vmlinuz-$kernel_version" -initrd "$initramfs" \
    -append "console=ttyS0 panic=-1 quiet loglevel=4 edgetrack.init=$here/guest-init.sh" \
    -virtfs local,path=/,mount_tag=hostroot,security_model=none,multidevs=remap,readonly=on \
    -virtfs "local,path=$results,mount_tag=results,security_model=none" \
    < /dev/null || qemu_status=$?

if [ ! -f "$results/rc" ]; then
    if [ "$qemu_status" -eq 137 ]; then
        echo "hil: FAILED: the guest did not finish within ${timeout_s} s and was killed"
    else
        echo "hil: FAILED: the guest left no exit code (qemu exited with $qemu_status)"
    fi
    exit 1
fi
rc=$(cat "$results/rc")
echo "hil: guest exit code $rc"
exit "$rc"
