#include "train_augment.h"

#include <ATen/ATen.h>

#include <algorithm>
#include <numeric>
#include <vector>

#include "affinity/features.h"

namespace affinity::train {

Augmentation randomAugmentation(std::mt19937_64& rng) {
    std::uniform_int_distribution<int> bit(0, 1);
    Augmentation augmentation;
    augmentation.transpose = bit(rng);
    augmentation.flipX = bit(rng);
    augmentation.flipY = bit(rng);
    std::shuffle(augmentation.colours.begin(), augmentation.colours.end(), rng);
    return augmentation;
}

void applyAugmentation(Clip& clip, const Augmentation& augmentation) {
    if (augmentation.transpose) {
        clip.samples = clip.samples.transpose(-1, -2);
        clip.motion = clip.motion.transpose(-1, -2).flip({1});  // (dx, dy) -> (dy, dx)
        clip.valid = clip.valid.transpose(-1, -2);
        clip.reference = clip.reference.transpose(-1, -2);
    }
    if (augmentation.flipX || augmentation.flipY) {
        std::vector<std::int64_t> dims;
        if (augmentation.flipX) dims.push_back(-1);
        if (augmentation.flipY) dims.push_back(-2);
        const at::Tensor sign =
            at::tensor(std::vector<float>{augmentation.flipX ? -1.0f : 1.0f, augmentation.flipY ? -1.0f : 1.0f},
                       clip.motion.options())
                .view({1, 2, 1, 1});
        clip.samples = clip.samples.flip(dims);
        clip.motion = clip.motion.flip(dims) * sign;
        clip.valid = clip.valid.flip(dims);
        clip.reference = clip.reference.flip(dims);
    }
    std::vector<std::int64_t> channels(kFeatureCount);
    std::iota(channels.begin(), channels.end(), 0);
    for (std::size_t c = 0; c < 3; ++c) {
        const std::int64_t source = augmentation.colours[c];
        channels[std::size_t(channel::kDiffuse) + c] = channel::kDiffuse + source;
        channels[std::size_t(channel::kSpecular) + c] = channel::kSpecular + source;
        channels[std::size_t(channel::kAlbedo) + c] = channel::kAlbedo + source;
    }
    const at::TensorOptions indexOptions = at::TensorOptions().dtype(at::kLong).device(clip.samples.device());
    clip.samples = clip.samples.index_select(2, at::tensor(channels, indexOptions));
    clip.reference = clip.reference.index_select(
        1,
        at::tensor(std::vector<std::int64_t>(augmentation.colours.begin(), augmentation.colours.end()), indexOptions));
}

}  // namespace affinity::train
