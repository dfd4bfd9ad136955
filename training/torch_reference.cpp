#include "torch_reference.h"

#include <torch/utils.h>

#include "affinity/error.h"
#include "affinity/features.h"
#include "affinity/weights.h"
#include "affinity_model.h"
#include "model_weights.h"

namespace affinity::train {
namespace {

// Frame layout (samples [y][x][s][f], motion [y][x][2], valid [y][x]) to the model's tensors.
FrameInput toTensors(const SampleFrame& frame) {
    const std::int64_t height = frame.height(), width = frame.width(), spp = frame.spp();
    auto view = [](const std::vector<float>& data, std::vector<std::int64_t> shape) {
        return torch::from_blob(const_cast<float*>(data.data()), shape, torch::kFloat);
    };
    FrameInput input;
    input.samples =
        view(frame.samples(), {height, width, spp, kFeatureCount}).permute({2, 3, 0, 1}).unsqueeze(0).clone();
    input.motion = view(frame.motion(), {height, width, 2}).permute({2, 0, 1}).unsqueeze(0).clone();
    input.valid = view(frame.valid(), {1, 1, height, width}).clone();
    return input;
}

}  // namespace

std::vector<std::vector<float>> torchDenoiseSequence(const std::string& weightsPath,
                                                     const std::vector<SampleFrame>& frames) {
    const Weights weights = Weights::fromFile(weightsPath);
    AffinityModel model = modelFromWeights(weights);
    model->eval();
    torch::NoGradGuard noGrad;

    std::vector<std::vector<float>> outputs;
    RecurrentState state;
    for (std::size_t t = 0; t < frames.size(); ++t) {
        const SampleFrame& frame = frames[t];
        if (frame.pixelCount() == 0 ||
            frame.samples().size() != frame.pixelCount() * std::size_t(frame.spp()) * kFeatureCount) {
            throw Error("torchDenoiseSequence: frame " + std::to_string(t) + " is empty or inconsistent");
        }
        if (t > 0 && (frame.width() != frames[0].width() || frame.height() != frames[0].height())) {
            throw Error("torchDenoiseSequence: frame " + std::to_string(t) + " is " + std::to_string(frame.width()) +
                        "x" + std::to_string(frame.height()) + ", the first frame " +
                        std::to_string(frames[0].width()) + "x" + std::to_string(frames[0].height()));
        }
        const torch::Tensor output = model->forwardFrame(toTensors(frame), state).output;
        const torch::Tensor pixels = output.squeeze(0).permute({1, 2, 0}).contiguous();  // [H][W][3]
        outputs.emplace_back(pixels.data_ptr<float>(), pixels.data_ptr<float>() + pixels.numel());
    }
    return outputs;
}

void writeInitialModel(const ModelConfig& config, std::uint64_t seed, const std::string& path) {
    exportWeights(makeModel(config, seed), path);
}

}  // namespace affinity::train
