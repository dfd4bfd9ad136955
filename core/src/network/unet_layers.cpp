#include "network/unet_layers.h"

#include <algorithm>
#include <cstring>
#include <string>

#include "affinity/error.h"

namespace affinity {
namespace {

// Below this many multiply-adds a layer runs on the calling thread: waking the team costs
// more than it saves (the U-Net's deepest levels at small frame sizes).
constexpr double kParallelMinFma = 2e5;

std::string shapeText(const FeatureMap& map) {
    return std::to_string(map.height()) + "x" + std::to_string(map.width()) + "x" + std::to_string(map.channels());
}

}  // namespace

Conv2d::Conv2d(const float* torchWeights, const float* bias, int outChannels, int inChannels, int size, ConvIsa isa,
               int upsampledChannels, ConvForm form, Precision precision)
    : packed_(torchWeights, bias, outChannels, inChannels, size, isa) {
    if (size != 1 && size != 3)  // centred windows only (the kernel also packs 2x2)
        throw Error("Conv2d: unsupported size " + std::to_string(size) + "x" + std::to_string(size));
    if (form == ConvForm::Winograd) {
        if (size != 3 || upsampledChannels > 0)
            throw Error("Conv2d: the Winograd form needs a 3x3 layer without a folded upsampled input");
        winograd_.emplace(torchWeights, bias, outChannels, inChannels, isa, precision);
    }
    if (precision == Precision::BFloat16 && size == 1 && inChannels % 2 == 0)
        bf16Pointwise_.emplace(torchWeights, outChannels, inChannels, bias);
    if (upsampledChannels <= 0) return;
    if (size != 3 || upsampledChannels >= inChannels)
        throw Error("Conv2d: an upsampled input of " + std::to_string(upsampledChannels) +
                    " channels needs a 3x3 "
                    "layer with more inputs than that, not " +
                    std::to_string(size) + "x" + std::to_string(size) + " over " + std::to_string(inChannels));
    upsampled_.emplace(torchWeights, bias, outChannels, upsampledChannels, inChannels - upsampledChannels, isa,
                       precision);
}

bool Conv2d::folds(const ConvSource* sources, int sourceCount) const {
    return upsampled_ && sourceCount == 2 && sources[0].upsampled && !sources[1].upsampled &&
           sources[0].channels == upsampled_->coarseChannels();
}

void Conv2d::row(const ConvSource* sources, int sourceCount, int height, int width, int y, int x0, int x1,
                 Activation activation, float* outRow) const {
    if (folds(sources, sourceCount)) {
        upsampled_->row(packed_, sources[0], sources[1], height, width, y, x0, x1, activation, outRow);
    } else if (bf16Pointwise_ && sourceCount == 1 && !sources[0].upsampled && x1 > x0) {
        const float* input = sources[0].data + (std::size_t(y) * width + x0) * sources[0].channels;
        gemmBf16(*bf16Pointwise_, input, x1 - x0, outRow + std::size_t(x0) * outChannels(), std::size_t(outChannels()),
                 activation == Activation::LeakyRelu);
    } else {
        convolveRow(packed_, sources, sourceCount, height, width, y, x0, x1, activation, outRow);
    }
}

void Conv2d::rowGroup(const ConvSource* sources, int sourceCount, int height, int width, int y0, int x0, int x1,
                      Activation activation, float* const* rows) const {
    const int tileY = y0 / kWinogradRows;
    if (folds(sources, sourceCount)) {
        upsampled_->rowGroup(packed_, sources[0], sources[1], height, width, tileY, x0, x1, activation, rows);
    } else if (winograd_) {
        winograd_->strip(sources, sourceCount, height, width, tileY, x0, x1, activation, false, rows);
    } else {
        for (int r = 0; r < kWinogradRows; ++r)
            if (rows[r]) convolveRow(packed_, sources, sourceCount, height, width, y0 + r, x0, x1, activation, rows[r]);
    }
}

void Conv2d::apply(const FeatureMap& input, Activation activation, FeatureMap& output) const {
    if (input.channels() != inChannels())
        throw Error("Conv2d: input " + shapeText(input) + " has " + std::to_string(input.channels()) +
                    " channels, the layer expects " + std::to_string(inChannels()));
    if (&input == &output) throw Error("Conv2d: the output must not be the input");
    const ConvSource source{input.data(), input.channels()};
    run(&source, 1, input.height(), input.width(), activation, output);
}

void Conv2d::apply(const FeatureMap& first, const FeatureMap& second, Activation activation, FeatureMap& output) const {
    if (first.height() != second.height() || first.width() != second.width())
        throw Error("Conv2d: concatenated inputs differ in size: " + shapeText(first) + " and " + shapeText(second));
    if (first.channels() + second.channels() != inChannels())
        throw Error("Conv2d: concatenated inputs " + shapeText(first) + " and " + shapeText(second) + " have " +
                    std::to_string(first.channels() + second.channels()) + " channels, the layer expects " +
                    std::to_string(inChannels()));
    if (&first == &output || &second == &output) throw Error("Conv2d: the output must not be an input");
    const ConvSource sources[2] = {{first.data(), first.channels()}, {second.data(), second.channels()}};
    // A source without channels contributes nothing; skipping it keeps the kernel's loops simple.
    const int offset = first.channels() == 0 ? 1 : 0;
    const int count = 2 - offset - (second.channels() == 0 ? 1 : 0);
    run(sources + offset, count, first.height(), first.width(), activation, output);
}

void Conv2d::applyUpsampled(const FeatureMap& coarse, const FeatureMap& skip, Activation activation,
                            FeatureMap& output) const {
    if (coarse.height() != (skip.height() + 1) / 2 || coarse.width() != (skip.width() + 1) / 2)
        throw Error("Conv2d: coarse input " + shapeText(coarse) + " is not half the size of the skip input " +
                    shapeText(skip));
    if (coarse.channels() + skip.channels() != inChannels())
        throw Error("Conv2d: upsampled " + shapeText(coarse) + " and skip " + shapeText(skip) + " have " +
                    std::to_string(coarse.channels() + skip.channels()) + " channels, the layer expects " +
                    std::to_string(inChannels()));
    if (&coarse == &output || &skip == &output) throw Error("Conv2d: the output must not be an input");
    const ConvSource sources[2] = {{coarse.data(), coarse.channels(), true}, {skip.data(), skip.channels()}};
    const int offset = coarse.channels() == 0 ? 1 : 0;
    const int count = 2 - offset - (skip.channels() == 0 ? 1 : 0);
    run(sources + offset, count, skip.height(), skip.width(), activation, output);
}

void Conv2d::checkRowInputs(const ConvSource* sources, int sourceCount, int height, int width, int y, int x0,
                            int x1) const {
    int channels = 0;
    for (int s = 0; s < sourceCount; ++s) channels += sources[s].channels;
    if (channels != inChannels())
        throw Error("Conv2d: the inputs have " + std::to_string(channels) + " channels, the layer expects " +
                    std::to_string(inChannels()));
    if (y < 0 || y >= height || x0 < 0 || x1 > width || x0 > x1)
        throw Error("Conv2d: row " + std::to_string(y) + ", columns " + std::to_string(x0) + ".." + std::to_string(x1) +
                    " are outside a " + std::to_string(height) + "x" + std::to_string(width) + " image");
}

void Conv2d::applyRow(const ConvSource* sources, int sourceCount, int height, int width, int y, int x0, int x1,
                      Activation activation, float* outRow) const {
    checkRowInputs(sources, sourceCount, height, width, y, x0, x1);
    row(sources, sourceCount, height, width, y, x0, x1, activation, outRow);
}

void Conv2d::applyRowGroup(const ConvSource* sources, int sourceCount, int height, int width, int y0, int x0, int x1,
                           Activation activation, float* const* rows) const {
    checkRowInputs(sources, sourceCount, height, width, y0, x0, x1);
    bool nullsPastTheImage = true;
    for (int r = 0; r < kWinogradRows; ++r) nullsPastTheImage &= (rows[r] == nullptr) == (y0 + r >= height);
    if (y0 % kWinogradRows != 0 || !nullsPastTheImage)
        throw Error("Conv2d: a group of rows starts at a multiple of " + std::to_string(kWinogradRows) +
                    " and has exactly the image's rows (row " + std::to_string(y0) + " of " + std::to_string(height) +
                    ")");
    rowGroup(sources, sourceCount, height, width, y0, x0, x1, activation, rows);
}

void Conv2d::run(const ConvSource* sources, int sourceCount, int height, int width, Activation activation,
                 FeatureMap& output) const {
    output.resize(height, width, outChannels());
    if (output.empty()) return;
    const double fmaCount = double(height) * width * outChannels() * inChannels() * size() * size();
    const bool parallel = fmaCount >= kParallelMinFma;
    const bool folded = folds(sources, sourceCount);
    if (winograd_ && !folded) {
        winograd_->apply(sources, sourceCount, height, width, activation, output, parallel);
        return;
    }
    // Row groups where the folded form runs (in its Winograd forms), else single rows.
    const int step = folded ? kWinogradRows : 1;
    const int strips = (height + step - 1) / step;
    const int tiles = (width + kConvTileWidth - 1) / kConvTileWidth;
    const long long tasks = (long long)strips * tiles;
    // Each task owns whole output pixels, so the split cannot change any value; dynamic
    // scheduling only balances load when another process competes for the cores.
#pragma omp parallel for schedule(dynamic) if (parallel)
    for (long long task = 0; task < tasks; ++task) {
        const int y = int(task / tiles) * step;
        const int x0 = int(task % tiles) * kConvTileWidth;
        const int x1 = std::min(width, x0 + kConvTileWidth);
        if (step == kWinogradRows) {
            float* rows[kWinogradRows];
            for (int r = 0; r < kWinogradRows; ++r) rows[r] = y + r < height ? output.pixel(y + r, 0) : nullptr;
            rowGroup(sources, sourceCount, height, width, y, x0, x1, activation, rows);
        } else {
            row(sources, sourceCount, height, width, y, x0, x1, activation, output.pixel(y, 0));
        }
    }
}

void maxPool2x2(const FeatureMap& input, FeatureMap& output) {
    if (&input == &output) throw Error("maxPool2x2: the output must not be the input");
    const int height = input.height(), width = input.width(), channels = input.channels();
    output.resize((height + 1) / 2, (width + 1) / 2, channels);
    const int outHeight = output.height(), outWidth = output.width();
#pragma omp parallel for schedule(static) if (output.size() >= (1 << 16))
    for (int y = 0; y < outHeight; ++y) {
        // A missing last row or column repeats the one before it: max(a, a) = a.
        const int y0 = 2 * y, y1 = std::min(2 * y + 1, height - 1);
        for (int x = 0; x < outWidth; ++x) {
            const int x0 = 2 * x, x1 = std::min(2 * x + 1, width - 1);
            const float* a = input.pixel(y0, x0);
            const float* b = input.pixel(y0, x1);
            const float* c = input.pixel(y1, x0);
            const float* d = input.pixel(y1, x1);
            float* o = output.pixel(y, x);
#pragma omp simd
            for (int k = 0; k < channels; ++k) o[k] = std::max(std::max(a[k], b[k]), std::max(c[k], d[k]));
        }
    }
}

void upsampleNearest(const FeatureMap& input, int height, int width, FeatureMap& output) {
    if (&input == &output) throw Error("upsampleNearest: the output must not be the input");
    if (height < 0 || width < 0 || (height + 1) / 2 > input.height() || (width + 1) / 2 > input.width())
        throw Error("upsampleNearest: input " + shapeText(input) + " does not cover an output of " +
                    std::to_string(height) + "x" + std::to_string(width));
    const int channels = input.channels();
    output.resize(height, width, channels);
    const std::size_t pixelBytes = std::size_t(channels) * sizeof(float);
#pragma omp parallel for schedule(static) if (output.size() >= (1 << 16))
    for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) std::memcpy(output.pixel(y, x), input.pixel(y / 2, x / 2), pixelBytes);
    }
}

}  // namespace affinity
