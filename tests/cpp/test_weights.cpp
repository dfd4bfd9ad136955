// Weights files: exact round trips through the training-side writer, aligned tensor data, and
// rejection of every kind of corrupt file with an Error naming the source and the problem.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "affinity/error.h"
#include "affinity/weights.h"
#include "train/weights_writer.h"

namespace affinity {
namespace {

namespace fs = std::filesystem;
using train::NamedTensor;

constexpr const char* kSource = "test-source.affw";

NamedTensor floatTensor(const std::string& name, std::vector<std::int64_t> shape, std::mt19937& rng) {
    NamedTensor tensor{name, DType::Float32, std::move(shape), {}, {}};
    std::size_t count = 1;
    for (const std::int64_t dim : tensor.shape) count *= static_cast<std::size_t>(dim);
    std::uniform_real_distribution<float> uniform(-3.0f, 3.0f);
    std::uniform_int_distribution<std::uint32_t> bits;
    for (std::size_t i = 0; i < count; ++i) {
        float value = uniform(rng);
        // Arbitrary bit patterns too (NaN payloads, denormals): the file must keep every bit.
        if (i % 5 == 2) {
            const std::uint32_t pattern = bits(rng);
            std::memcpy(&value, &pattern, sizeof value);
        }
        tensor.floats.push_back(value);
    }
    return tensor;
}

NamedTensor intTensor(const std::string& name, std::vector<std::int64_t> shape, std::mt19937& rng) {
    NamedTensor tensor{name, DType::Int32, std::move(shape), {}, {}};
    std::size_t count = 1;
    for (const std::int64_t dim : tensor.shape) count *= static_cast<std::size_t>(dim);
    std::uniform_int_distribution<std::int32_t> values(std::numeric_limits<std::int32_t>::min(),
                                                       std::numeric_limits<std::int32_t>::max());
    for (std::size_t i = 0; i < count; ++i) tensor.ints.push_back(values(rng));
    return tensor;
}

std::vector<NamedTensor> sampleTensors() {
    std::mt19937 rng(7);
    std::vector<NamedTensor> tensors;
    tensors.push_back(floatTensor("embed.0.weight", {7, 3}, rng));
    tensors.push_back(floatTensor("embed.0.bias", {7}, rng));
    tensors.push_back(floatTensor("unet.enc0.conv0.weight", {5, 3, 3, 3}, rng));
    tensors.push_back(floatTensor("odd", {3, 1, 13}, rng));
    tensors.push_back(floatTensor("single", {1}, rng));
    tensors.push_back(intTensor("config.version", {1}, rng));
    tensors.push_back(intTensor("ints.2d", {3, 11}, rng));
    tensors.push_back(floatTensor("name \xC3\xA9\xE2\x82\xAC", {2, 2}, rng));  // UTF-8 name
    return tensors;
}

// Two tensors with three-byte names, so that renaming one onto the other keeps the layout.
std::vector<NamedTensor> twoTensors() {
    std::mt19937 rng(3);
    return {floatTensor("w.a", {3, 5}, rng), intTensor("w.b", {2}, rng)};
}

// A serialized file with helpers to patch fields in place and then make the size field and
// checksum consistent again, so that each test reaches the check it aims at.
struct FileImage {
    std::vector<std::uint8_t> bytes;

    explicit FileImage(const std::vector<NamedTensor>& tensors) : bytes(train::serializeWeights(tensors)) {}

    std::uint64_t u64(std::size_t offset) const {
        std::uint64_t value = 0;
        for (int i = 0; i < 8; ++i) value |= std::uint64_t(bytes[offset + i]) << (8 * i);
        return value;
    }
    std::uint32_t u32(std::size_t offset) const {
        std::uint32_t value = 0;
        for (int i = 0; i < 4; ++i) value |= std::uint32_t(bytes[offset + i]) << (8 * i);
        return value;
    }
    void setU32(std::size_t offset, std::uint32_t value) {
        for (int i = 0; i < 4; ++i) bytes[offset + i] = static_cast<std::uint8_t>(value >> (8 * i));
    }
    void setU64(std::size_t offset, std::uint64_t value) {
        for (int i = 0; i < 8; ++i) bytes[offset + i] = static_cast<std::uint8_t>(value >> (8 * i));
    }

    // Field offsets of record `index`.
    struct Record {
        std::size_t nameLength, name, dtype, rank, dims, dataOffset, byteSize;
    };
    Record record(std::size_t index) const {
        std::size_t at = WeightsFormat::kHeaderSize;
        for (std::size_t i = 0;; ++i) {
            Record r{};
            r.nameLength = at;
            r.name = at + 4;
            r.dtype = r.name + u32(r.nameLength);
            r.rank = r.dtype + 4;
            r.dims = r.rank + 4;
            r.dataOffset = r.dims + 8 * u32(r.rank);
            r.byteSize = r.dataOffset + 8;
            if (i == index) return r;
            at = r.byteSize + 8;
        }
    }

    void sealChecksum() {
        const std::size_t end = bytes.size() - WeightsFormat::kChecksumSize;
        setU64(end, weightsChecksum(bytes.data(), end));
    }
    void reseal() {
        setU64(24, bytes.size());
        sealChecksum();
    }

    Weights load() const { return Weights::fromMemory(bytes.data(), bytes.size(), kSource); }
};

// Expects loading to throw an affinity::Error whose message names the source and contains
// every one of `fragments`.
void expectRejected(const FileImage& image, const std::vector<std::string>& fragments) {
    try {
        image.load();
        ADD_FAILURE() << "the file was accepted; expected an error mentioning '" << fragments.front() << "'";
    } catch (const Error& e) {
        const std::string message = e.what();
        EXPECT_NE(message.find(kSource), std::string::npos) << message;
        for (const std::string& fragment : fragments) {
            EXPECT_NE(message.find(fragment), std::string::npos) << "missing '" << fragment << "' in: " << message;
        }
    }
}

void expectErrorMentioning(const std::function<void()>& action, const std::vector<std::string>& fragments) {
    try {
        action();
        ADD_FAILURE() << "no error; expected one mentioning '" << fragments.front() << "'";
    } catch (const Error& e) {
        const std::string message = e.what();
        for (const std::string& fragment : fragments) {
            EXPECT_NE(message.find(fragment), std::string::npos) << "missing '" << fragment << "' in: " << message;
        }
    }
}

TEST(Weights, RoundTripIsExact) {
    const std::vector<NamedTensor> tensors = sampleTensors();
    const FileImage image(tensors);
    const Weights weights = image.load();
    EXPECT_EQ(weights.source(), kSource);
    EXPECT_EQ(weights.names().size(), tensors.size());
    for (const NamedTensor& expected : tensors) {
        ASSERT_TRUE(weights.has(expected.name)) << expected.name;
        const TensorView& view = weights.tensor(expected.name);
        EXPECT_EQ(view.name, expected.name);
        EXPECT_EQ(view.dtype, expected.dtype);
        EXPECT_EQ(view.shape, expected.shape);
        if (expected.dtype == DType::Float32) {
            ASSERT_EQ(view.count, expected.floats.size());
            const float* data = weights.floats(expected.name, expected.shape);
            EXPECT_EQ(std::memcmp(data, expected.floats.data(), view.count * sizeof(float)), 0) << expected.name;
        } else {
            ASSERT_EQ(view.count, expected.ints.size());
            EXPECT_EQ(std::memcmp(view.data, expected.ints.data(), view.count * sizeof(std::int32_t)), 0)
                << expected.name;
        }
    }
    EXPECT_EQ(weights.integer("config.version"), tensors[5].ints[0]);
    EXPECT_FALSE(weights.has("missing"));
}

TEST(Weights, NamesAreSorted) {
    const Weights weights = FileImage(sampleTensors()).load();
    const std::vector<std::string> names = weights.names();
    EXPECT_TRUE(std::is_sorted(names.begin(), names.end()));
}

TEST(Weights, TensorDataIs64ByteAligned) {
    const Weights weights = FileImage(sampleTensors()).load();
    for (const std::string& name : weights.names()) {
        EXPECT_EQ(reinterpret_cast<std::uintptr_t>(weights.tensor(name).data) % 64, 0u) << name;
    }
}

TEST(Weights, EmptyContainerRoundTrips) {
    const Weights weights = FileImage({}).load();
    EXPECT_TRUE(weights.names().empty());
}

TEST(Weights, MovingKeepsTheViewsValid) {
    const std::vector<NamedTensor> tensors = sampleTensors();
    Weights original = FileImage(tensors).load();
    const void* before = original.tensor("odd").data;
    const Weights moved = std::move(original);
    EXPECT_EQ(moved.tensor("odd").data, before);
    EXPECT_EQ(std::memcmp(moved.floats("odd", {3, 1, 13}), tensors[3].floats.data(), 39 * sizeof(float)), 0);
}

TEST(Weights, FileRoundTripIsAtomicAndExact) {
    const fs::path dir = fs::temp_directory_path() / ("affinity_test_weights_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    const std::string path = (dir / "model.affw").string();
    const std::vector<NamedTensor> tensors = sampleTensors();
    train::writeWeightsFile(path, tensors);
    const Weights weights = Weights::fromFile(path);
    EXPECT_EQ(weights.source(), path);
    EXPECT_EQ(std::memcmp(weights.floats("embed.0.weight", {7, 3}), tensors[0].floats.data(), 21 * sizeof(float)), 0);
    // Only the final file is left: the temporary was renamed over it.
    std::vector<std::string> entries;
    for (const auto& entry : fs::directory_iterator(dir)) entries.push_back(entry.path().filename().string());
    EXPECT_EQ(entries, std::vector<std::string>{"model.affw"});
    fs::remove_all(dir);
}

TEST(Weights, MissingFileNamesThePath) {
    const std::string path = "/nonexistent-folder/model.affw";
    expectErrorMentioning([&] { Weights::fromFile(path); }, {path, "does not exist"});
    const std::string folder = fs::temp_directory_path().string();
    expectErrorMentioning([&] { Weights::fromFile(folder); }, {folder, "not a regular file"});
}

TEST(Weights, NullBufferIsRejected) {
    expectErrorMentioning([] { Weights::fromMemory(nullptr, 10, kSource); }, {kSource, "null"});
}

TEST(WeightsCorrupt, WrongMagic) {
    FileImage image(twoTensors());
    image.bytes[3] = 'X';
    image.reseal();
    expectRejected(image, {"magic"});
}

TEST(WeightsCorrupt, WrongVersion) {
    FileImage image(twoTensors());
    image.setU32(8, 2);
    image.reseal();
    expectRejected(image, {"version 2"});
}

TEST(WeightsCorrupt, FileSizeFieldMismatch) {
    FileImage image(twoTensors());
    image.setU64(24, image.bytes.size() + 64);
    image.sealChecksum();
    expectRejected(image, {"file size field", std::to_string(image.bytes.size() + 64)});
}

TEST(WeightsCorrupt, ChecksumMismatch) {
    FileImage image(twoTensors());
    image.bytes[image.u64(image.record(0).dataOffset) + 5] ^= 0x10;
    expectRejected(image, {"checksum mismatch"});
}

TEST(WeightsCorrupt, EveryFlippedByteIsRejected) {
    const FileImage valid(twoTensors());
    for (std::size_t i = 0; i < valid.bytes.size(); ++i) {
        FileImage image = valid;
        image.bytes[i] ^= 0x01;
        EXPECT_THROW(image.load(), Error) << "byte " << i;
    }
}

TEST(WeightsCorrupt, RankZero) {
    FileImage image(twoTensors());
    image.setU32(image.record(0).rank, 0);
    image.reseal();
    expectRejected(image, {"'w.a'", "rank 0"});
}

TEST(WeightsCorrupt, RankAboveFour) {
    FileImage image(twoTensors());
    image.setU32(image.record(1).rank, 5);
    image.reseal();
    expectRejected(image, {"'w.b'", "rank 5"});
}

TEST(WeightsCorrupt, DimsProductOverflows) {
    FileImage image(twoTensors());
    const auto r = image.record(0);
    image.setU64(r.dims, std::uint64_t(1) << 40);
    image.setU64(r.dims + 8, std::uint64_t(1) << 40);
    image.reseal();
    expectRejected(image, {"'w.a'", "overflows"});
}

TEST(WeightsCorrupt, SingleHugeDimensionOverflowsTheByteSize) {
    FileImage image(twoTensors());
    const auto r = image.record(1);
    image.setU64(r.dims, std::numeric_limits<std::uint64_t>::max());
    image.reseal();
    expectRejected(image, {"'w.b'", "overflows"});
}

TEST(WeightsCorrupt, ZeroDimension) {
    FileImage image(twoTensors());
    image.setU64(image.record(0).dims + 8, 0);
    image.reseal();
    expectRejected(image, {"'w.a'", "dimension 1 is zero"});
}

TEST(WeightsCorrupt, NameLengthBeyondTheFile) {
    FileImage image(twoTensors());
    image.setU32(image.record(1).nameLength, 0xFFFFFFFFu);
    image.reseal();
    expectRejected(image, {"tensor record 1", "name", "header ends"});
}

TEST(WeightsCorrupt, EmptyName) {
    FileImage image(twoTensors());
    image.setU32(image.record(0).nameLength, 0);
    image.reseal();
    expectRejected(image, {"tensor record 0", "empty name"});
}

TEST(WeightsCorrupt, NameWithNulByte) {
    FileImage image(twoTensors());
    image.bytes[image.record(0).name + 1] = 0;
    image.reseal();
    expectRejected(image, {"tensor record 0", "NUL"});
}

TEST(WeightsCorrupt, NameNotUtf8) {
    FileImage image(twoTensors());
    image.bytes[image.record(0).name + 1] = 0xC3;  // a lead byte followed by ASCII
    image.reseal();
    expectRejected(image, {"tensor record 0", "UTF-8"});
}

TEST(WeightsCorrupt, DataOffsetNotAligned) {
    FileImage image(twoTensors());
    const auto r = image.record(1);
    image.setU64(r.dataOffset, image.u64(r.dataOffset) + 4);
    image.reseal();
    expectRejected(image, {"'w.b'", "not a multiple of 64"});
}

TEST(WeightsCorrupt, DataBeforeTheDataSection) {
    FileImage image(twoTensors());
    image.setU64(image.record(0).dataOffset, 0);
    image.reseal();
    expectRejected(image, {"'w.a'", "outside the data section"});
}

TEST(WeightsCorrupt, DataPastTheEnd) {
    FileImage image(twoTensors());
    image.setU64(image.record(1).dataOffset, std::uint64_t(1) << 63);
    image.reseal();
    expectRejected(image, {"'w.b'", "outside the data section"});
}

TEST(WeightsCorrupt, DataRunsIntoTheChecksum) {
    FileImage image(twoTensors());
    // The 60-byte tensor moved to the last 64-aligned offset of the data section, whose tail is
    // too short for it.
    const auto r = image.record(0);
    const std::uint64_t dataEnd = image.bytes.size() - 8;
    image.setU64(r.dataOffset, dataEnd / 64 * 64);
    ASSERT_GT(dataEnd / 64 * 64 + 60, dataEnd);
    image.reseal();
    expectRejected(image, {"'w.a'", "outside the data section"});
}

TEST(WeightsCorrupt, OffsetPlusSizeWouldWrapAround) {
    FileImage image(twoTensors());
    const auto r = image.record(1);
    // 2^62 elements: 2^64 bytes would wrap to 0 without the overflow check on the byte size;
    // 2^61 elements: a 2^63-byte size whose end wraps when added to a large offset.
    image.setU64(r.dims, std::uint64_t(1) << 61);
    image.setU64(r.byteSize, std::uint64_t(1) << 63);
    image.setU64(r.dataOffset, (std::uint64_t(1) << 63) + 64);
    image.reseal();
    expectRejected(image, {"'w.b'", "outside the data section"});
}

TEST(WeightsCorrupt, ByteSizeDisagreesWithShape) {
    FileImage image(twoTensors());
    const auto r = image.record(0);
    image.setU64(r.byteSize, image.u64(r.byteSize) - 4);
    image.reseal();
    expectRejected(image, {"'w.a'", "data byte size"});
}

TEST(WeightsCorrupt, OverlappingTensors) {
    FileImage image(twoTensors());
    image.setU64(image.record(1).dataOffset, image.u64(image.record(0).dataOffset));
    image.reseal();
    expectRejected(image, {"'w.a'", "'w.b'", "overlap"});
}

TEST(WeightsCorrupt, DuplicateNames) {
    FileImage image(twoTensors());
    image.bytes[image.record(1).name + 2] = 'a';
    image.reseal();
    expectRejected(image, {"duplicate", "'w.a'"});
}

TEST(WeightsCorrupt, UnknownDtype) {
    FileImage image(twoTensors());
    image.setU32(image.record(0).dtype, 7);
    image.reseal();
    expectRejected(image, {"'w.a'", "unknown dtype 7"});
}

TEST(WeightsCorrupt, DataSectionOffsetOutOfRange) {
    FileImage image(twoTensors());
    image.setU64(16, image.bytes.size());
    image.reseal();
    expectRejected(image, {"data section offset"});
    image.setU64(16, 8);
    image.reseal();
    expectRejected(image, {"data section offset"});
}

TEST(WeightsCorrupt, TensorCountBeyondTheHeader) {
    FileImage image(twoTensors());
    image.setU32(12, 1000000);
    image.reseal();
    // The zero padding before the data section reads as a record with an empty name.
    expectRejected(image, {"tensor record 2"});
}

TEST(WeightsCorrupt, EveryTruncationThrows) {
    const FileImage valid(twoTensors());
    for (std::size_t length = 0; length < valid.bytes.size(); ++length) {
        try {
            Weights::fromMemory(valid.bytes.data(), length, kSource);
            ADD_FAILURE() << "accepted a file truncated to " << length << " bytes";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(kSource), std::string::npos) << e.what();
        }
    }
}

TEST(WeightsAccess, MissingTensorIsNamed) {
    const Weights weights = FileImage(twoTensors()).load();
    expectErrorMentioning([&] { weights.tensor("nope"); }, {kSource, "'nope'"});
    expectErrorMentioning([&] { weights.floats("nope", {1}); }, {kSource, "'nope'"});
    expectErrorMentioning([&] { weights.integer("nope"); }, {kSource, "'nope'"});
}

TEST(WeightsAccess, WrongShapeIsNamed) {
    const Weights weights = FileImage(twoTensors()).load();
    expectErrorMentioning([&] { weights.floats("w.a", {5, 3}); }, {kSource, "'w.a'", "[3, 5]", "expected [5, 3]"});
    expectErrorMentioning([&] { weights.integer("w.b"); }, {kSource, "'w.b'", "[2]", "expected [1]"});
}

TEST(WeightsAccess, WrongDtypeIsNamed) {
    const Weights weights = FileImage(twoTensors()).load();
    expectErrorMentioning([&] { weights.floats("w.b", {2}); }, {kSource, "'w.b'", "int32", "expected float32"});
    expectErrorMentioning([&] { weights.integer("w.a"); }, {kSource, "'w.a'", "float32", "expected int32"});
}

TEST(WeightsWriter, RejectsInconsistentTensors) {
    std::mt19937 rng(1);
    expectErrorMentioning(
        [&] {
            train::serializeWeights({floatTensor("x", {2}, rng), floatTensor("x", {3}, rng)});
        },
        {"duplicate", "'x'"});
    expectErrorMentioning(
        [] {
            train::serializeWeights({NamedTensor{"r0", DType::Float32, {}, {1.0f}, {}}});
        },
        {"'r0'", "rank 0"});
    expectErrorMentioning(
        [] {
            train::serializeWeights({NamedTensor{"r5", DType::Float32, {1, 1, 1, 1, 1}, {1.0f}, {}}});
        },
        {"'r5'", "rank 5"});
    expectErrorMentioning(
        [] {
            train::serializeWeights({NamedTensor{"n", DType::Float32, {3}, {1.0f, 2.0f}, {}}});
        },
        {"'n'", "shape needs 3"});
    expectErrorMentioning([] { train::serializeWeights({NamedTensor{"i", DType::Int32, {1}, {1.0f}, {}}}); }, {"'i'"});
    expectErrorMentioning(
        [] {
            train::serializeWeights({NamedTensor{"z", DType::Float32, {0}, {}, {}}});
        },
        {"'z'", "dimension 0"});
    expectErrorMentioning(
        [] {
            train::serializeWeights({NamedTensor{"", DType::Int32, {1}, {}, {1}}});
        },
        {"empty name"});
}

TEST(WeightsWriter, WriteFailureNamesThePath) {
    const std::string path = "/nonexistent-folder/model.affw";
    expectErrorMentioning([&] { train::writeWeightsFile(path, twoTensors()); }, {path});
}

}  // namespace
}  // namespace affinity
