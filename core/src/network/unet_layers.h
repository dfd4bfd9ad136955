#pragma once
// The U-Net's layers on NHWC FeatureMaps: 3x3 and 1x1 convolutions (optionally reading the
// channel concatenation of two inputs without copying it), 2x2 max pooling with ceil mode,
// nearest-neighbour upsampling. Semantics: docs/MODEL.md section 4. Multithreaded (OpenMP)
// and vectorised; results do not depend on the thread count.
#include <optional>

#include "kernels/conv_kernel.h"
#include "kernels/feature_map.h"
#include "kernels/upsampled_conv.h"
#include "kernels/winograd_conv.h"

namespace affinity {

// Output columns per unit of work: a tile's input rows stay in L2 while each channel block's
// weights stay in L1. Row-fused callers of Conv2d::applyRow use it too.
inline constexpr int kConvTileWidth = 128;

// How a 3x3 layer computes whole images (apply, applyUpsampled) and row groups: directly, or in
// the Winograd form of winograd_conv.h (36 multiply-adds per 4x4 pixels and channel pair instead
// of 144; equal up to float rounding). applyRow always runs the direct form. A layer with a folded
// upsampled input runs its skip part in the Winograd form whatever `form` says.
enum class ConvForm { Direct, Winograd };

// A convolution's weights, repacked once at load time for the kernel's access pattern.
class Conv2d {
public:
    // torchWeights: [outChannels][inChannels][size][size] (torch layout); size is 1 or 3.
    // bias: [outChannels]. Throws affinity::Error on an unsupported shape. `isa` picks the
    // kernel's vector width (the results are bitwise the same). A decoder layer passes
    // `upsampledChannels` > 0, the channel count of the coarse level it reads upsampled
    // (applyUpsampled, or applyRow with an upsampled first source of that many channels): those
    // run the folded form of upsampled_conv.h, equal up to float rounding, with 4 taps instead
    // of 9 over the coarse channels. `form` Winograd needs size 3 and no folded input.
    // `precision` BFloat16 takes the Winograd forms' products and a 1x1 layer's in bfloat16
    // (winograd_products.h, bf16_gemm.h), where the input channel count is even.
    Conv2d(const float* torchWeights, const float* bias, int outChannels, int inChannels, int size,
           ConvIsa isa = defaultConvIsa(), int upsampledChannels = 0, ConvForm form = ConvForm::Direct,
           Precision precision = Precision::Float32);

    int inChannels() const { return packed_.inChannels(); }
    int outChannels() const { return packed_.outChannels(); }
    int size() const { return packed_.size(); }

    // output = act(conv(input) + bias), zero padding (size / 2). output is resized and must
    // not be the input. Throws affinity::Error when the input's channel count does not match.
    void apply(const FeatureMap& input, Activation activation, FeatureMap& output) const;
    // The same on concat(first, second) along channels (first's channels first): what the
    // decoder does with its skip connections, without materialising the concatenation.
    // Bitwise equal to apply() on the explicit concatenation (in either form).
    void apply(const FeatureMap& first, const FeatureMap& second, Activation activation, FeatureMap& output) const;
    // The same on concat(upsampleNearest(coarse), skip), output the skip's size, without
    // materialising the upsampled map; coarse must be exactly ceil(h / 2) x ceil(w / 2).
    // Bitwise equal to upsampleNearest followed by the two-input apply(), unless the layer was
    // built with upsampledChannels = coarse.channels() (then equal up to float rounding).
    void applyUpsampled(const FeatureMap& coarse, const FeatureMap& skip, Activation activation,
                        FeatureMap& output) const;
    // Columns [x0, x1) of output row y for height x width images, on the calling thread, into
    // outRow (row y's column 0 of an NHWC image with outChannels() channels, or a buffer of
    // width x outChannels() floats): for fusing a layer with what consumes its rows. Results
    // equal apply()'s (up to float rounding in the Winograd form). Throws affinity::Error when
    // the channel counts or the range are wrong.
    void applyRow(const ConvSource* sources, int sourceCount, int height, int width, int y, int x0, int x1,
                  Activation activation, float* outRow) const;
    // Rows y0 + r, r < kWinogradRows (y0 a multiple of it), columns [x0, x1), the same way:
    // into rows[r] (column 0 of an NHWC row), null exactly for the rows past the image. A group
    // is what the Winograd form computes at once; the results equal apply()'s bit for bit in
    // every form.
    void applyRowGroup(const ConvSource* sources, int sourceCount, int height, int width, int y0, int x0, int x1,
                       Activation activation, float* const* rows) const;

private:
    void run(const ConvSource* sources, int sourceCount, int height, int width, Activation activation,
             FeatureMap& output) const;
    // Whether the folded form applies to these sources.
    bool folds(const ConvSource* sources, int sourceCount) const;
    void checkRowInputs(const ConvSource* sources, int sourceCount, int height, int width, int y, int x0, int x1) const;
    // A group of rows (null past the image), through the folded or Winograd form where they apply.
    void rowGroup(const ConvSource* sources, int sourceCount, int height, int width, int y0, int x0, int x1,
                  Activation activation, float* const* rows) const;
    // One row of the output, through the folded form where it applies.
    void row(const ConvSource* sources, int sourceCount, int height, int width, int y, int x0, int x1,
             Activation activation, float* outRow) const;

    PackedConv packed_;
    std::optional<UpsampledConv> upsampled_;
    std::optional<WinogradConv> winograd_;
    std::optional<PackedGemmBf16> bf16Pointwise_;  // a 1x1 layer in bfloat16 (Precision::BFloat16)
};

// out(y, x) = max over in(2y..2y+1, 2x..2x+1) that exist; out is ceil(h/2) x ceil(w/2).
void maxPool2x2(const FeatureMap& input, FeatureMap& output);
// out(y, x) = in(y / 2, x / 2) for an output of height x width; the input must cover
// ceil(height / 2) x ceil(width / 2) (throws affinity::Error otherwise).
void upsampleNearest(const FeatureMap& input, int height, int width, FeatureMap& output);

}  // namespace affinity
