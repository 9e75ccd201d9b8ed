# Bad inputs an integrator met, through the real command line (cmake -P; PROGRAM, WORK, and
# EMULATOR on cross builds): each must end in one line on stderr and a non-zero exit, never a
# crash, a hang or a file replaced.
file(REMOVE_RECURSE ${WORK})
file(MAKE_DIRECTORY ${WORK})

function(expect_one_line_error what pattern)
    execute_process(COMMAND ${EMULATOR} ${PROGRAM} ${ARGN} RESULT_VARIABLE code
                    OUTPUT_VARIABLE out ERROR_VARIABLE err TIMEOUT 60)
    string(REGEX MATCHALL "\n" lines "${err}")
    list(LENGTH lines count)
    if(NOT code EQUAL 1 OR NOT count EQUAL 1 OR NOT err MATCHES "${pattern}")
        message(FATAL_ERROR "${what}: expected exit 1 and one line matching '${pattern}'\n"
                            "edgetrack ${ARGN}\n--- exit ${code}\n--- stderr\n${err}")
    endif()
    message("ok: ${what}: ${err}")
endfunction()

execute_process(COMMAND ${EMULATOR} ${PROGRAM} sim --scene two_cubes --frames 3 --level images
                        --out ${WORK}/rec RESULT_VARIABLE code)
if(NOT code EQUAL 0)
    message(FATAL_ERROR "sim failed")
endif()

# A directory where a model file should be aborted on an uncaught std::ios_base::failure.
file(MAKE_DIRECTORY ${WORK}/models/body_0.json)
expect_one_line_error("a directory named like a model" "body_0.json: is a directory"
    track --models ${WORK}/models --input ${WORK}/rec --out ${WORK}/poses.csv --from images)
expect_one_line_error("model list of such a directory" "is a directory" model list
    --models ${WORK}/models)
# ... and where a .c3d file should be.
file(MAKE_DIRECTORY ${WORK}/x.c3d)
expect_one_line_error("a directory named like a C3D file" "is a directory"
    calibrate --input ${WORK}/x.c3d --out ${WORK}/learnt)
# --config DIR ran on the built-in defaults in silence.
expect_one_line_error("a directory as the configuration" "is a directory"
    reconstruct --config ${WORK}/models --input ${WORK}/rec --out ${WORK}/rec2)
# Images of a frame that frames.csv does not list were skipped in silence.
file(COPY_FILE ${WORK}/rec/images/000001_0.pgm ${WORK}/rec/images/000007_0.pgm)
expect_one_line_error("an image of a frame not in frames.csv"
    "000007_0.pgm: frame 7 is not in frames.csv"
    reconstruct --input ${WORK}/rec --out ${WORK}/rec3)
