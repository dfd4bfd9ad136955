#include "affinity/frame_io.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCompression.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfMatrixAttribute.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStdIO.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfThreading.h>
#include <OpenEXR/ImfVersion.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <new>
#include <set>
#include <utility>

#include <omp.h>

#include "affinity/atomic_file.h"
#include "affinity/error.h"
#include "io/exr_header_check.h"
#include "io/exr_threads.h"

// The format is specified in docs/FRAME_FILES.md; keep the two in step.
namespace affinity {
namespace {

constexpr int kFormatVersion = 1;

// Two digits cover every sample index and make the (alphabetical) EXR channel order equal the
// sample order.
static_assert(SampleFrame::kMaxSpp <= 100, "sample channel names use two digits");

namespace attr {
constexpr const char* kVersion = "affinity.version";
constexpr const char* kSpp = "affinity.spp";
constexpr const char* kSceneName = "affinity.sceneName";
constexpr const char* kFrameIndex = "affinity.frameIndex";
constexpr const char* kReferenceSpp = "affinity.referenceSpp";
constexpr const char* kSeed = "affinity.seed";
constexpr const char* kWorldToCamera = "affinity.worldToCamera";
constexpr const char* kCameraToClip = "affinity.cameraToClip";
constexpr const char* kChecksum = "affinity.checksum";
}  // namespace attr

constexpr const char* kMotionChannels[2] = {"motion.X", "motion.Y"};
constexpr const char* kValidChannel = "valid.Y";
constexpr const char* kReferenceChannels[3] = {"reference.R", "reference.G", "reference.B"};

std::string sampleChannelName(int sampleIndex, int feature) {
    char prefix[32];
    std::snprintf(prefix, sizeof prefix, "sample%02d.", sampleIndex);
    return prefix + featureChannelName(feature);
}

// Imath stores a matrix for row vectors (p' = p * M); ours is for column vectors (p' = M * p).
// The same transform is therefore the transpose: imath[i][j] = ours[j][i]. Exact both ways.
Imath::M44f toImath(const Matrix4& m) {
    Imath::M44f result;
    for (int i = 0; i < 4; ++i) {
        for (int j = 0; j < 4; ++j) result[i][j] = m[std::size_t(j * 4 + i)];
    }
    return result;
}

Matrix4 fromImath(const Imath::M44f& m) {
    Matrix4 result{};
    for (int i = 0; i < 4; ++i) {
        for (int j = 0; j < 4; ++j) result[std::size_t(j * 4 + i)] = m[i][j];
    }
    return result;
}

// FNV-1a over 32-bit words: cheap, and any single changed word always changes the result
// (each step is a bijection of the state). Guards against silent corruption that the
// decompressors cannot see, e.g. overwritten bytes in an uncompressed file.
class Checksum {
public:
    void add(std::uint32_t word) { hash_ = (hash_ ^ word) * 0x100000001b3ull; }
    void add(int value) { add(static_cast<std::uint32_t>(value)); }
    void add(const float* values, std::size_t count) {
        std::uint64_t hash = hash_;
        for (std::size_t i = 0; i < count; ++i) {
            std::uint32_t word;
            std::memcpy(&word, values + i, sizeof word);
            hash = (hash ^ word) * 0x100000001b3ull;
        }
        hash_ = hash;
    }
    std::string hex() const {
        char text[17];
        std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(hash_));
        return text;
    }

private:
    std::uint64_t hash_ = 0xcbf29ce484222325ull;
};

std::string frameChecksum(const SampleFrame& frame, const std::vector<SampleBand>& bands) {
    Checksum sum;
    const FrameInfo& info = frame.info;
    sum.add(frame.width());
    sum.add(frame.height());
    sum.add(frame.spp());
    sum.add(frame.hasReference() ? 1 : 0);
    sum.add(info.frameIndex);
    sum.add(info.referenceSpp);
    sum.add(static_cast<std::uint32_t>(info.seed));
    sum.add(static_cast<std::uint32_t>(info.seed >> 32));
    sum.add(static_cast<std::uint32_t>(info.sceneName.size()));
    for (char c : info.sceneName) {
        sum.add(static_cast<std::uint32_t>(static_cast<unsigned char>(c)));
    }
    sum.add(info.worldToCamera.data(), 16);
    sum.add(info.cameraToClip.data(), 16);
    const std::size_t rowValues = std::size_t(frame.width()) * std::size_t(frame.spp()) * kFeatureCount;
    for (const SampleBand& band : bands) sum.add(band.samples, std::size_t(band.rows) * rowValues);
    sum.add(frame.motion().data(), frame.motion().size());
    sum.add(frame.valid().data(), frame.valid().size());
    sum.add(frame.reference().data(), frame.reference().size());
    return sum.hex();
}

Imf::Compression toImf(ExrCompression compression) {
    switch (compression) {
    case ExrCompression::None:
        return Imf::NO_COMPRESSION;
    case ExrCompression::Zip:
        return Imf::ZIP_COMPRESSION;
    case ExrCompression::Piz:
        return Imf::PIZ_COMPRESSION;
    }
    throw Error("unknown compression " + std::to_string(static_cast<int>(compression)));
}

// Slice over a strided float buffer; OpenEXR wants non-const pointers even for writing.
Imf::Slice floatSlice(const float* first, std::size_t xStride, std::size_t yStride) {
    return Imf::Slice(Imf::FLOAT, const_cast<char*>(reinterpret_cast<const char*>(first)), xStride * sizeof(float),
                      yStride * sizeof(float));
}

// The frame's samples as one band.
std::vector<SampleBand> wholeFrameBand(const SampleFrame& frame) {
    return {SampleBand{0, frame.height(), const_cast<float*>(frame.samples().data())}};
}

// One place that maps every channel of the format to its place in a SampleFrame, used by both
// the writer and the reader so they cannot disagree. The samples of rows `band` are at
// band.samples (the frame's own when it holds them).
Imf::FrameBuffer frameBufferFor(const SampleFrame& frame, const SampleBand& band) {
    const std::size_t width = std::size_t(frame.width());
    const std::size_t spp = std::size_t(frame.spp());
    Imf::FrameBuffer buffer;
    const std::size_t sampleStride = spp * kFeatureCount;
    // OpenEXR finds row y at origin + y * yStride: the origin of a band's rows lies before its
    // buffer (address arithmetic only; only the band's rows are read or written).
    const std::uintptr_t origin = reinterpret_cast<std::uintptr_t>(band.samples) -
                                  std::uintptr_t(band.firstRow) * sampleStride * width * sizeof(float);
    for (int s = 0; s < frame.spp(); ++s) {
        for (int f = 0; f < kFeatureCount; ++f) {
            buffer.insert(sampleChannelName(s, f),
                          floatSlice(reinterpret_cast<const float*>(origin) + std::size_t(s) * kFeatureCount + f,
                                     sampleStride, sampleStride * width));
        }
    }
    for (int c = 0; c < 2; ++c) {
        buffer.insert(kMotionChannels[c], floatSlice(frame.motion().data() + c, 2, 2 * width));
    }
    buffer.insert(kValidChannel, floatSlice(frame.valid().data(), 1, width));
    if (frame.hasReference()) {
        for (int c = 0; c < 3; ++c) {
            buffer.insert(kReferenceChannels[c], floatSlice(frame.reference().data() + c, 3, 3 * width));
        }
    }
    return buffer;
}

void checkBufferSizes(const SampleFrame& frame) {
    if (frame.width() < 1 || frame.height() < 1) throw Error("the frame is empty");
    const std::size_t pixels = frame.pixelCount();
    const auto check = [](const char* name, std::size_t actual, std::size_t expected) {
        if (actual != expected) {
            throw Error(std::string("the ") + name + " buffer holds " + std::to_string(actual) + " floats, expected " +
                        std::to_string(expected));
        }
    };
    check("samples", frame.samples().size(), pixels * std::size_t(frame.spp()) * kFeatureCount);
    check("motion", frame.motion().size(), pixels * 2);
    check("valid", frame.valid().size(), pixels);
    if (frame.hasReference()) check("reference", frame.reference().size(), pixels * 3);
}

Imf::Header headerFor(const SampleFrame& frame, ExrCompression compression) {
    Imf::Header header(frame.width(), frame.height());
    header.compression() = toImf(compression);
    header.lineOrder() = Imf::INCREASING_Y;
    const Imf::FrameBuffer buffer = frameBufferFor(frame, wholeFrameBand(frame)[0]);
    for (auto it = buffer.begin(); it != buffer.end(); ++it) {
        header.channels().insert(it.name(), Imf::Channel(Imf::FLOAT));
    }
    const FrameInfo& info = frame.info;
    header.insert(attr::kVersion, Imf::IntAttribute(kFormatVersion));
    header.insert(attr::kSpp, Imf::IntAttribute(frame.spp()));
    header.insert(attr::kSceneName, Imf::StringAttribute(info.sceneName));
    header.insert(attr::kFrameIndex, Imf::IntAttribute(info.frameIndex));
    header.insert(attr::kReferenceSpp, Imf::IntAttribute(info.referenceSpp));
    // A string, because an EXR int is 32 bits and a double cannot hold every uint64.
    header.insert(attr::kSeed, Imf::StringAttribute(std::to_string(info.seed)));
    header.insert(attr::kWorldToCamera, Imf::M44fAttribute(toImath(info.worldToCamera)));
    header.insert(attr::kCameraToClip, Imf::M44fAttribute(toImath(info.cameraToClip)));
    header.insert(attr::kChecksum, Imf::StringAttribute(frameChecksum(frame, wholeFrameBand(frame))));
    return header;
}

void writeExr(const std::string& temporaryPath, const Imf::Header& header, const Imf::FrameBuffer& buffer, int height) {
    // Our own stream: ~OutputFile writes the line offset table and swallows errors, so only
    // the stream state after closing tells whether everything reached the file.
    std::ofstream stream(temporaryPath, std::ios::binary | std::ios::trunc);
    if (!stream) {
        throw Error("cannot create '" + temporaryPath + "': " + std::strerror(errno));
    }
    {
        Imf::StdOFStream exrStream(stream, temporaryPath.c_str());
        useExrWorkerThreads();
        Imf::OutputFile file(exrStream, header);
        file.setFrameBuffer(buffer);
        file.writePixels(height);
    }
    stream.close();
    if (stream.fail()) throw Error("writing '" + temporaryPath + "' failed");
}

// --- reading --------------------------------------------------------------------------------

template <typename Attribute>
const Attribute& requireAttribute(const Imf::Header& header, const char* name, const char* expectedType) {
    const auto found = header.find(name);
    if (found == header.end()) throw Error(std::string("missing attribute '") + name + "'");
    const auto* typed = dynamic_cast<const Attribute*>(&found.attribute());
    if (typed == nullptr) {
        throw Error(std::string("attribute '") + name + "' has type '" + found.attribute().typeName() +
                    "', expected '" + expectedType + "'");
    }
    return *typed;
}

int intAttribute(const Imf::Header& header, const char* name) {
    return requireAttribute<Imf::IntAttribute>(header, name, "int").value();
}

const std::string& stringAttribute(const Imf::Header& header, const char* name) {
    return requireAttribute<Imf::StringAttribute>(header, name, "string").value();
}

Matrix4 matrixAttribute(const Imf::Header& header, const char* name) {
    return fromImath(requireAttribute<Imf::M44fAttribute>(header, name, "m44f").value());
}

std::uint64_t parseSeed(const std::string& text) {
    std::uint64_t seed = 0;
    const char* end = text.data() + text.size();
    const auto [next, error] = std::from_chars(text.data(), end, seed);
    if (text.empty() || error != std::errc() || next != end) {
        throw Error(std::string("attribute '") + attr::kSeed + "' is '" + text +
                    "', expected a decimal unsigned 64-bit integer");
    }
    return seed;
}

const char* pixelTypeName(Imf::PixelType type) {
    switch (type) {
    case Imf::UINT:
        return "UINT";
    case Imf::HALF:
        return "HALF";
    case Imf::FLOAT:
        return "FLOAT";
    default:
        return "unknown";
    }
}

void checkChannel(const Imf::ChannelList& channels, const std::string& name) {
    const Imf::Channel* channel = channels.findChannel(name);
    if (channel == nullptr) throw Error("missing channel '" + name + "'");
    if (channel->type != Imf::FLOAT) {
        throw Error("channel '" + name + "' has type " + pixelTypeName(channel->type) + ", expected FLOAT");
    }
    if (channel->xSampling != 1 || channel->ySampling != 1) {
        throw Error("channel '" + name + "' is subsampled; every channel must have sampling 1");
    }
}

// Returns whether the frame has a reference. Every expected channel must be there as FLOAT and
// nothing else may be: a stray channel means a writer disagrees with this format.
bool checkChannels(const Imf::ChannelList& channels, int spp) {
    std::set<std::string> expected;
    for (int s = 0; s < spp; ++s) {
        for (int f = 0; f < kFeatureCount; ++f) expected.insert(sampleChannelName(s, f));
    }
    expected.insert(kMotionChannels[0]);
    expected.insert(kMotionChannels[1]);
    expected.insert(kValidChannel);
    for (const std::string& name : expected) checkChannel(channels, name);

    int referenceChannels = 0;
    for (const char* name : kReferenceChannels) {
        if (channels.findChannel(name) != nullptr) ++referenceChannels;
    }
    const bool hasReference = referenceChannels > 0;
    if (hasReference) {
        for (const char* name : kReferenceChannels) {
            checkChannel(channels, name);
            expected.insert(name);
        }
    }
    for (auto it = channels.begin(); it != channels.end(); ++it) {
        if (expected.count(it.name()) == 0) {
            throw Error(std::string("unexpected channel '") + it.name() + "' (affinity.spp is " + std::to_string(spp) +
                        ")");
        }
    }
    return hasReference;
}

void checkMagic(const std::string& path) {
    std::error_code error;
    const auto status = std::filesystem::status(path, error);
    if (!std::filesystem::exists(status)) throw Error("the file does not exist");
    if (!std::filesystem::is_regular_file(status)) throw Error("not a regular file");
    std::ifstream stream(path, std::ios::binary);
    if (!stream) throw Error(std::string("cannot open the file: ") + std::strerror(errno));
    char magic[4] = {};
    stream.read(magic, sizeof magic);
    if (stream.gcount() != sizeof magic || !Imf::isImfMagic(magic)) {
        throw Error("not an OpenEXR file");
    }
}

// Rows [first, end) of the frame file into `frame` and the bands that hold its samples.
void readRows(Imf::InputFile& file, const SampleFrame& frame, const std::vector<SampleBand>& bands, int first,
              int end) {
    for (const SampleBand& band : bands) {
        const int from = std::max(first, band.firstRow), to = std::min(end, band.firstRow + band.rows);
        if (from >= to) continue;
        file.setFrameBuffer(frameBufferFor(frame, band));
        file.readPixels(from, to - 1);
    }
}

// Rows per compression block of a scanline file (OpenEXR's file format documentation); a wrong
// value here would only make a block be decoded twice.
int linesPerBlock(Imf::Compression compression) {
    switch (compression) {
    case Imf::NO_COMPRESSION:
    case Imf::RLE_COMPRESSION:
    case Imf::ZIPS_COMPRESSION:
        return 1;
    case Imf::ZIP_COMPRESSION:
    case Imf::PXR24_COMPRESSION:
        return 16;
    case Imf::DWAB_COMPRESSION:
        return 256;
    default:
        return 32;  // PIZ, B44, B44A, DWAA
    }
}

// The whole frame, its rows split between OpenMP's threads at compression-block boundaries
// (no block is decoded twice); each thread reads through a file of its own, the first through
// `file`. A 1080p 4-spp PIZ frame read in about the time OpenEXR's own two worker threads took.
void readRowsInParallel(const std::string& path, Imf::InputFile& file, const SampleFrame& frame,
                        const std::vector<SampleBand>& bands) {
    const int height = frame.height();
    const int block = linesPerBlock(file.header().compression());
    const int blocks = (height + block - 1) / block;
    const int readers = std::max(1, std::min(omp_get_max_threads(), blocks));
    std::vector<std::exception_ptr> failures(static_cast<std::size_t>(readers));
#pragma omp parallel num_threads(readers)
    {
        const int reader = omp_get_thread_num(), count = omp_get_num_threads();
        const int first = std::min(height, blocks * reader / count * block);
        const int end = std::min(height, blocks * (reader + 1) / count * block);
        try {
            if (reader == 0) {
                readRows(file, frame, bands, first, end);
            } else {
                Imf::InputFile own(path.c_str(), 0);
                readRows(own, frame, bands, first, end);
            }
        } catch (...) {
            failures[std::size_t(reader)] = std::current_exception();
        }
    }
    for (const std::exception_ptr& failure : failures)
        if (failure) std::rethrow_exception(failure);
}

SampleFrame readFrameFile(const std::string& path, const SampleBandsFor* bandsFor) {
    checkMagic(path);
    checkExrHeader(path);  // before OpenEXR sizes any buffer from the header
    // No worker threads of OpenEXR's own: readRowsInParallel() decodes on OpenMP's threads,
    // each with its own file, so that one compression block per thread is buffered rather than
    // two per OpenEXR thread in every file (a block holds every channel of its rows).
    Imf::InputFile file(path.c_str(), 0);
    const Imf::Header& header = file.header();

    const int version = intAttribute(header, attr::kVersion);
    if (version != kFormatVersion) {
        throw Error("unsupported frame file version " + std::to_string(version) + " (this build reads version " +
                    std::to_string(kFormatVersion) + ")");
    }
    const Imath::Box2i window = header.dataWindow();
    if (window.min.x != 0 || window.min.y != 0) {
        throw Error("the data window starts at (" + std::to_string(window.min.x) + ", " + std::to_string(window.min.y) +
                    "), expected (0, 0)");
    }
    if (window.max.x < 0 || window.max.y < 0 || window.max.x == INT32_MAX || window.max.y == INT32_MAX) {
        throw Error("the data window is empty or too large");
    }
    const int width = window.max.x + 1;
    const int height = window.max.y + 1;
    const int spp = intAttribute(header, attr::kSpp);
    if (spp < 1 || spp > SampleFrame::kMaxSpp) {
        throw Error("attribute '" + std::string(attr::kSpp) + "' is " + std::to_string(spp) + ", expected 1.." +
                    std::to_string(SampleFrame::kMaxSpp));
    }

    FrameInfo info;
    info.sceneName = stringAttribute(header, attr::kSceneName);
    info.frameIndex = intAttribute(header, attr::kFrameIndex);
    info.referenceSpp = intAttribute(header, attr::kReferenceSpp);
    info.seed = parseSeed(stringAttribute(header, attr::kSeed));
    info.worldToCamera = matrixAttribute(header, attr::kWorldToCamera);
    info.cameraToClip = matrixAttribute(header, attr::kCameraToClip);
    const std::string storedChecksum = stringAttribute(header, attr::kChecksum);

    const bool hasReference = checkChannels(header.channels(), spp);
    if (!file.isComplete()) {
        throw Error("the file is incomplete (truncated or still being written)");
    }

    SampleFrame frame = bandsFor ? SampleFrame::withoutSamples(width, height, spp, hasReference)
                                 : SampleFrame(width, height, spp, hasReference);
    frame.info = std::move(info);
    const std::vector<SampleBand> bands = bandsFor ? (*bandsFor)(width, height, spp) : wholeFrameBand(frame);
    int nextRow = 0;
    for (const SampleBand& band : bands) {
        if (band.firstRow != nextRow || band.rows < 1 || band.firstRow + band.rows > height || !band.samples)
            throw Error("the sample bands to read into do not cover the frame's rows in order");
        nextRow += band.rows;
    }
    if (nextRow != height) throw Error("the sample bands to read into do not cover the frame's rows");
    readRowsInParallel(path, file, frame, bands);

    const std::string checksum = frameChecksum(frame, bands);
    if (checksum != storedChecksum) {
        throw Error("checksum mismatch (stored " + storedChecksum + ", computed " + checksum +
                    "): the file is corrupt");
    }
    return frame;
}

}  // namespace

void writeFrame(const std::string& path, const SampleFrame& frame, ExrCompression compression) {
    const std::string context = "cannot write frame file '" + path + "': ";
    try {
        checkBufferSizes(frame);
        const Imf::Header header = headerFor(frame, compression);
        const Imf::FrameBuffer buffer = frameBufferFor(frame, wholeFrameBand(frame)[0]);
        writeAtomically(
            path, [&](const std::string& temporaryPath) { writeExr(temporaryPath, header, buffer, frame.height()); });
    } catch (const std::bad_alloc&) {
        throw Error(context + "out of memory");
    } catch (const std::exception& e) {
        throw Error(context + e.what());
    }
}

std::size_t frameWriteBufferBytes(int width, int height, int spp, bool withReference, ExrCompression compression) {
    // OpenEXR's OutputFile keeps max(1, 2 x worker threads) line buffers, each one compression
    // block of rows, with its compressor's buffers beside it: measured (1024x1024, 16 spp,
    // 2 threads), the whole stays under 2.5 blocks per line buffer for ZIP and PIZ, so 2.5 here.
    // writeExr() sets the worker threads to OpenMP's count (useExrWorkerThreads) if none are set.
    const int threads = Imf::globalThreadCount() > 0 ? Imf::globalThreadCount() : omp_get_max_threads();
    const std::size_t lineBuffers = 2 * std::size_t(std::max(1, threads));
    const std::size_t channels = std::size_t(std::max(spp, 0)) * kFeatureCount + 3 + (withReference ? 3 : 0);
    const std::size_t rows = std::size_t(std::clamp(height, 0, linesPerBlock(toImf(compression))));
    const std::size_t block = rows * std::size_t(std::max(width, 0)) * channels * sizeof(float);
    return lineBuffers * block * 5 / 2;
}

SampleFrame readFrame(const std::string& path) { return readFrame(path, nullptr); }

SampleFrame readFrame(const std::string& path, const SampleBandsFor& bandsFor) {
    // Every failure, including OpenEXR's own exceptions on corrupt data, becomes one Error that
    // names the file.
    const std::string context = "cannot read frame file '" + path + "': ";
    try {
        return readFrameFile(path, bandsFor ? &bandsFor : nullptr);
    } catch (const std::bad_alloc&) {
        throw Error(context + "out of memory (corrupt image size?)");
    } catch (const std::exception& e) {
        throw Error(context + e.what());
    } catch (...) {
        throw Error(context + "unknown error");
    }
}

std::string frameFileName(int frameIndex) {
    if (frameIndex < 0) throw Error("frame index " + std::to_string(frameIndex) + " is negative");
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04d.exr", frameIndex);
    return name;
}

std::vector<std::string> listFrameFiles(const std::string& directory) {
    namespace fs = std::filesystem;
    try {
        if (!fs::is_directory(directory)) {
            throw Error(fs::exists(directory) ? "not a folder" : "the folder does not exist");
        }
        std::vector<std::pair<int, std::string>> frames;
        for (const fs::directory_entry& entry : fs::directory_iterator(directory)) {
            const std::string name = entry.path().filename().string();
            constexpr std::string_view prefix = "frame_", suffix = ".exr";
            if (name.size() <= prefix.size() + suffix.size() || !name.starts_with(prefix) || !name.ends_with(suffix)) {
                continue;
            }
            int index = -1;
            const char* first = name.data() + prefix.size();
            const char* last = name.data() + name.size() - suffix.size();
            const auto [next, error] = std::from_chars(first, last, index);
            // Only the exact spelling frameFileName() produces, so no two files share an index.
            if (error != std::errc() || next != last || index < 0 || name != frameFileName(index)) {
                continue;
            }
            if (!entry.is_regular_file()) continue;
            frames.emplace_back(index, entry.path().string());
        }
        std::sort(frames.begin(), frames.end());
        std::vector<std::string> paths;
        paths.reserve(frames.size());
        for (auto& frame : frames) paths.push_back(std::move(frame.second));
        return paths;
    } catch (const std::exception& e) {
        throw Error("cannot list frame files in '" + directory + "': " + e.what());
    }
}

}  // namespace affinity
