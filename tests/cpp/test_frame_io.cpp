// Frame files: exact round trips, rejection of every kind of broken file with an Error naming
// the file, atomic writes, and sequence folder listing.
#include <gtest/gtest.h>
#include <unistd.h>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfMatrixAttribute.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStringAttribute.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "affinity/atomic_file.h"
#include "affinity/error.h"
#include "affinity/frame.h"
#include "affinity/frame_io.h"

namespace affinity {
namespace {

namespace fs = std::filesystem;

// A fresh folder per test, removed afterwards.
class FrameIo : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
        dir_ =
            fs::temp_directory_path() / ("affinity_test_frame_io_" + std::to_string(::getpid()) + "_" + test->name());
        fs::remove_all(dir_);
        fs::create_directories(dir_);
    }
    void TearDown() override { fs::remove_all(dir_); }

    std::string path(const std::string& name) const { return (dir_ / name).string(); }

    std::vector<std::string> folderContents() const {
        std::vector<std::string> names;
        for (const auto& entry : fs::directory_iterator(dir_)) {
            names.push_back(entry.path().filename().string());
        }
        std::sort(names.begin(), names.end());
        return names;
    }

    fs::path dir_;
};

std::uint32_t bitsOf(float value) {
    std::uint32_t bits;
    std::memcpy(&bits, &value, sizeof bits);
    return bits;
}

// Mostly ordinary values, plus arbitrary bit patterns (NaN payloads, infinities, denormals,
// -0) so the test proves the file keeps every bit.
void fillRandom(std::vector<float>& values, std::mt19937& rng) {
    std::uniform_real_distribution<float> uniform(-100.0f, 100.0f);
    std::uniform_int_distribution<std::uint32_t> bits;
    for (std::size_t i = 0; i < values.size(); ++i) {
        if (i % 7 == 3) {
            const std::uint32_t pattern = bits(rng);
            std::memcpy(&values[i], &pattern, sizeof pattern);
        } else {
            values[i] = uniform(rng);
        }
    }
}

SampleFrame randomFrame(int width, int height, int spp, bool withReference, unsigned seed) {
    SampleFrame frame(width, height, spp, withReference);
    std::mt19937 rng(seed);
    fillRandom(frame.samples(), rng);
    fillRandom(frame.motion(), rng);
    fillRandom(frame.valid(), rng);
    fillRandom(frame.reference(), rng);
    frame.info.sceneName = "kitchen \xc3\xa9t\xc3\xa9 #" + std::to_string(seed);
    frame.info.frameIndex = int(seed % 1000);
    frame.info.referenceSpp = withReference ? 4096 : 0;
    // Above 2^53: a double would round it.
    frame.info.seed = 0xFEDCBA9876543211ull + seed;
    std::uniform_real_distribution<float> uniform(-2.0f, 2.0f);
    for (float& v : frame.info.worldToCamera) v = uniform(rng);
    for (float& v : frame.info.cameraToClip) v = uniform(rng);
    frame.info.worldToCamera[3] = 123.25f;  // a translation, distinct from every other entry
    return frame;
}

::testing::AssertionResult sameBits(const std::vector<float>& a, const std::vector<float>& b) {
    if (a.size() != b.size()) {
        return ::testing::AssertionFailure() << "sizes " << a.size() << " and " << b.size();
    }
    for (std::size_t i = 0; i < a.size(); ++i) {
        if (bitsOf(a[i]) != bitsOf(b[i])) {
            return ::testing::AssertionFailure() << "index " << i << ": " << a[i] << " (0x" << std::hex << bitsOf(a[i])
                                                 << ") vs " << b[i] << " (0x" << bitsOf(b[i]) << ")";
        }
    }
    return ::testing::AssertionSuccess();
}

void expectSameFrame(const SampleFrame& expected, const SampleFrame& actual) {
    EXPECT_EQ(actual.width(), expected.width());
    EXPECT_EQ(actual.height(), expected.height());
    EXPECT_EQ(actual.spp(), expected.spp());
    EXPECT_EQ(actual.hasReference(), expected.hasReference());
    EXPECT_TRUE(sameBits(expected.samples(), actual.samples()));
    EXPECT_TRUE(sameBits(expected.motion(), actual.motion()));
    EXPECT_TRUE(sameBits(expected.valid(), actual.valid()));
    EXPECT_TRUE(sameBits(expected.reference(), actual.reference()));
    EXPECT_EQ(actual.info.sceneName, expected.info.sceneName);
    EXPECT_EQ(actual.info.frameIndex, expected.info.frameIndex);
    EXPECT_EQ(actual.info.referenceSpp, expected.info.referenceSpp);
    EXPECT_EQ(actual.info.seed, expected.info.seed);
    for (std::size_t i = 0; i < 16; ++i) {
        EXPECT_EQ(bitsOf(actual.info.worldToCamera[i]), bitsOf(expected.info.worldToCamera[i])) << i;
        EXPECT_EQ(bitsOf(actual.info.cameraToClip[i]), bitsOf(expected.info.cameraToClip[i])) << i;
    }
}

const char* compressionName(ExrCompression compression) {
    switch (compression) {
    case ExrCompression::None:
        return "none";
    case ExrCompression::Zip:
        return "zip";
    case ExrCompression::Piz:
        return "piz";
    }
    return "?";
}

constexpr ExrCompression kCompressions[] = {ExrCompression::None, ExrCompression::Zip, ExrCompression::Piz};

// Runs `read` and checks it throws an Error whose message names `file` and contains `problem`.
void expectReadError(const std::string& file, const std::string& problem = "") {
    try {
        (void)readFrame(file);
        ADD_FAILURE() << "reading " << file << " did not throw";
    } catch (const Error& e) {
        const std::string message = e.what();
        EXPECT_NE(message.find(file), std::string::npos) << message;
        EXPECT_NE(message.find(problem), std::string::npos) << "'" << problem << "' not in: " << message;
    } catch (const std::exception& e) {
        ADD_FAILURE() << "reading " << file << " threw a non-affinity exception: " << e.what();
    }
}

std::vector<char> readBytes(const std::string& file) {
    std::ifstream in(file, std::ios::binary);
    return std::vector<char>(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void writeBytes(const std::string& file, const char* data, std::size_t size) {
    std::ofstream out(file, std::ios::binary | std::ios::trunc);
    out.write(data, std::streamsize(size));
}

// --- round trips ----------------------------------------------------------------------------

TEST_F(FrameIo, RoundTripIsExactForEveryCompression) {
    for (ExrCompression compression : kCompressions) {
        SCOPED_TRACE(compressionName(compression));
        const SampleFrame frame = randomFrame(13, 7, 5, true, 11);
        const std::string file = path(std::string("frame_") + compressionName(compression) + ".exr");
        writeFrame(file, frame, compression);
        expectSameFrame(frame, readFrame(file));
    }
}

// Bands of 3, 3 and 1 rows (a split inside OpenEXR's 16- and 32-line blocks): the same samples
// and the same checksum as one buffer, the frame itself without samples.
TEST_F(FrameIo, ReadingIntoBandsGivesTheSameSamples) {
    for (ExrCompression compression : kCompressions) {
        SCOPED_TRACE(compressionName(compression));
        const SampleFrame frame = randomFrame(13, 7, 5, true, 12);
        const std::string file = path("banded.exr");
        writeFrame(file, frame, compression);
        const std::size_t rowValues = std::size_t(13) * 5 * kFeatureCount;
        std::vector<float> first(3 * rowValues, -1.0f), second(3 * rowValues, -1.0f), third(rowValues, -1.0f);
        const SampleFrame back = readFrame(file, [&](int width, int height, int spp) {
            EXPECT_EQ(width, 13);
            EXPECT_EQ(height, 7);
            EXPECT_EQ(spp, 5);
            return std::vector<SampleBand>{{0, 3, first.data()}, {3, 3, second.data()}, {6, 1, third.data()}};
        });
        EXPECT_TRUE(back.samples().empty());
        std::vector<float> samples = first;
        samples.insert(samples.end(), second.begin(), second.end());
        samples.insert(samples.end(), third.begin(), third.end());
        EXPECT_TRUE(sameBits(samples, frame.samples()));
        EXPECT_TRUE(sameBits(back.motion(), frame.motion()));
        EXPECT_TRUE(sameBits(back.valid(), frame.valid()));
        EXPECT_TRUE(sameBits(back.reference(), frame.reference()));
        EXPECT_TRUE(
            sameBits(meanRadiance({{0, 3, first.data()}, {3, 3, second.data()}, {6, 1, third.data()}}, 13, 7, 5),
                     frame.meanRadiance()));
    }
}

TEST_F(FrameIo, BandsThatDoNotCoverTheRowsAreAnError) {
    const std::string file = path("frame.exr");
    writeFrame(file, randomFrame(6, 5, 2, false, 13), ExrCompression::Zip);
    std::vector<float> buffer(std::size_t(6) * 5 * 2 * kFeatureCount);
    const std::vector<std::vector<SampleBand>> wrong = {
        {{0, 4, buffer.data()}},                          // a row short
        {{0, 2, buffer.data()}, {3, 2, buffer.data()}},   // a gap
        {{0, 5, nullptr}},                                // no memory
        {{0, 3, buffer.data()}, {3, 3, buffer.data()}}};  // past the end
    for (const auto& bands : wrong) {
        try {
            (void)readFrame(file, [&](int, int, int) { return bands; });
            ADD_FAILURE() << "no error";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("bands"), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
        }
    }
}

TEST_F(FrameIo, RoundTripWithoutReference) {
    for (ExrCompression compression : kCompressions) {
        SCOPED_TRACE(compressionName(compression));
        const SampleFrame frame = randomFrame(9, 4, 3, false, 5);
        const std::string file = path("frame.exr");
        writeFrame(file, frame, compression);
        const SampleFrame back = readFrame(file);
        EXPECT_FALSE(back.hasReference());
        expectSameFrame(frame, back);
    }
}

TEST_F(FrameIo, RoundTripExtremeSizes) {
    const SampleFrame single = randomFrame(1, 1, 1, true, 1);
    writeFrame(path("single.exr"), single);
    expectSameFrame(single, readFrame(path("single.exr")));

    const SampleFrame many = randomFrame(3, 2, SampleFrame::kMaxSpp, false, 2);
    writeFrame(path("many.exr"), many, ExrCompression::Zip);
    expectSameFrame(many, readFrame(path("many.exr")));
}

TEST_F(FrameIo, SeedExtremesRoundTrip) {
    for (std::uint64_t seed :
         {std::uint64_t(0), std::uint64_t(1) << 53 | 1, std::numeric_limits<std::uint64_t>::max()}) {
        SampleFrame frame = randomFrame(2, 2, 1, false, 3);
        frame.info.seed = seed;
        writeFrame(path("seed.exr"), frame);
        EXPECT_EQ(readFrame(path("seed.exr")).info.seed, seed);
    }
}

TEST_F(FrameIo, MatrixIsStoredInImathLayout) {
    // Imath's M44f is for row vectors, so our column-vector matrix is stored transposed.
    SampleFrame frame = randomFrame(2, 2, 1, false, 4);
    for (std::size_t i = 0; i < 16; ++i) frame.info.worldToCamera[i] = float(i + 1);
    // A pure translation by (4, 8, 12): our [0][3], [1][3], [2][3].
    frame.info.cameraToClip = {1, 0, 0, 4, 0, 1, 0, 8, 0, 0, 1, 12, 0, 0, 0, 1};
    writeFrame(path("m.exr"), frame);
    Imf::InputFile file(path("m.exr").c_str());
    const Imath::M44f stored = file.header().typedAttribute<Imf::M44fAttribute>("affinity.worldToCamera").value();
    for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) {
            EXPECT_EQ(stored[c][r], frame.info.worldToCamera[std::size_t(r * 4 + c)]) << r << c;
        }
    }
    const Imath::M44f translation = file.header().typedAttribute<Imf::M44fAttribute>("affinity.cameraToClip").value();
    EXPECT_EQ(Imath::V3f(0, 0, 0) * translation, Imath::V3f(4, 8, 12));
}

TEST_F(FrameIo, ChannelNamesFollowTheDocumentedScheme) {
    writeFrame(path("names.exr"), randomFrame(2, 2, 12, true, 6));
    Imf::InputFile file(path("names.exr").c_str());
    const Imf::ChannelList& channels = file.header().channels();
    for (const char* name : {"sample00.diffuse.R", "sample11.specular_bounce.Y", "sample03.normal.Z", "motion.X",
                             "motion.Y", "valid.Y", "reference.R", "reference.B"}) {
        const Imf::Channel* channel = channels.findChannel(name);
        ASSERT_NE(channel, nullptr) << name;
        EXPECT_EQ(channel->type, Imf::FLOAT) << name;
    }
    int count = 0;
    for (auto it = channels.begin(); it != channels.end(); ++it) ++count;
    EXPECT_EQ(count, 12 * kFeatureCount + 3 + 3);
    EXPECT_EQ(file.header().typedAttribute<Imf::IntAttribute>("affinity.version").value(), 1);
    EXPECT_EQ(file.header().typedAttribute<Imf::StringAttribute>("affinity.seed").value(),
              std::to_string(0xFEDCBA9876543211ull + 6));
}

TEST_F(FrameIo, WriteRejectsInconsistentFrames) {
    EXPECT_THROW(writeFrame(path("empty.exr"), SampleFrame()), Error);
    SampleFrame frame = randomFrame(4, 4, 2, false, 7);
    frame.motion().pop_back();
    try {
        writeFrame(path("broken.exr"), frame);
        ADD_FAILURE() << "no throw";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("motion"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(path("broken.exr")), std::string::npos) << e.what();
    }
    EXPECT_TRUE(folderContents().empty());
}

// --- broken files ---------------------------------------------------------------------------

TEST_F(FrameIo, MissingFile) { expectReadError(path("nothing_here.exr"), "does not exist"); }

TEST_F(FrameIo, FolderInsteadOfFile) {
    fs::create_directory(path("folder.exr"));
    expectReadError(path("folder.exr"), "not a regular file");
}

TEST_F(FrameIo, RandomBytes) {
    std::mt19937 rng(1);
    std::vector<char> bytes(5000);
    for (char& b : bytes) b = char(rng());
    writeBytes(path("random.exr"), bytes.data(), bytes.size());
    expectReadError(path("random.exr"), "not an OpenEXR file");

    // Random bytes after a valid magic number and version get past the first check.
    const unsigned char start[8] = {0x76, 0x2f, 0x31, 0x01, 0x02, 0, 0, 0};
    std::memcpy(bytes.data(), start, sizeof start);
    writeBytes(path("random_magic.exr"), bytes.data(), bytes.size());
    expectReadError(path("random_magic.exr"));

    writeBytes(path("empty.exr"), nullptr, 0);
    expectReadError(path("empty.exr"), "not an OpenEXR file");
}

TEST_F(FrameIo, TruncatedFiles) {
    for (ExrCompression compression : kCompressions) {
        SCOPED_TRACE(compressionName(compression));
        const std::string good = path("good.exr");
        writeFrame(good, randomFrame(24, 16, 4, true, 8), compression);
        const std::vector<char> bytes = readBytes(good);
        for (double fraction : {0.001, 0.1, 0.5, 0.9, 0.99}) {
            const auto size = std::size_t(double(bytes.size()) * fraction);
            SCOPED_TRACE(size);
            const std::string file = path("truncated.exr");
            writeBytes(file, bytes.data(), size);
            expectReadError(file);
        }
        // One byte short: only the last scanline block is damaged.
        writeBytes(path("short.exr"), bytes.data(), bytes.size() - 1);
        expectReadError(path("short.exr"));
    }
}

TEST_F(FrameIo, OverwrittenByteRanges) {
    for (ExrCompression compression : kCompressions) {
        SCOPED_TRACE(compressionName(compression));
        const std::string good = path("good.exr");
        writeFrame(good, randomFrame(24, 16, 4, true, 9), compression);
        const std::vector<char> bytes = readBytes(good);
        std::mt19937 rng(2);
        for (double fraction : {0.2, 0.4, 0.6, 0.8, 0.97}) {
            std::vector<char> damaged = bytes;
            const auto start = std::size_t(double(bytes.size()) * fraction);
            for (std::size_t i = start; i < start + 16 && i < damaged.size(); ++i) {
                damaged[i] = char(rng());
            }
            SCOPED_TRACE(start);
            writeBytes(path("damaged.exr"), damaged.data(), damaged.size());
            expectReadError(path("damaged.exr"));
        }
        // A single flipped bit in the pixel data of an uncompressed file is still caught.
        std::vector<char> flipped = bytes;
        flipped[bytes.size() / 2] = char(flipped[bytes.size() / 2] ^ 0x01);
        writeBytes(path("flipped.exr"), flipped.data(), flipped.size());
        expectReadError(path("flipped.exr"));
    }
}

// Writes an EXR with OpenEXR directly, the way writeFrame does, without the attribute
// `omitAttribute` and with `edit` applied to the header before writing; channel data are zeros.
// (Omitting instead of Header::erase, which leaks the attribute in OpenEXR 3.1.)
void writeCustomExr(const std::string& file, int spp, const std::function<void(Imf::Header&)>& edit,
                    const std::string& omitAttribute = "") {
    const int width = 4, height = 3;
    Imf::Header header(width, height);
    for (int s = 0; s < spp; ++s) {
        for (int f = 0; f < kFeatureCount; ++f) {
            char prefix[32];
            std::snprintf(prefix, sizeof prefix, "sample%02d.", s);
            header.channels().insert(prefix + featureChannelName(f), Imf::Channel(Imf::FLOAT));
        }
    }
    for (const char* name : {"motion.X", "motion.Y", "valid.Y"}) {
        header.channels().insert(name, Imf::Channel(Imf::FLOAT));
    }
    const auto insert = [&](const char* name, const Imf::Attribute& value) {
        if (name != omitAttribute) header.insert(name, value);
    };
    insert("affinity.version", Imf::IntAttribute(1));
    insert("affinity.spp", Imf::IntAttribute(spp));
    insert("affinity.sceneName", Imf::StringAttribute("custom"));
    insert("affinity.frameIndex", Imf::IntAttribute(0));
    insert("affinity.referenceSpp", Imf::IntAttribute(0));
    insert("affinity.seed", Imf::StringAttribute("42"));
    insert("affinity.worldToCamera", Imf::M44fAttribute(Imath::M44f()));
    insert("affinity.cameraToClip", Imf::M44fAttribute(Imath::M44f()));
    insert("affinity.checksum", Imf::StringAttribute("0000000000000000"));
    edit(header);

    const Imath::Box2i window = header.dataWindow();
    const int w = window.max.x - window.min.x + 1, h = window.max.y - window.min.y + 1;
    std::vector<float> zeros(std::size_t(w) * std::size_t(h) * 4, 0.0f);
    Imf::FrameBuffer buffer;
    for (auto it = header.channels().begin(); it != header.channels().end(); ++it) {
        // Every channel reads the same zeros; the element size follows the channel's type.
        const std::size_t size = it.channel().type == Imf::HALF ? 2 : 4;
        const std::ptrdiff_t origin = std::ptrdiff_t(window.min.x) + std::ptrdiff_t(window.min.y) * w;
        char* base = reinterpret_cast<char*>(zeros.data()) - origin * std::ptrdiff_t(size);
        buffer.insert(it.name(), Imf::Slice(it.channel().type, base, size, size * std::size_t(w)));
    }
    Imf::OutputFile out(file.c_str(), header);
    out.setFrameBuffer(buffer);
    out.writePixels(h);
}

TEST_F(FrameIo, CustomExrWithAllChannelsOnlyFailsTheChecksum) {
    // The control for the tests below: the hand-written file is right apart from the checksum.
    writeCustomExr(path("custom.exr"), 2, [](Imf::Header&) {});
    expectReadError(path("custom.exr"), "checksum mismatch");
}

// ChannelList has no erase: rebuild it without `name`.
void removeChannel(Imf::Header& header, const char* name) {
    Imf::ChannelList kept;
    for (auto it = header.channels().begin(); it != header.channels().end(); ++it) {
        if (std::strcmp(it.name(), name) != 0) kept.insert(it.name(), it.channel());
    }
    header.channels() = kept;
}

TEST_F(FrameIo, MissingChannelIsNamed) {
    writeCustomExr(path("missing.exr"), 2, [](Imf::Header& h) { removeChannel(h, "sample01.normal.Z"); });
    expectReadError(path("missing.exr"), "missing channel 'sample01.normal.Z'");
    writeCustomExr(path("nomotion.exr"), 1, [](Imf::Header& h) { removeChannel(h, "motion.Y"); });
    expectReadError(path("nomotion.exr"), "missing channel 'motion.Y'");
}

TEST_F(FrameIo, PartialReferenceIsRejected) {
    writeCustomExr(path("partial.exr"), 1, [](Imf::Header& h) {
        h.channels().insert("reference.R", Imf::Channel(Imf::FLOAT));
        h.channels().insert("reference.B", Imf::Channel(Imf::FLOAT));
    });
    expectReadError(path("partial.exr"), "missing channel 'reference.G'");
}

TEST_F(FrameIo, UnexpectedChannelIsRejected) {
    // A channel of a sample beyond affinity.spp means the writer and the header disagree.
    writeCustomExr(path("extra.exr"), 1,
                   [](Imf::Header& h) { h.channels().insert("sample01.diffuse.R", Imf::Channel(Imf::FLOAT)); });
    expectReadError(path("extra.exr"), "unexpected channel 'sample01.diffuse.R'");
}

TEST_F(FrameIo, NonFloatChannelIsRejected) {
    writeCustomExr(path("half.exr"), 1,
                   [](Imf::Header& h) { h.channels().insert("valid.Y", Imf::Channel(Imf::HALF)); });
    expectReadError(path("half.exr"), "channel 'valid.Y' has type HALF, expected FLOAT");
}

TEST_F(FrameIo, MissingAttributeIsNamed) {
    for (const char* name :
         {"affinity.version", "affinity.spp", "affinity.sceneName", "affinity.frameIndex", "affinity.referenceSpp",
          "affinity.seed", "affinity.worldToCamera", "affinity.cameraToClip", "affinity.checksum"}) {
        SCOPED_TRACE(name);
        writeCustomExr(
            path("noattr.exr"), 1, [](Imf::Header&) {}, name);
        expectReadError(path("noattr.exr"), std::string("missing attribute '") + name + "'");
    }
}

TEST_F(FrameIo, WrongAttributeTypeIsNamed) {
    writeCustomExr(
        path("type.exr"), 1, [](Imf::Header& h) { h.insert("affinity.spp", Imf::StringAttribute("1")); },
        "affinity.spp");
    expectReadError(path("type.exr"), "attribute 'affinity.spp' has type 'string', expected 'int'");
}

TEST_F(FrameIo, BadSeedIsRejected) {
    for (const char* seed : {"", "-1", "18446744073709551616", "12x", " 5"}) {
        SCOPED_TRACE(seed);
        writeCustomExr(path("seed.exr"), 1,
                       [&](Imf::Header& h) { h.insert("affinity.seed", Imf::StringAttribute(seed)); });
        expectReadError(path("seed.exr"), "affinity.seed");
    }
}

TEST_F(FrameIo, UnsupportedVersion) {
    writeCustomExr(path("v2.exr"), 1, [](Imf::Header& h) { h.insert("affinity.version", Imf::IntAttribute(2)); });
    expectReadError(path("v2.exr"), "unsupported frame file version 2");
}

TEST_F(FrameIo, SppOutOfRange) {
    for (int spp : {0, -3, SampleFrame::kMaxSpp + 1}) {
        SCOPED_TRACE(spp);
        writeCustomExr(path("spp.exr"), 1, [&](Imf::Header& h) { h.insert("affinity.spp", Imf::IntAttribute(spp)); });
        expectReadError(path("spp.exr"), "affinity.spp");
    }
}

TEST_F(FrameIo, DataWindowMustStartAtOrigin) {
    writeCustomExr(path("window.exr"), 1,
                   [](Imf::Header& h) { h.dataWindow() = Imath::Box2i(Imath::V2i(1, 2), Imath::V2i(4, 4)); });
    expectReadError(path("window.exr"), "data window starts at (1, 2)");
}

// --- atomic writes --------------------------------------------------------------------------

TEST_F(FrameIo, WriteLeavesNoTemporaryFiles) {
    writeFrame(path("frame_0000.exr"), randomFrame(5, 5, 2, true, 10));
    writeFrame(path("frame_0000.exr"), randomFrame(5, 5, 2, true, 11));  // replaces
    EXPECT_EQ(folderContents(), std::vector<std::string>{"frame_0000.exr"});
    expectSameFrame(randomFrame(5, 5, 2, true, 11), readFrame(path("frame_0000.exr")));
}

TEST_F(FrameIo, WriteIntoMissingFolderThrows) {
    const std::string file = path("no/such/folder/frame_0000.exr");
    try {
        writeFrame(file, randomFrame(2, 2, 1, false, 12));
        ADD_FAILURE() << "no throw";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
    }
    EXPECT_FALSE(fs::exists(file));
    EXPECT_TRUE(folderContents().empty());
}

TEST_F(FrameIo, FailedWriteKeepsThePreviousFile) {
    const std::string file = path("frame_0001.exr");
    const SampleFrame original = randomFrame(4, 3, 2, false, 13);
    writeFrame(file, original);
    SampleFrame broken = randomFrame(4, 3, 2, false, 14);
    broken.samples().resize(5);
    EXPECT_THROW(writeFrame(file, broken), Error);
    expectSameFrame(original, readFrame(file));
    EXPECT_EQ(folderContents(), std::vector<std::string>{"frame_0001.exr"});
}

TEST_F(FrameIo, WriteAtomicallyRemovesTheTemporaryOnFailure) {
    const std::string file = path("data.bin");
    writeBytes(file, "old", 3);
    std::string temporary;
    EXPECT_THROW(writeAtomically(file,
                                 [&](const std::string& t) {
                                     temporary = t;
                                     writeBytes(t, "partial", 7);
                                     throw std::runtime_error("disk on fire");
                                 }),
                 std::runtime_error);
    EXPECT_NE(temporary, file);
    EXPECT_EQ(fs::path(temporary).parent_path(), fs::path(file).parent_path());
    EXPECT_FALSE(fs::exists(temporary));
    const std::vector<char> bytes = readBytes(file);
    EXPECT_EQ(std::string(bytes.begin(), bytes.end()), "old");
    EXPECT_EQ(folderContents(), std::vector<std::string>{"data.bin"});

    writeAtomically(file, [](const std::string& t) { writeBytes(t, "new", 3); });
    const std::vector<char> replaced = readBytes(file);
    EXPECT_EQ(std::string(replaced.begin(), replaced.end()), "new");
    EXPECT_EQ(folderContents(), std::vector<std::string>{"data.bin"});
}

TEST_F(FrameIo, WriteAtomicallyFailsWhenNothingWasWritten) {
    EXPECT_THROW(writeAtomically(path("x.bin"), [](const std::string&) {}), Error);
    EXPECT_TRUE(folderContents().empty());
}

TEST_F(FrameIo, TemporaryNamesAreUnique) {
    std::vector<std::string> names;
    for (int i = 0; i < 3; ++i) {
        writeAtomically(path("x.bin"), [&](const std::string& t) {
            names.push_back(t);
            writeBytes(t, "x", 1);
        });
    }
    EXPECT_NE(names[0], names[1]);
    EXPECT_NE(names[1], names[2]);
}

// --- sequence folders -----------------------------------------------------------------------

TEST(FrameFileName, IsZeroPadded) {
    EXPECT_EQ(frameFileName(0), "frame_0000.exr");
    EXPECT_EQ(frameFileName(7), "frame_0007.exr");
    EXPECT_EQ(frameFileName(1234), "frame_1234.exr");
    EXPECT_EQ(frameFileName(12345), "frame_12345.exr");
    EXPECT_THROW(frameFileName(-1), Error);
}

TEST_F(FrameIo, ListFrameFilesInFrameOrder) {
    for (const char* name : {"frame_0010.exr", "frame_0002.exr", "frame_12345.exr", "frame_0001.exr", "frame_9999.exr",
                             // not frame files:
                             "frame_0003.exr.tmp-12-0", "frame_3.exr", "frame_00004.exr", "frame_-001.exr",
                             "frame_0006.EXR", "frame_.exr", "notes.txt", "reference_0001.exr"}) {
        writeBytes(path(name), "x", 1);
    }
    fs::create_directory(path("frame_0005.exr"));
    const std::vector<std::string> expected = {path("frame_0001.exr"), path("frame_0002.exr"), path("frame_0010.exr"),
                                               path("frame_9999.exr"), path("frame_12345.exr")};
    EXPECT_EQ(listFrameFiles(dir_.string()), expected);
}

TEST_F(FrameIo, ListFrameFilesOfEmptyFolder) { EXPECT_TRUE(listFrameFiles(dir_.string()).empty()); }

TEST_F(FrameIo, ListFrameFilesOfMissingFolderThrows) {
    const std::string missing = path("missing");
    try {
        (void)listFrameFiles(missing);
        ADD_FAILURE() << "no throw";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(missing), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
    }
    writeBytes(path("file"), "x", 1);
    EXPECT_THROW((void)listFrameFiles(path("file")), Error);
}

}  // namespace
}  // namespace affinity
