// Regression tests for the OpenEXR header pre-check that readFrame runs before OpenEXR parses
// a file: each case is a fuzzing finding (or its close relative) where a few bytes made
// OpenEXR 3.1 allocate gigabytes. Every one must be an affinity::Error naming the problem.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "affinity/error.h"
#include "affinity/frame.h"
#include "affinity/frame_io.h"

namespace affinity {
namespace {

namespace fs = std::filesystem;

class ExrHeaderCheck : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
        dir_ =
            fs::temp_directory_path() / ("affinity_test_exr_header_" + std::to_string(::getpid()) + "_" + test->name());
        fs::remove_all(dir_);
        fs::create_directories(dir_);
        SampleFrame frame(3, 2, 1, false);
        for (std::size_t i = 0; i < frame.samples().size(); ++i) frame.samples()[i] = float(i % 7) * 0.25f;
        frame.info.sceneName = "scene";
        const std::string valid = (dir_ / "valid.exr").string();
        writeFrame(valid, frame, ExrCompression::None);
        std::ifstream in(valid, std::ios::binary);
        bytes_.assign(std::istreambuf_iterator<char>(in), {});
    }
    void TearDown() override { fs::remove_all(dir_); }

    // Offset of the 4-byte size field of the header attribute `name` of type `type`.
    std::size_t sizeField(const std::string& name, const std::string& type) const {
        const std::string key = name + '\0' + type + '\0';
        const auto found = std::search(bytes_.begin(), bytes_.end(), key.begin(), key.end());
        EXPECT_NE(found, bytes_.end()) << name;
        return std::size_t(found - bytes_.begin()) + key.size();
    }
    void setI32(std::size_t offset, std::int32_t value) { std::memcpy(bytes_.data() + offset, &value, 4); }
    std::int32_t i32(std::size_t offset) const {
        std::int32_t value;
        std::memcpy(&value, bytes_.data() + offset, 4);
        return value;
    }

    // Writes the patched bytes and expects readFrame to reject them, naming the file and
    // every fragment.
    void expectRejected(const std::vector<std::string>& fragments) {
        const std::string path = (dir_ / "patched.exr").string();
        {
            std::ofstream out(path, std::ios::binary);
            out.write(bytes_.data(), std::streamsize(bytes_.size()));
        }
        try {
            readFrame(path);
            ADD_FAILURE() << "accepted; expected an error mentioning '" << fragments.front() << "'";
        } catch (const Error& e) {
            const std::string message = e.what();
            EXPECT_NE(message.find(path), std::string::npos) << message;
            for (const std::string& fragment : fragments) {
                EXPECT_NE(message.find(fragment), std::string::npos) << "missing '" << fragment << "' in: " << message;
            }
        }
    }

    fs::path dir_;
    std::vector<char> bytes_;
};

TEST_F(ExrHeaderCheck, ValidFileIsRead) {
    const std::string path = (dir_ / "valid.exr").string();
    EXPECT_EQ(readFrame(path).width(), 3);
}

TEST_F(ExrHeaderCheck, StringSizeBeyondTheFile) {
    setI32(sizeField("affinity.sceneName", "string"), 1852375044);
    expectRejected({"affinity.sceneName", "claims 1852375044 bytes"});
}

TEST_F(ExrHeaderCheck, NegativeAttributeSize) {
    setI32(sizeField("affinity.sceneName", "string"), -5);
    expectRejected({"affinity.sceneName", "negative size"});
}

TEST_F(ExrHeaderCheck, FixedSizeTypeWithAnotherSize) {
    // OpenEXR would read 4 bytes anyway and parse the rest of the header out of step.
    setI32(sizeField("affinity.spp", "int"), 0);
    expectRejected({"affinity.spp", "size 0, expected 4"});
}

TEST_F(ExrHeaderCheck, ChannelListEndingBeforeItsSize) {
    const std::size_t field = sizeField("channels", "chlist");
    const std::size_t end = field + 4 + std::size_t(i32(field));
    bytes_.insert(bytes_.begin() + std::ptrdiff_t(end), '\0');
    setI32(field, i32(field) + 1);
    expectRejected({"channel list ends before its declared size"});
}

TEST_F(ExrHeaderCheck, ChannelListNotTerminated) {
    const std::size_t field = sizeField("channels", "chlist");
    setI32(field, i32(field) - 1);
    expectRejected({"channel list"});
}

TEST_F(ExrHeaderCheck, HugeDataWindow) {
    const std::size_t field = sizeField("dataWindow", "box2i");
    setI32(field + 4 + 8, 4128769);  // xMax
    expectRejected({"data window", "4128770 x 2"});
}

TEST_F(ExrHeaderCheck, MultiPartFlag) {
    bytes_[5] = char(bytes_[5] | 0x10);  // 0x1000 in the little-endian version field
    expectRejected({"multi-part"});
}

TEST_F(ExrHeaderCheck, UnknownCompression) {
    bytes_[sizeField("compression", "compression") + 4] = 42;
    expectRejected({"compression 42"});
}

TEST_F(ExrHeaderCheck, TruncatedHeader) {
    bytes_.resize(sizeField("channels", "chlist") + 20);
    expectRejected({"'channels' claims"});
}

}  // namespace
}  // namespace affinity
