// libFuzzer target: readFrame on arbitrary bytes written to a file, into the frame and into bands
// of rows. Rejection with
// affinity::Error is the expected outcome; any other exception, a crash, a leak or undefined
// behaviour (ours or OpenEXR's) is a finding.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "affinity/error.h"
#include "affinity/frame_io.h"

namespace {

// One file per fuzzing process, rewritten for every input.
const std::string& scratchPath() {
    static const std::string path = [] {
        const char* folder = std::getenv("TMPDIR");
        std::string name = std::string(folder != nullptr && *folder != '\0' ? folder : "/tmp") +
                           "/affinity_fuzz_frame_" + std::to_string(::getpid()) + ".exr";
        std::atexit([] { std::remove(scratchPath().c_str()); });
        return name;
    }();
    return path;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string& path = scratchPath();
    std::FILE* file = std::fopen(path.c_str(), "wb");
    if (file == nullptr) std::abort();  // the harness itself is broken, not the reader
    if (size > 0 && std::fwrite(data, 1, size, file) != size) std::abort();
    if (std::fclose(file) != 0) std::abort();
    try {
        const affinity::SampleFrame frame = affinity::readFrame(path);
        // Touch the buffers so that a frame with inconsistent sizes shows up.
        float sum = 0.0f;
        for (const float value : frame.samples()) sum += value;
        for (const float value : frame.motion()) sum += value;
        volatile float sink = sum;
        (void)sink;
    } catch (const affinity::Error&) {}
    // Again into two bands of rows (as `affinity denoise` reads into a denoiser's memory).
    try {
        std::vector<float> top, bottom;
        const affinity::SampleFrame frame = affinity::readFrame(path, [&](int width, int height, int spp) {
            const std::size_t rowValues = std::size_t(width) * std::size_t(spp) * affinity::kFeatureCount;
            const int half = (height + 1) / 2;
            top.assign(std::size_t(half) * rowValues, 0.0f);
            bottom.assign(std::size_t(height - half) * rowValues, 0.0f);
            std::vector<affinity::SampleBand> bands{{0, half, top.data()}};
            if (height > half) bands.push_back({half, height - half, bottom.data()});
            return bands;
        });
        float sum = 0.0f;
        for (const float value : top) sum += value;
        for (const float value : bottom) sum += value;
        for (const float value : frame.valid()) sum += value;
        volatile float sink = sum;
        (void)sink;
    } catch (const affinity::Error&) {}
    return 0;
}
