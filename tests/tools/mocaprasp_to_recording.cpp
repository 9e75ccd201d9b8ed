// Command-line wrapper: mocaprasp_to_recording LOG.csv CONSTANTS.py OUT_RECORDING.
#include <iostream>

#include "tests/tools/mocaprasp.hpp"

int main(int argc, char** argv) {
    if (argc != 4) {
        std::cerr << "usage: mocaprasp_to_recording LOG.csv constants.py OUT_RECORDING\n";
        return 2;
    }
    const auto result = edgetrack::test::convertMoCapRasp(argv[1], argv[2], argv[3]);
    if (!result) {
        std::cerr << "mocaprasp_to_recording: " << result.error().message << "\n";
        return 1;
    }
    std::cout << "wrote " << argv[3] << ": " << result->frames << " frames ("
              << result->framesBothCameras << " seen by both cameras), " << result->blobsPerCamera
              << " blobs per image\n";
    return 0;
}
