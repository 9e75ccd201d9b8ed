# CMake toolchain: cross build for the board (Cortex-A72/A76) with Debian's g++-aarch64-linux-gnu.
#
# Libraries come from Debian's arm64 multiarch packages (libgtest-dev:arm64, ...), installed by
# toolchain/install-deps.sh aarch64. Tests run under qemu-aarch64 (package qemu-user) with a hard
# time limit, because qemu-user ignores SIGTERM when a guest spins (see toolchain/README.md).
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)

set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)

# Cortex-A72 is the oldest core we ship on; the code runs unchanged on the A76.
set(CMAKE_C_FLAGS_INIT "-mcpu=cortex-a72")
set(CMAKE_CXX_FLAGS_INIT "-mcpu=cortex-a72")

# The multiarch libraries live in the host's own root, under lib/aarch64-linux-gnu; Ceres, glog
# and gflags, whose arm64 -dev packages cannot be installed beside the host's, are unpacked under
# /opt/edgetrack-arm64 (toolchain/install-deps.sh aarch64).
set(CMAKE_FIND_ROOT_PATH /usr/aarch64-linux-gnu /usr /opt/edgetrack-arm64/usr)
list(APPEND CMAKE_PREFIX_PATH /opt/edgetrack-arm64/usr)
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE BOTH)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE BOTH)
set(ENV{PKG_CONFIG_LIBDIR} "/usr/lib/aarch64-linux-gnu/pkgconfig:/usr/share/pkgconfig")

# Plain qemu-aarch64 with the multiarch loader; never "-L /usr/aarch64-linux-gnu" (it mixes two
# C libraries). SIGKILL after 580 s so a spinning guest cannot hang CI: the emulator runs about
# 22 times slower than the host, and a whole calibration of the real Vicon recording in two point
# orders takes 10 s on the host.
# The guest's loader finds the unpacked Ceres, glog and gflags through LD_LIBRARY_PATH (a
# binary's RUNPATH does not reach a library's own dependencies, such as glog's gflags).
find_program(EDGETRACK_QEMU_AARCH64 qemu-aarch64)
if(EDGETRACK_QEMU_AARCH64)
    set(CMAKE_CROSSCOMPILING_EMULATOR timeout -s KILL 580 ${EDGETRACK_QEMU_AARCH64}
        -E LD_LIBRARY_PATH=/opt/edgetrack-arm64/usr/lib/aarch64-linux-gnu)
endif()
