// Plain image output: exact float EXR, tone-mapped PNG with non-finite values shown black.
#include <gtest/gtest.h>
#include <stb/stb_image.h>
#include <unistd.h>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "affinity/error.h"
#include "affinity/image_io.h"

namespace affinity {
namespace {

namespace fs = std::filesystem;

class ImageIo : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
        dir_ =
            fs::temp_directory_path() / ("affinity_test_image_io_" + std::to_string(::getpid()) + "_" + test->name());
        fs::remove_all(dir_);
        fs::create_directories(dir_);
    }
    void TearDown() override { fs::remove_all(dir_); }
    std::string path(const std::string& name) const { return (dir_ / name).string(); }
    std::size_t fileCount() const {
        return std::size_t(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()));
    }
    fs::path dir_;
};

struct Png {
    int width = 0, height = 0;
    std::vector<unsigned char> rgb;
};

Png loadPng(const std::string& file) {
    Png png;
    int channels = 0;
    unsigned char* data = stbi_load(file.c_str(), &png.width, &png.height, &channels, 3);
    if (data == nullptr) return png;
    png.rgb.assign(data, data + std::size_t(png.width) * std::size_t(png.height) * 3);
    stbi_image_free(data);
    return png;
}

template <typename F>
void expectErrorNaming(const std::string& file, F&& write) {
    try {
        write();
        ADD_FAILURE() << "no throw";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
    }
}

TEST_F(ImageIo, ExrRoundTripIsExact) {
    const int width = 5, height = 3;
    std::vector<float> rgb(width * height * 3);
    for (std::size_t i = 0; i < rgb.size(); ++i) rgb[i] = float(i) * 0.37f - 2.0f;
    rgb[4] = 1e30f;
    writeRgbExr(path("image.exr"), width, height, rgb.data());
    EXPECT_EQ(fileCount(), 1u);

    Imf::InputFile file(path("image.exr").c_str());
    const Imath::Box2i window = file.header().dataWindow();
    EXPECT_EQ(window.max.x - window.min.x + 1, width);
    EXPECT_EQ(window.max.y - window.min.y + 1, height);
    for (const char* name : {"R", "G", "B"}) {
        ASSERT_NE(file.header().channels().findChannel(name), nullptr);
        EXPECT_EQ(file.header().channels().findChannel(name)->type, Imf::FLOAT);
    }
    std::vector<float> back(rgb.size(), -1.0f);
    Imf::FrameBuffer buffer;
    const char* names[3] = {"R", "G", "B"};
    for (int c = 0; c < 3; ++c) {
        buffer.insert(names[c], Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(back.data() + c), 3 * sizeof(float),
                                           3 * sizeof(float) * width));
    }
    file.setFrameBuffer(buffer);
    file.readPixels(0, height - 1);
    EXPECT_EQ(back, rgb);
}

TEST_F(ImageIo, PngToneMapping) {
    const float inf = std::numeric_limits<float>::infinity();
    const float nan = std::numeric_limits<float>::quiet_NaN();
    // One pixel per row of this table: input RGB and expected 8-bit output.
    const std::vector<float> rgb = {
        0.0f,  1.0f,   3e38f,  // black, x/(1+x) = 0.5 -> sRGB 188, overflow after exposure -> white
        nan,   inf,    -inf,   // non-finite -> black
        -1.0f, 0.001f, 9.0f,   // negative -> black; tiny values use the linear sRGB segment
    };
    writeTonemappedPng(path("image.png"), 1, 3, rgb.data(), 2.0f);
    const Png png = loadPng(path("image.png"));
    ASSERT_EQ(png.width, 1);
    ASSERT_EQ(png.height, 3);
    const auto srgb8 = [](float linear) {
        const double v = linear <= 0.0031308 ? 12.92 * linear : 1.055 * std::pow(double(linear), 1 / 2.4) - 0.055;
        return int(std::lround(v * 255));
    };
    const std::vector<int> expected = {
        0, srgb8(2.0f / 3.0f), 255, 0, 0, 0, 0, srgb8(0.002f / 1.002f), srgb8(18.0f / 19.0f)};
    ASSERT_EQ(png.rgb.size(), expected.size());
    for (std::size_t i = 0; i < expected.size(); ++i) {
        EXPECT_NEAR(int(png.rgb[i]), expected[i], 1) << i;
    }
    EXPECT_EQ(fileCount(), 1u);
}

TEST_F(ImageIo, PngExposureScales) {
    const std::vector<float> rgb = {1.0f, 1.0f, 1.0f};
    writeTonemappedPng(path("dark.png"), 1, 1, rgb.data(), 0.0f);
    EXPECT_EQ(loadPng(path("dark.png")).rgb, std::vector<unsigned char>(3, 0));
    writeTonemappedPng(path("mid.png"), 1, 1, rgb.data());
    EXPECT_EQ(loadPng(path("mid.png")).rgb, std::vector<unsigned char>(3, 188));
}

TEST_F(ImageIo, BadArgumentsThrowAndWriteNothing) {
    const std::vector<float> rgb(12, 0.5f);
    expectErrorNaming(path("a.exr"), [&] { writeRgbExr(path("a.exr"), 0, 4, rgb.data()); });
    expectErrorNaming(path("a.exr"), [&] { writeRgbExr(path("a.exr"), 2, 2, nullptr); });
    expectErrorNaming(path("a.png"), [&] { writeTonemappedPng(path("a.png"), 2, -1, rgb.data()); });
    expectErrorNaming(path("a.png"), [&] { writeTonemappedPng(path("a.png"), 2, 2, rgb.data(), -1.0f); });
    const float nan = std::numeric_limits<float>::quiet_NaN();
    expectErrorNaming(path("a.png"), [&] { writeTonemappedPng(path("a.png"), 2, 2, rgb.data(), nan); });
    EXPECT_EQ(fileCount(), 0u);
}

TEST_F(ImageIo, MissingFolderThrows) {
    const std::vector<float> rgb(12, 0.5f);
    const std::string exr = path("missing/a.exr"), png = path("missing/a.png");
    expectErrorNaming(exr, [&] { writeRgbExr(exr, 2, 2, rgb.data()); });
    expectErrorNaming(png, [&] { writeTonemappedPng(png, 2, 2, rgb.data()); });
    EXPECT_EQ(fileCount(), 0u);
}

}  // namespace
}  // namespace affinity
