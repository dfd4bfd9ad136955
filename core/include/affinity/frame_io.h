#pragma once
// Frame files: one OpenEXR file per frame holding every sample's features, the per-pixel
// motion / validity / reference and the metadata. The channel naming scheme is documented in
// docs/FRAME_FILES.md. Writes are atomic; reads reject anything incomplete with an
// affinity::Error naming the file and the problem.
#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#include "affinity/frame.h"

namespace affinity {

enum class ExrCompression { None, Zip, Piz };

// Writes to a temporary file beside `path`, then renames it over `path`.
void writeFrame(const std::string& path, const SampleFrame& frame, ExrCompression compression = ExrCompression::Piz);
SampleFrame readFrame(const std::string& path);
// The same with the samples read into the bands bandsFor(width, height, spp) returns, which
// must cover the rows in order, instead of into the frame, whose samples() stays empty: for a
// reader that hands them on (Denoiser::sampleBands), so that they are never held twice.
using SampleBandsFor = std::function<std::vector<SampleBand>(int width, int height, int spp)>;
SampleFrame readFrame(const std::string& path, const SampleBandsFor& bandsFor);
// About how many bytes writeFrame() holds besides the frame itself while it writes a frame of
// this size (OpenEXR's line buffers and compressors): for checking a run's memory before it
// starts; an estimate a little above what OpenEXR 3.1 was measured to hold (frame_io.cpp).
std::size_t frameWriteBufferBytes(int width, int height, int spp, bool withReference, ExrCompression compression);

// "frame_0007.exr" for index 7: the name every sequence folder uses.
std::string frameFileName(int frameIndex);
// The frame files of a sequence folder in frame order (throws if the folder does not exist).
std::vector<std::string> listFrameFiles(const std::string& directory);

}  // namespace affinity
