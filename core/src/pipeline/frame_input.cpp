#include "pipeline/frame_input.h"

#include <algorithm>
#include <chrono>
#include <string>
#include <utility>

#include "affinity/error.h"
#include "network/filter_signal.h"

namespace affinity {
namespace {

// How much larger than a request a free map may be and still serve it while a frame is lent in
// bands (FeatureMapPool::kKeepRatio otherwise).
constexpr std::size_t kLentKeepRatio = 2;

// 1 / mean depth of the samples that hit something, over every kDepthScaleRowStep-th row
// (docs/MODEL.md section 1). Rows are summed in parallel and their sums added in row order, so
// the result does not depend on the threads.
float depthScale(const SampleBands& frame, int height) {
    const int rows = (height + kDepthScaleRowStep - 1) / kDepthScaleRowStep;
    std::vector<double> rowSums(std::size_t(rows), 0.0);
    std::vector<long long> rowCounts(std::size_t(rows), 0);
    const std::size_t rowValues = std::size_t(frame.width) * std::size_t(frame.spp) * kFeatureCount;
#pragma omp parallel for schedule(static)
    for (int r = 0; r < rows; ++r) {
        const float* row = frame.row(r * kDepthScaleRowStep);
        // Branch-free, four chains: a mispredicted test and one chain of dependent double adds
        // made this pass slower than reading the frame from memory.
        double sums[4] = {0.0, 0.0, 0.0, 0.0};
        long long counts[4] = {0, 0, 0, 0};
        std::size_t sample = 0;
        const std::size_t samples = rowValues / kFeatureCount;
        auto add = [&](int chain, float depth) {
            const bool hit = depth > 0.0f && depth <= 3.40282347e38f;  // false for NaN and +Inf
            sums[chain] += hit ? double(depth) : 0.0;
            counts[chain] += hit ? 1 : 0;
        };
        for (; sample + 4 <= samples; sample += 4)
            for (int chain = 0; chain < 4; ++chain)
                add(chain, row[(sample + std::size_t(chain)) * kFeatureCount + channel::kDepth]);
        for (; sample < samples; ++sample) add(0, row[sample * kFeatureCount + channel::kDepth]);
        rowSums[std::size_t(r)] = (sums[0] + sums[1]) + (sums[2] + sums[3]);
        rowCounts[std::size_t(r)] = (counts[0] + counts[1]) + (counts[2] + counts[3]);
    }
    double sum = 0.0;
    long long count = 0;
    for (int r = 0; r < rows; ++r) {
        sum += rowSums[std::size_t(r)];
        count += rowCounts[std::size_t(r)];
    }
    return count > 0 ? float(double(count) / sum) : 0.0f;
}

}  // namespace

EmbeddedFrame embedWholeFrame(const Network& net, FeatureMapPool& pool, SequenceHistory& history,
                              const SampleBands& samples, int height, const FrameInfo& info) {
    EmbeddedFrame frame;
    frame.depthScale = depthScale(samples, height);
    // The sequence goes on (also in single-frame mode, which keeps the sequence's exposure).
    const bool continues = history.continuedBy(samples.width, height, info, frame.meanDepth());
    const InputScales scales(frame.depthScale, history.exposureFor(samples, height, !continues));
    frame.exposure = scales.exposure;
    frame.embedding = pool.take(height, samples.width, net.embedding->outChannels());
    // The signal straight from each chunk's sample sums: a map of the sums would be the third
    // largest while the samples are held.
    frame.signal = pool.take(height, samples.width, kSignalChannels);
    frame.meanSquares = pool.take(height, samples.width, 1);
    frame.emissiveShare = pool.take(height, samples.width, 1);
    const int spp = frame.spp = samples.spp;
    float* signal = frame.signal.data();
    float* meanSquares = frame.meanSquares.data();
    float* emissiveShare = frame.emissiveShare.data();
    frame.invalidRadiance = net.embedding->apply(
        samples, height, scales, frame.embedding, [&](long long firstPixel, int count, const float* sums) {
            signalFromSums(sums, count, spp, signal + std::size_t(firstPixel) * std::size_t(kSignalChannels));
            sampleMeansFromSums(sums, count, spp, Embedding::kSumLuminanceSquares,
                                meanSquares + std::size_t(firstPixel));
            sampleMeansFromSums(sums, count, spp, Embedding::kSumEmissive, emissiveShare + std::size_t(firstPixel));
        });
    return frame;
}

Denoiser::PendingFrame FrameInput::pending() const {
    return spp_ > 0 ? Denoiser::PendingFrame{width_, height_, spp_} : Denoiser::PendingFrame{};
}

void FrameInput::refuseWhileWaiting(const char* call) const {
    if (spp_ > 0)
        throw Error(std::string(call) + ": " + std::to_string(spp_) +
                    " samples added with addSamples() or lent with sampleBands() wait for finishFrame() (or "
                    "discardSamples())");
}

std::vector<SampleBand> FrameInput::lend(const Network& net, FeatureMapPool& pool, int width, int height, int spp) {
    if (width < 1 || height < 1 || spp < 1) throw Error("sampleBands: the frame is empty");
    if (spp > SampleFrame::kMaxSpp)
        throw Error("sampleBands: " + std::to_string(spp) + " samples per pixel, at most " +
                    std::to_string(SampleFrame::kMaxSpp));
    if (spp_ > 0)
        throw Error("sampleBands: " + std::to_string(spp_) + " samples wait for finishFrame() (or discardSamples())");
    // The bands are large maps among smaller ones: a free band serving a small map would leave
    // the next frame's bands to new memory. kLentKeepRatio gave the lowest peak memory over the
    // models at 1080p (bench_denoiser --lend 1; commit ebb2c3b holds the figures).
    pool.setKeepRatio(kLentKeepRatio);
    // A band holds no more floats than a full-resolution embedding map, the largest maps made
    // after the embedding, so that those can take the bands' memory.
    const int channels = spp * kFeatureCount;
    const int bandRows =
        int(std::clamp<long long>((long long)height * net.embedding->outChannels() / channels, 1, height));
    std::vector<SampleBand> bands;
    for (int row = 0; row < height; row += bandRows) {
        const int rows = std::min(bandRows, height - row);
        lentBands_.push_back(pool.take(rows, width, channels));
        bands.push_back({row, rows, lentBands_.back().data()});
    }
    width_ = width;
    height_ = height;
    spp_ = spp;
    return bands;
}

void FrameInput::add(const Network& net, FeatureMapPool& pool, SequenceHistory& history, int width, int height, int spp,
                     const float* samples) {
    const auto start = std::chrono::steady_clock::now();
    if (width < 1 || height < 1 || spp < 1) throw Error("addSamples: the batch is empty");
    if (!samples) throw Error("addSamples: the batch has no samples buffer");
    if (!lentBands_.empty())
        throw Error("addSamples: a frame lent with sampleBands() waits for finishFrame() (or discardSamples())");
    const bool first = spp_ == 0;
    if (!first && (width != width_ || height != height_))
        throw Error("addSamples: a " + std::to_string(width) + "x" + std::to_string(height) +
                    " batch does not match the frame's first batch of " + std::to_string(width_) + "x" +
                    std::to_string(height_));
    if (first) {
        pool.setKeepRatio(FeatureMapPool::kKeepRatio);
        width_ = width;
        height_ = height;
        const SampleBands batch(samples, height, width, spp);
        depthScale_ = depthScale(batch, height);
        // A camera cut shows only at finishFrame(): such a frame keeps the exposure before it.
        exposure_ = history.exposureFor(batch, height, !history.continuedBySize(width, height));
        invalidRadiance_ = 0;
        milliseconds_ = 0.0;
        hiddenSum_ = pool.take(height, width, net.embedding->hiddenChannels());
        sampleSums_ = pool.take(height, width, Embedding::kSampleSumChannels);
    }
    invalidRadiance_ += net.embedding->accumulate(samples, height, width, spp, InputScales(depthScale_, exposure_),
                                                  hiddenSum_, first, &sampleSums_);
    spp_ += spp;
    milliseconds_ += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

FrameInput::LentFrame FrameInput::takeLent() {
    LentFrame frame;
    frame.bands = std::move(lentBands_);
    lentBands_.clear();
    spp_ = 0;
    for (const FeatureMap& band : frame.bands) frame.samples.bands.push_back(band.data());
    frame.samples.bandRows = frame.bands.front().height();
    frame.samples.width = width_;
    frame.samples.spp = frame.bands.front().channels() / kFeatureCount;
    frame.height = height_;
    return frame;
}

EmbeddedFrame FrameInput::finishStreamed(const Network& net, FeatureMapPool& pool) {
    EmbeddedFrame frame;
    // In place where the last layer keeps the width: the sums and the embedding, together with
    // the previous frame's embedding, would otherwise be the largest set of maps alive.
    if (net.embedding->outChannels() == net.embedding->hiddenChannels()) {
        frame.embedding = std::move(hiddenSum_);
        net.embedding->finish(frame.embedding, spp_, frame.embedding);
    } else {
        frame.embedding = pool.take(height_, width_, net.embedding->outChannels());
        net.embedding->finish(hiddenSum_, spp_, frame.embedding);
        pool.give(hiddenSum_);
    }
    frame.signal = pool.take(sampleSums_.height(), sampleSums_.width(), kSignalChannels);
    makeAccumulatedSignal(sampleSums_, spp_, frame.signal);
    frame.meanSquares = pool.take(sampleSums_.height(), sampleSums_.width(), 1);
    makeSampleMeans(sampleSums_, spp_, Embedding::kSumLuminanceSquares, frame.meanSquares);
    frame.emissiveShare = pool.take(sampleSums_.height(), sampleSums_.width(), 1);
    makeSampleMeans(sampleSums_, spp_, Embedding::kSumEmissive, frame.emissiveShare);
    frame.spp = spp_;
    pool.give(sampleSums_);
    frame.invalidRadiance = invalidRadiance_;
    frame.exposure = exposure_;
    frame.depthScale = depthScale_;
    frame.batchMilliseconds = milliseconds_;
    spp_ = 0;
    return frame;
}

void FrameInput::discard(FeatureMapPool& pool) {
    spp_ = 0;
    for (FeatureMap& band : lentBands_) pool.give(band);
    lentBands_.clear();
    pool.give(hiddenSum_);
    pool.give(sampleSums_);
}

}  // namespace affinity
