# Third-party dependencies, all from Debian packages (see toolchain/install-deps.sh).
find_package(Eigen3 3.4 REQUIRED NO_MODULE)
find_package(CLI11 REQUIRED)
find_package(ZLIB REQUIRED)
find_package(Threads REQUIRED)
# sd_notify: READY=1 and the watchdog of the systemd unit (deploy/edgetrack.service).
find_package(PkgConfig REQUIRED)
pkg_check_modules(LIBSYSTEMD REQUIRED IMPORTED_TARGET libsystemd)
# The LED ring strobe, button and status LED (hal/linux). Debian 12 ships libgpiod 1.6: v1 API.
pkg_check_modules(LIBGPIOD REQUIRED IMPORTED_TARGET libgpiod>=1.6)
pkg_check_modules(LIBCAMERA REQUIRED IMPORTED_TARGET libcamera>=0.0.3)
# Bundle adjustment of rig calibration by wand (core/rig_calibration). For the aarch64 build its
# arm64 package comes unpacked under /opt/edgetrack-arm64 (toolchain/install-deps.sh aarch64).
find_package(Ceres 2.1 REQUIRED)

# toml++ from its headers, so the host's package serves every target architecture. Its
# implementation is compiled once, in edgetrack_toml, not in every file that reads TOML (Debian's
# shared libtomlplusplus is built with exceptions, which our code does not use).
find_path(TOMLPLUSPLUS_INCLUDE_DIR toml++/toml.h REQUIRED)
add_library(edgetrack_toml STATIC ${CMAKE_CURRENT_LIST_DIR}/toml_implementation.cpp)
target_include_directories(edgetrack_toml SYSTEM PUBLIC ${TOMLPLUSPLUS_INCLUDE_DIR})
target_compile_definitions(edgetrack_toml PUBLIC TOML_HEADER_ONLY=0 TOML_EXCEPTIONS=0)

# nlohmann/json reads and writes the model files of INTERFACES §4 (offline tools only; the board
# keeps models in its own binary format). Header-only like toml++.
find_path(NLOHMANN_JSON_INCLUDE_DIR nlohmann/json.hpp REQUIRED)
add_library(nlohmann_json_header_only INTERFACE)
target_include_directories(nlohmann_json_header_only SYSTEM INTERFACE ${NLOHMANN_JSON_INCLUDE_DIR})

# NEON intrinsics: native on aarch64, translated by SIMDe everywhere else.
if(NOT CMAKE_SYSTEM_PROCESSOR MATCHES "^(aarch64|arm64|ARM64)$")
    find_path(SIMDE_INCLUDE_DIR simde/arm/neon.h REQUIRED)
    add_library(simde_neon INTERFACE)
    target_include_directories(simde_neon SYSTEM INTERFACE ${SIMDE_INCLUDE_DIR})
    target_compile_definitions(simde_neon INTERFACE EDGETRACK_NEON_VIA_SIMDE=1)
    set(EDGETRACK_NEON_BACKEND "SIMDe")
else()
    add_library(simde_neon INTERFACE)
    set(EDGETRACK_NEON_BACKEND "native")
endif()
message(STATUS "edgetrack: NEON intrinsics ${EDGETRACK_NEON_BACKEND}")

if(EDGETRACK_BUILD_TESTS)
    find_package(GTest REQUIRED)
    include(GoogleTest)
endif()
if(EDGETRACK_BUILD_BENCHMARKS)
    find_package(benchmark REQUIRED)
endif()
