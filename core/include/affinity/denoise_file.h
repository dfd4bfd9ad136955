#pragma once
// A frame file denoised as the next frame of a sequence, its samples read straight into the
// bands the denoiser lends (Denoiser::sampleBands), so that they are never held beside all of the
// denoiser's buffers: what `affinity denoise` and Python's Denoiser.denoise_file do.
#include <string>
#include <vector>

#include "affinity/denoiser.h"
#include "affinity/frame.h"

namespace affinity {

struct DenoisedFile {
    SampleFrame frame;               // as readFrame() gives it, without samples
    std::vector<float> noisy;        // the samples' mean radiance [y][x][3], where asked for
    std::vector<float> denoised;     // [y][x][3], bit for bit denoiser.denoise(readFrame(path))
    double denoiseMilliseconds = 0;  // finishFrame() alone, the read excluded
};

// When to make DenoisedFile::noisy (a pass over the samples): for metrics against the reference.
enum class NoisyMean { Never, WithReference, Always };

// Throws affinity::Error (naming the file) as readFrame() and Denoiser::finishFrame() do; a read
// that fails after the bands were lent leaves nothing waiting in the denoiser.
DenoisedFile denoiseFrameFile(Denoiser& denoiser, const std::string& path, NoisyMean noisy,
                              DenoiseReport* report = nullptr);

}  // namespace affinity
