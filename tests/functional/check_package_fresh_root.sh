#!/usr/bin/env bash
# The .deb as a user meets it: installed with apt into a fresh Debian root, `edgetrack --help`
# runs, and the tracker runs on the simulated board there and sends DTrack frames.
#
#   check_package_fresh_root.sh BUILD_DIR
#
# Needs root (chroot), mmdebstrap and the Debian mirror this machine's apt uses (its sources file
# is copied into the new root, so no mirror is named here). Skips (77) without them.
set -euo pipefail
build=$(cd "$1" && pwd)

if [ "$(id -u)" -ne 0 ]; then
    echo "SKIP: installing into a fresh root needs root (chroot)"
    exit 77
fi
if ! command -v mmdebstrap >/dev/null; then
    echo "SKIP: mmdebstrap is not installed (toolchain/install-deps.sh hil installs it)"
    exit 77
fi
sources=/etc/apt/sources.list.d/debian.sources
[ -f "$sources" ] || sources=/etc/apt/sources.list
if [ ! -f "$sources" ]; then
    echo "SKIP: no apt sources on this machine to build a root from"
    exit 77
fi

work=$(mktemp -d)
root="$work/root"
cleanup() {
    umount "$root/proc" 2>/dev/null || true
    rm -rf "$work"
}
trap cleanup EXIT

echo "== the package"
cpack -G DEB -B "$work/deb" --config "$build/CPackConfig.cmake" >"$work/cpack.log" 2>&1 ||
    { cat "$work/cpack.log"; exit 1; }
deb=$(ls "$work"/deb/edgetrack_*.deb)
echo "$deb"

echo "== a fresh Debian 12 root (apt, nothing else)"
mmdebstrap --variant=apt --quiet bookworm "$root" "$sources"
cp "$deb" "$root/tmp/edgetrack.deb"

echo "== apt-get install ./edgetrack.deb in it"
# mmdebstrap leaves no package lists behind: a user's apt-get update comes first.
chroot "$root" apt-get update -q >"$work/update.log" 2>&1 || { cat "$work/update.log"; exit 1; }
chroot "$root" apt-get install -y -q --no-install-recommends /tmp/edgetrack.deb >"$work/install.log" 2>&1 ||
    { cat "$work/install.log"; exit 1; }
tail -3 "$work/install.log"
mount -t proc proc "$root/proc"

echo "== edgetrack --help"
chroot "$root" edgetrack --help | head -3

echo "== edgetrack run --board sim, 300 frames, DTrack to the loopback"
chroot "$root" /bin/sh -c \
    'edgetrack run --board sim --frames 300 --udp 127.0.0.1:5000 </dev/null >/tmp/run.out 2>/tmp/run.err'
tail -5 "$root/tmp/run.out"
grep -q "frames processed *300" "$root/tmp/run.out" ||
    { echo "FAIL: run did not process 300 frames"; cat "$root/tmp/run.out" "$root/tmp/run.err"; exit 1; }
grep -Eq "udp sent +[1-9]" "$root/tmp/run.out" ||
    { echo "FAIL: no DTrack frames sent"; cat "$root/tmp/run.out"; exit 1; }
echo "ok: installed into a fresh root and ran there"
