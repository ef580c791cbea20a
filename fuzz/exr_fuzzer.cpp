// Fuzz target: an OpenEXR image, read by core's readExr (OpenEXR) and compared
// with itself as `rtlab compare case.exr case.exr` does.
#include "fuzz_input.hpp"

#include <rtlab/core/image.hpp>

RTLAB_FUZZ_INITIALIZE

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::filesystem::path path = rtlab::fuzz::writeInput(data, size, "case.exr");
    rtlab::fuzz::expectingInputErrors([&] {
        const rtlab::Image image = rtlab::readExr(path);
        rtlab::compareImages(image, image);
    });
    return 0;
}
