#include "train_preroll.h"

#include <algorithm>

#include <ATen/ATen.h>

#include "affinity/error.h"

namespace affinity::train {

int prerollFrameCount(int spp, int heldSpp, int wanted) {
    if (spp < 1 || wanted < 0) throw Error("prerollFrameCount: spp must be at least 1 and wanted at least 0");
    return std::max(0, std::min(wanted, (heldSpp - spp) / spp));
}

Clip withPreroll(const Clip& clip, const std::vector<at::Tensor>& groups) {
    if (groups.empty()) return clip;
    const at::Tensor firstSamples = clip.samples[0];
    std::vector<at::Tensor> samples, motion, valid, reference;
    for (std::size_t g = 0; g < groups.size(); ++g) {
        if (groups[g].sizes() != firstSamples.sizes())
            throw Error("withPreroll: a pre-roll group must have the shape of the clip's first frame's samples");
        samples.push_back(groups[g]);
        motion.push_back(at::zeros_like(clip.motion[0]));
        valid.push_back(at::full_like(clip.valid[0], g == 0 ? 0.0 : 1.0));
        reference.push_back(clip.reference[0]);
    }
    const std::int64_t rest = clip.samples.size(0) - 1;
    samples.push_back(firstSamples);
    motion.push_back(at::zeros_like(clip.motion[0]));
    valid.push_back(at::ones_like(clip.valid[0]));
    reference.push_back(clip.reference[0]);
    Clip result{at::stack(samples), at::stack(motion), at::stack(valid), at::stack(reference)};
    if (rest > 0) {
        result.samples = at::cat({result.samples, clip.samples.narrow(0, 1, rest)});
        result.motion = at::cat({result.motion, clip.motion.narrow(0, 1, rest)});
        result.valid = at::cat({result.valid, clip.valid.narrow(0, 1, rest)});
        result.reference = at::cat({result.reference, clip.reference.narrow(0, 1, rest)});
    }
    return result;
}

}  // namespace affinity::train
