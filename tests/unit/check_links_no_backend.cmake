# Fails when a firmware unit test binary needs libcamera or libgpiod: the firmware library links
# hal's interfaces only, so its tests build and run on any machine.
#   cmake -DREADELF=... -DBINARIES=a;b -P check_links_no_backend.cmake
foreach(binary IN LISTS BINARIES)
    execute_process(COMMAND ${READELF} -d ${binary} OUTPUT_VARIABLE dynamic RESULT_VARIABLE rc)
    if(NOT rc EQUAL 0)
        message(FATAL_ERROR "${READELF} -d ${binary} failed")
    endif()
    string(REGEX MATCHALL "NEEDED[^\n]*(camera|gpiod)[^\n]*" backends "${dynamic}")
    if(backends)
        message(FATAL_ERROR "${binary} needs a hal backend's library: ${backends}")
    endif()
endforeach()
