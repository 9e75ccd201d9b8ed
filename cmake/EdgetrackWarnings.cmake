# Compiler warnings for edgetrack's own targets: all of them are errors.
# (-Wnull-dereference is left out: GCC 12 reports false positives inside libstdc++ at -O2.)
add_library(edgetrack_warnings INTERFACE)
target_compile_options(edgetrack_warnings INTERFACE
    -Wall -Wextra -Wpedantic -Wconversion -Wsign-conversion -Wshadow
    -Wnon-virtual-dtor -Wold-style-cast -Wcast-align -Woverloaded-virtual
    -Wdouble-promotion -Wformat=2 -Wimplicit-fallthrough
    -Werror)
