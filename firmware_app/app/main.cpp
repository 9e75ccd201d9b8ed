// Entry point of the edgetrack program.
#include <iostream>

#include "firmware_app/app/cli.hpp"

int main(int argc, char** argv) {
    return edgetrack::app::runCommandLine(argc, argv, std::cout, std::cerr);
}
