// Writes small valid seed inputs for the fuzzers: weights files from the training-side writer
// and frame files from writeFrame. Usage: make_fuzz_seeds <weights folder> <frames folder>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "affinity/frame.h"
#include "affinity/frame_io.h"
#include "train/weights_writer.h"

namespace {

using affinity::train::NamedTensor;

void writeWeightSeeds(const std::string& folder) {
    std::vector<NamedTensor> tensors;
    tensors.push_back({"config.version", affinity::DType::Int32, {1}, {}, {1}});
    tensors.push_back({"embed.0.weight", affinity::DType::Float32, {3, 2}, {1, -2, 3, -4, 5, -6}, {}});
    tensors.push_back({"embed.0.bias", affinity::DType::Float32, {3}, {0.5f, 0.25f, 0.125f}, {}});
    tensors.push_back({"unet.head.weight", affinity::DType::Float32, {1, 1, 1, 2}, {7, 8}, {}});
    affinity::train::writeWeightsFile(folder + "/model.affw", tensors);
    affinity::train::writeWeightsFile(folder + "/empty.affw", {});
}

void writeFrameSeeds(const std::string& folder) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> uniform(-1.0f, 2.0f);
    struct Seed {
        int width, height, spp;
        bool withReference;
        affinity::ExrCompression compression;
        const char* name;
    };
    const Seed seeds[] = {{2, 1, 1, false, affinity::ExrCompression::None, "plain.exr"},
                          {3, 2, 2, true, affinity::ExrCompression::Zip, "zip.exr"},
                          {2, 2, 1, true, affinity::ExrCompression::Piz, "piz.exr"}};
    for (const Seed& seed : seeds) {
        affinity::SampleFrame frame(seed.width, seed.height, seed.spp, seed.withReference);
        for (float& value : frame.samples()) value = uniform(rng);
        for (float& value : frame.motion()) value = uniform(rng);
        for (float& value : frame.valid()) value = uniform(rng) > 0.5f ? 1.0f : 0.0f;
        for (float& value : frame.reference()) value = uniform(rng);
        frame.info.sceneName = "seed";
        frame.info.frameIndex = 3;
        frame.info.referenceSpp = seed.withReference ? 16 : 0;
        affinity::writeFrame(folder + "/" + seed.name, frame, seed.compression);
    }
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: %s <weights folder> <frames folder>\n", argv[0]);
        return 2;
    }
    try {
        std::filesystem::create_directories(argv[1]);
        std::filesystem::create_directories(argv[2]);
        writeWeightSeeds(argv[1]);
        writeFrameSeeds(argv[2]);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "make_fuzz_seeds: %s\n", e.what());
        return 1;
    }
    return 0;
}
