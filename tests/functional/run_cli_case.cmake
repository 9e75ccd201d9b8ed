# Runs one edgetrack command line and checks its exit code and output (a functional test case).
#
# -DEMULATOR=...   optional ;-list run before the program (qemu-aarch64 on cross builds)
# -DPROGRAM=...    the edgetrack binary
# -DARGS=...       ;-list of arguments
# -DEXPECT_EXIT=N  expected exit code
# -DEXPECT_STDOUT=regex, -DEXPECT_STDERR=regex   optional patterns the streams must match
# -DSTDERR_ONE_LINE=ON   stderr must be exactly one line
# -DCLEAN_DIR=path       removed before the run, so the case starts from nothing
# -DEXPECT_FILES=a;b     files (relative to CLEAN_DIR) that must exist afterwards
if(DEFINED CLEAN_DIR)
    file(REMOVE_RECURSE "${CLEAN_DIR}")
endif()
execute_process(COMMAND ${EMULATOR} ${PROGRAM} ${ARGS}
                RESULT_VARIABLE exit_code
                OUTPUT_VARIABLE out
                ERROR_VARIABLE err)
set(shown "edgetrack ${ARGS}\n--- exit ${exit_code}\n--- stdout\n${out}--- stderr\n${err}")
if(NOT exit_code STREQUAL EXPECT_EXIT)
    message(FATAL_ERROR "expected exit ${EXPECT_EXIT}\n${shown}")
endif()
if(DEFINED EXPECT_STDOUT AND NOT out MATCHES "${EXPECT_STDOUT}")
    message(FATAL_ERROR "stdout does not match '${EXPECT_STDOUT}'\n${shown}")
endif()
if(DEFINED EXPECT_STDERR AND NOT err MATCHES "${EXPECT_STDERR}")
    message(FATAL_ERROR "stderr does not match '${EXPECT_STDERR}'\n${shown}")
endif()
if(STDERR_ONE_LINE)
    string(REGEX MATCHALL "\n" newlines "${err}")
    list(LENGTH newlines lines)
    if(NOT lines EQUAL 1)
        message(FATAL_ERROR "stderr should be one line, has ${lines}\n${shown}")
    endif()
endif()
foreach(expected IN LISTS EXPECT_FILES)
    if(NOT EXISTS "${CLEAN_DIR}/${expected}")
        message(FATAL_ERROR "missing ${CLEAN_DIR}/${expected}\n${shown}")
    endif()
endforeach()
