#include "affinity/image_io.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStdIO.h>
#include <stb/stb_image_write.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <new>
#include <vector>

#include "affinity/atomic_file.h"
#include "affinity/error.h"
#include "io/exr_threads.h"

namespace affinity {
namespace {

void checkImage(int width, int height, const float* rgb) {
    if (width < 1 || height < 1) {
        throw Error("image size " + std::to_string(width) + "x" + std::to_string(height) +
                    " is invalid: both sides must be at least 1");
    }
    if (rgb == nullptr) throw Error("no pixel data");
}

// The stream is ours so that a failed write (disk full) is seen when closing, see frame_io.cpp.
std::ofstream createFile(const std::string& path) {
    std::ofstream stream(path, std::ios::binary | std::ios::trunc);
    if (!stream) throw Error("cannot create '" + path + "': " + std::strerror(errno));
    return stream;
}

void closeFile(std::ofstream& stream, const std::string& path) {
    stream.close();
    if (stream.fail()) throw Error("writing '" + path + "' failed");
}

// Linear [0, 1] to the sRGB transfer curve, as an 8-bit code.
unsigned char encodeSrgb(float linear) {
    const float encoded = linear <= 0.0031308f ? 12.92f * linear : 1.055f * std::pow(linear, 1.0f / 2.4f) - 0.055f;
    return static_cast<unsigned char>(std::lround(std::clamp(encoded, 0.0f, 1.0f) * 255.0f));
}

unsigned char tonemap(float radiance, float exposure) {
    // NaN and infinities carry no brightness we could show; negative radiance is not light.
    if (!std::isfinite(radiance) || radiance <= 0.0f) return 0;
    const float scaled = radiance * exposure;
    // x / (1 + x) tends to 1; a product that overflowed to infinity is that limit.
    const float mapped = std::isfinite(scaled) ? scaled / (1.0f + scaled) : 1.0f;
    return encodeSrgb(mapped);
}

template <typename Body>
void writeImage(const char* kind, const std::string& path, Body&& body) {
    try {
        writeAtomically(path, body);
    } catch (const std::bad_alloc&) {
        throw Error(std::string("cannot write ") + kind + " '" + path + "': out of memory");
    } catch (const std::exception& e) {
        throw Error(std::string("cannot write ") + kind + " '" + path + "': " + e.what());
    }
}

}  // namespace

void writeRgbExr(const std::string& path, int width, int height, const float* rgb) {
    writeImage("EXR image", path, [&](const std::string& temporaryPath) {
        checkImage(width, height, rgb);
        Imf::Header header(width, height);
        header.compression() = Imf::ZIP_COMPRESSION;
        Imf::FrameBuffer buffer;
        const char* names[3] = {"R", "G", "B"};
        const std::size_t pixelStride = 3 * sizeof(float);
        for (int c = 0; c < 3; ++c) {
            header.channels().insert(names[c], Imf::Channel(Imf::FLOAT));
            // OpenEXR wants a non-const pointer even though writing only reads it.
            char* first = const_cast<char*>(reinterpret_cast<const char*>(rgb + c));
            buffer.insert(names[c], Imf::Slice(Imf::FLOAT, first, pixelStride, pixelStride * std::size_t(width)));
        }
        std::ofstream stream = createFile(temporaryPath);
        {
            Imf::StdOFStream exrStream(stream, temporaryPath.c_str());
            useExrWorkerThreads();
            Imf::OutputFile file(exrStream, header);
            file.setFrameBuffer(buffer);
            file.writePixels(height);
        }
        closeFile(stream, temporaryPath);
    });
}

void writeTonemappedPng(const std::string& path, int width, int height, const float* rgb, float exposure) {
    writeImage("PNG image", path, [&](const std::string& temporaryPath) {
        checkImage(width, height, rgb);
        if (!std::isfinite(exposure) || exposure < 0.0f) {
            throw Error("exposure " + std::to_string(exposure) + " must be finite and >= 0");
        }
        const std::size_t count = std::size_t(width) * std::size_t(height) * 3;
        std::vector<unsigned char> pixels(count);
        for (std::size_t i = 0; i < count; ++i) pixels[i] = tonemap(rgb[i], exposure);

        std::vector<unsigned char> encoded;
        const auto append = [](void* context, void* data, int size) {
            auto* out = static_cast<std::vector<unsigned char>*>(context);
            const auto* bytes = static_cast<const unsigned char*>(data);
            out->insert(out->end(), bytes, bytes + size);
        };
        if (stbi_write_png_to_func(append, &encoded, width, height, 3, pixels.data(), width * 3) == 0) {
            throw Error("PNG encoding failed");
        }
        std::ofstream stream = createFile(temporaryPath);
        stream.write(reinterpret_cast<const char*>(encoded.data()), static_cast<std::streamsize>(encoded.size()));
        closeFile(stream, temporaryPath);
    });
}

}  // namespace affinity
