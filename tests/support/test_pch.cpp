// Gives the unit tests' shared precompiled header (tests/CMakeLists.txt) a target to be built in.
