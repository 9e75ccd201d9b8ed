#!/usr/bin/env bash
# Installs edgetrack's build and test dependencies from Debian 12 packages (run as root).
#
#   toolchain/install-deps.sh               host build, tests and benchmarks
#   toolchain/install-deps.sh aarch64       also the cross compiler, qemu-user and arm64 libraries
#   toolchain/install-deps.sh aarch64 hil   also the hardware-test VM (tests/hil): qemu-system,
#                                           Debian's kernel, its headers and sources, can-utils,
#                                           gpiod and libcamera's tools (cam) and IPA modules; and
#                                           mmdebstrap, for the package test in a fresh root
set -euo pipefail

if [ "$(id -u)" -ne 0 ]; then
    echo "install-deps.sh: run as root (sudo $0 $*)" >&2
    exit 1
fi
export DEBIAN_FRONTEND=noninteractive
apt_install() { apt-get install -y -q --no-install-recommends "$@"; }

host_packages=(
    build-essential cmake ninja-build pkg-config git clang-format
    clang
    libeigen3-dev libtomlplusplus-dev libcli11-dev libsimde-dev nlohmann-json3-dev
    zlib1g-dev libsystemd-dev libgpiod-dev libcamera-dev
    libopencv-imgproc-dev
    libgtest-dev libgmock-dev libbenchmark-dev
    libceres-dev
)

apt-get update -q
apt_install "${host_packages[@]}"

# Test only: an independent DBC decoder (the npm package candied) reads run --can-log's output.
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
    apt_install nodejs npm
fi
(cd "$(dirname "$0")/../tests/functional/can_log_decode" && npm ci --no-audit --no-fund)

want() {
    local word
    for word in "${requested[@]}"; do
        [ "$word" = "$1" ] && return 0
    done
    return 1
}
requested=("$@")
for word in "${requested[@]}"; do
    case "$word" in
    aarch64 | hil) ;;
    *)
        echo "install-deps.sh: unknown part '$word' (aarch64, hil)" >&2
        exit 2
        ;;
    esac
done

if want hil; then
    # The VM boots Debian's own kernel; gpio-sim and vimc are built from its sources against its
    # headers (tests/hil/build-modules.sh), so image, headers and sources must be one version.
    apt_install qemu-system-x86 linux-image-amd64 linux-headers-amd64 linux-source-6.1 \
        busybox-static cpio kmod udev iproute2 can-utils xz-utils gpiod libcamera-ipa libcamera-tools \
        mmdebstrap
fi

if want aarch64; then
    # Debian's multiarch arm64 -dev packages link the cross build; qemu-user runs its tests.
    if ! dpkg --print-foreign-architectures | grep -qx arm64; then
        dpkg --add-architecture arm64
        apt-get update -q
    fi
    apt_install g++-aarch64-linux-gnu qemu-user \
        libc6:arm64 libstdc++6:arm64 \
        libgtest-dev:arm64 libgmock-dev:arm64 libbenchmark-dev:arm64 \
        zlib1g-dev:arm64 libsystemd-dev:arm64 libgpiod-dev:arm64 libcamera-dev:arm64 \
        libsuitesparse-dev:arm64 libatlas-base-dev:arm64 liblapack3:arm64 libunwind8:arm64
    # Ceres for arm64: Debian's glog and gflags packages are not multiarch, so their arm64 -dev
    # packages cannot sit beside the host's. Ceres, glog and gflags for arm64 are unpacked under
    # /opt/edgetrack-arm64 instead (their other libraries above are multiarch); the toolchain
    # file searches there, and the test binaries find the libraries through their RUNPATH.
    arm64_prefix=/opt/edgetrack-arm64
    debs=$(mktemp -d)
    chmod 755 "$debs"
    (cd "$debs" && apt-get download libceres-dev:arm64 libceres3:arm64 libgoogle-glog-dev:arm64 \
        libgoogle-glog0v6:arm64 libgflags-dev:arm64 libgflags2.2:arm64)
    rm -rf "$arm64_prefix"
    for deb in "$debs"/*.deb; do
        dpkg-deb -x "$deb" "$arm64_prefix"
    done
    rm -rf "$debs"
fi
