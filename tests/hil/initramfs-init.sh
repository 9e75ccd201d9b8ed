#!/bin/busybox sh
# The hardware-test VM's first process: mounts the host's root read-only with a writable overlay.
/bin/busybox --install -s /bin
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t devtmpfs devtmpfs /dev

fail() {
    echo "initramfs: $*"
    echo o > /proc/sysrq-trigger
    sleep 10
}

while read -r module; do
    insmod "/modules/$module" || fail "cannot load $module"
done < /modules/order

# Large messages and a page cache make the shared root fast; it does not change under the guest.
mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000,cache=loose,ro hostroot /lower ||
    fail "cannot mount the host's root"
mount -t tmpfs -o size=512m tmpfs /upper
mkdir -p /upper/data /upper/work
mount -t overlay overlay -o lowerdir=/lower,upperdir=/upper/data,workdir=/upper/work /newroot ||
    fail "cannot mount the overlay"
mkdir -p /newroot/hil-results
mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000 results /newroot/hil-results ||
    fail "cannot mount the results share"

init=""
for word in $(cat /proc/cmdline); do
    case "$word" in
    edgetrack.init=*) init=${word#edgetrack.init=} ;;
    esac
done
[ -n "$init" ] || fail "no edgetrack.init= on the kernel command line"

umount /proc /sys
mount --move /dev /newroot/dev
exec switch_root /newroot /bin/bash "$init"
