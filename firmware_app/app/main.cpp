// Entry point of the edgetrack program.
#include <iostream>
#include <new>

#include "firmware_app/app/cli.hpp"

int main(int argc, char** argv) {
    // Capacities come from the configuration, which refuses what a board cannot hold; an
    // allocation that fails all the same (a machine short of memory) ends with one line, not an
    // abort.
    try {
        return edgetrack::app::runCommandLine(argc, argv, std::cout, std::cerr);
    } catch (const std::bad_alloc&) {
        std::cout.flush();
        std::cerr << "\nedgetrack: out of memory\n";
        return 1;
    }
}
