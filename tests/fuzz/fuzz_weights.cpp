// libFuzzer target: Weights::fromMemory on arbitrary bytes. Rejection with affinity::Error is
// the expected outcome; any other exception, a crash, a leak or undefined behaviour is a bug.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "affinity/error.h"
#include "affinity/weights.h"

namespace {

void parseAndTouch(const std::uint8_t* data, std::size_t size) {
    try {
        const affinity::Weights weights = affinity::Weights::fromMemory(data, size, "fuzz input");
        // Read every accepted tensor's bytes so that a view pointing out of range shows up.
        std::uint32_t sum = 0;
        for (const std::string& name : weights.names()) {
            const affinity::TensorView& view = weights.tensor(name);
            const auto* bytes = static_cast<const std::uint8_t*>(view.data);
            for (std::size_t i = 0; i < view.count * 4; ++i) sum += bytes[i];
        }
        volatile std::uint32_t sink = sum;
        (void)sink;
    } catch (const affinity::Error&) {}
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    parseAndTouch(data, size);
    // The checksum rejects almost every mutation before the record parser sees it, so also
    // parse a copy whose size field and checksum are made consistent: that reaches every check.
    constexpr std::size_t kSizeField = 24;
    constexpr std::size_t kMinimum = affinity::WeightsFormat::kHeaderSize + affinity::WeightsFormat::kChecksumSize;
    if (size >= kMinimum) {
        std::vector<std::uint8_t> sealed(data, data + size);
        const std::uint64_t fileSize = size;
        for (int i = 0; i < 8; ++i) sealed[kSizeField + i] = static_cast<std::uint8_t>(fileSize >> (8 * i));
        const std::size_t checksumAt = size - affinity::WeightsFormat::kChecksumSize;
        const std::uint64_t checksum = affinity::weightsChecksum(sealed.data(), checksumAt);
        for (int i = 0; i < 8; ++i) sealed[checksumAt + i] = static_cast<std::uint8_t>(checksum >> (8 * i));
        parseAndTouch(sealed.data(), sealed.size());
    }
    return 0;
}
