#include "affinity/denoise_file.h"

#include <chrono>

#include "affinity/frame_io.h"

namespace affinity {

DenoisedFile denoiseFrameFile(Denoiser& denoiser, const std::string& path, NoisyMean noisy, DenoiseReport* report) {
    DenoisedFile result;
    std::vector<SampleBand> bands;
    try {
        result.frame = readFrame(
            path, [&](int width, int height, int spp) { return bands = denoiser.sampleBands(width, height, spp); });
    } catch (...) {
        if (!bands.empty()) denoiser.discardSamples();
        throw;
    }
    const SampleFrame& frame = result.frame;
    if (noisy == NoisyMean::Always || (noisy == NoisyMean::WithReference && frame.hasReference()))
        result.noisy = meanRadiance(bands, frame.width(), frame.height(), frame.spp());
    const auto start = std::chrono::steady_clock::now();
    result.denoised = denoiser.finishFrame(frame.motion().data(), frame.valid().data(), frame.info, report);
    result.denoiseMilliseconds =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return result;
}

}  // namespace affinity
