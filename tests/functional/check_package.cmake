# Builds the .deb with CPack and checks what it installs (cmake -P; BUILD_DIR, EXPECT_ARCH,
# DPKG_DEB).
set(out ${BUILD_DIR}/package-test)
file(REMOVE_RECURSE ${out})
execute_process(COMMAND ${CMAKE_CPACK_COMMAND} -G DEB -B ${out}
                WORKING_DIRECTORY ${BUILD_DIR} RESULT_VARIABLE rc OUTPUT_VARIABLE log ERROR_VARIABLE log)
if(NOT rc EQUAL 0)
    message(FATAL_ERROR "cpack failed:\n${log}")
endif()
file(GLOB debs ${out}/edgetrack_*.deb)
list(LENGTH debs count)
if(NOT count EQUAL 1)
    message(FATAL_ERROR "expected one edgetrack_*.deb in ${out}, found: ${debs}")
endif()
execute_process(COMMAND ${DPKG_DEB} --contents ${debs} OUTPUT_VARIABLE contents RESULT_VARIABLE rc)
foreach(path ./usr/bin/edgetrack ./etc/edgetrack/edgetrack.toml
        ./usr/lib/systemd/system/edgetrack.service ./usr/lib/sysusers.d/edgetrack.conf
        ./usr/share/edgetrack/edgetrack.dbc)
    string(FIND "${contents}" " ${path}\n" at)
    if(at EQUAL -1)
        message(FATAL_ERROR "the package lacks ${path}:\n${contents}")
    endif()
endforeach()
execute_process(COMMAND ${DPKG_DEB} --field ${debs} Architecture Depends
                OUTPUT_VARIABLE fields)
# Every library the program links must be in Depends, or it does not start on a fresh system
# ("libgpiod.so.2: cannot open shared object file").
foreach(package libsystemd0 libgpiod2 libcamera0.0.3 libgoogle-glog0v6 libcholmod3)
    if(NOT fields MATCHES "${package}")
        message(FATAL_ERROR "Depends lacks ${package}:\n${fields}")
    endif()
endforeach()
if(NOT fields MATCHES "Architecture: ${EXPECT_ARCH}")
    message(FATAL_ERROR "unexpected control fields:\n${fields}")
endif()
execute_process(COMMAND ${DPKG_DEB} --ctrl-tarfile ${debs} COMMAND tar -t OUTPUT_VARIABLE control)
foreach(file postinst prerm conffiles)
    if(NOT control MATCHES "${file}")
        message(FATAL_ERROR "the package's control lacks ${file}:\n${control}")
    endif()
endforeach()
message("ok: ${debs}")
