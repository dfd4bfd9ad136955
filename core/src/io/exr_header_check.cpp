#include "io/exr_header_check.h"

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <string_view>
#include <vector>

#include "affinity/error.h"

namespace affinity {
namespace {

// OpenEXR's version field: the format version in the low byte, then flags.
constexpr std::uint32_t kVersionMask = 0xFF;
constexpr std::uint32_t kTiledFlag = 0x200;
constexpr std::uint32_t kLongNamesFlag = 0x400;
constexpr std::uint32_t kNonImageFlag = 0x800;
constexpr std::uint32_t kMultiPartFlag = 0x1000;
constexpr std::uint32_t kKnownFlags = kTiledFlag | kLongNamesFlag | kNonImageFlag | kMultiPartFlag;
constexpr std::size_t kLongNameLength = 255;
constexpr std::size_t kShortNameLength = 31;
constexpr std::size_t kChannelRecordBytes = 16;  // pixel type, pLinear + 3 reserved, x/y sampling

// How OpenEXR 3.1 reads the value of each attribute type it knows. Fixed-size types read their
// size whatever the header says, so a different declared size would desynchronise the parse.
enum class ValueLayout { Fixed, Bytes, ChannelList, StringVector, FloatVector, Preview, IdManifest };

struct TypeLayout {
    ValueLayout layout;
    std::uint32_t fixedSize = 0;
};

const std::map<std::string_view, TypeLayout>& knownTypes() {
    static const std::map<std::string_view, TypeLayout> types = {
        {"box2i", {ValueLayout::Fixed, 16}},
        {"box2f", {ValueLayout::Fixed, 16}},
        {"chromaticities", {ValueLayout::Fixed, 32}},
        {"compression", {ValueLayout::Fixed, 1}},
        {"deepImageState", {ValueLayout::Fixed, 1}},
        {"double", {ValueLayout::Fixed, 8}},
        {"envmap", {ValueLayout::Fixed, 1}},
        {"float", {ValueLayout::Fixed, 4}},
        {"int", {ValueLayout::Fixed, 4}},
        {"keycode", {ValueLayout::Fixed, 28}},
        {"lineOrder", {ValueLayout::Fixed, 1}},
        {"m33d", {ValueLayout::Fixed, 72}},
        {"m33f", {ValueLayout::Fixed, 36}},
        {"m44d", {ValueLayout::Fixed, 128}},
        {"m44f", {ValueLayout::Fixed, 64}},
        {"rational", {ValueLayout::Fixed, 8}},
        {"tiledesc", {ValueLayout::Fixed, 9}},
        {"timecode", {ValueLayout::Fixed, 8}},
        {"v2d", {ValueLayout::Fixed, 16}},
        {"v2f", {ValueLayout::Fixed, 8}},
        {"v2i", {ValueLayout::Fixed, 8}},
        {"v3d", {ValueLayout::Fixed, 24}},
        {"v3f", {ValueLayout::Fixed, 12}},
        {"v3i", {ValueLayout::Fixed, 12}},
        {"string", {ValueLayout::Bytes}},
        {"chlist", {ValueLayout::ChannelList}},
        {"stringvector", {ValueLayout::StringVector}},
        {"floatvector", {ValueLayout::FloatVector}},
        {"preview", {ValueLayout::Preview}},
        {"idmanifest", {ValueLayout::IdManifest}},
    };
    return types;
}

// Scanlines per chunk for each compression (the size of the line offset table depends on it).
int linesPerChunk(std::uint8_t compression) {
    static constexpr int kLines[] = {1, 1, 1, 16, 32, 16, 32, 32, 32, 256};
    if (compression >= sizeof kLines / sizeof kLines[0]) {
        throw Error("unknown compression " + std::to_string(compression));
    }
    return kLines[compression];
}

std::uint32_t littleU32(const unsigned char* bytes) {
    return std::uint32_t(bytes[0]) | std::uint32_t(bytes[1]) << 8 | std::uint32_t(bytes[2]) << 16 |
           std::uint32_t(bytes[3]) << 24;
}

std::int32_t littleI32(const unsigned char* bytes) {
    const std::uint32_t value = littleU32(bytes);
    std::int32_t result;
    std::memcpy(&result, &value, sizeof result);
    return result;
}

// Sequential reads that never go past the end of the file.
class HeaderReader {
public:
    HeaderReader(const std::string& path, std::uintmax_t fileSize)
        : stream_(path, std::ios::binary), remaining_(fileSize) {
        if (!stream_) throw Error("cannot open the file");
    }

    std::uintmax_t remaining() const { return remaining_; }

    std::vector<unsigned char> bytes(std::uintmax_t count, const char* what) {
        require(count, what);
        std::vector<unsigned char> data(static_cast<std::size_t>(count));
        stream_.read(reinterpret_cast<char*>(data.data()), static_cast<std::streamsize>(count));
        if (stream_.gcount() != static_cast<std::streamsize>(count)) throw Error("cannot read the header");
        remaining_ -= count;
        return data;
    }

    void skip(std::uintmax_t count, const char* what) {
        require(count, what);
        stream_.seekg(static_cast<std::streamoff>(count), std::ios::cur);
        if (!stream_) throw Error("cannot read the header");
        remaining_ -= count;
    }

    std::uint32_t u32(const char* what) { return littleU32(bytes(4, what).data()); }

    // A NUL-terminated name of at most maxLength characters.
    std::string name(std::size_t maxLength, const char* what) {
        std::string text;
        for (;;) {
            require(1, what);
            char c;
            if (!stream_.get(c)) throw Error("cannot read the header");
            --remaining_;
            if (c == 0) return text;
            if (text.size() == maxLength) {
                throw Error(std::string("a header ") + what + " is longer than " + std::to_string(maxLength) +
                            " characters");
            }
            text += c;
        }
    }

private:
    void require(std::uintmax_t count, const char* what) const {
        if (count > remaining_) {
            throw Error(std::string("the header is truncated (") + what + " needs " + std::to_string(count) +
                        " bytes, " + std::to_string(remaining_) + " left)");
        }
    }

    std::ifstream stream_;
    std::uintmax_t remaining_;
};

// A channel list consumes up to its terminating empty name, whatever its declared size says.
void checkChannelList(const std::vector<unsigned char>& value) {
    std::size_t at = 0;
    for (;;) {
        std::size_t length = 0;
        while (at + length < value.size() && value[at + length] != 0) ++length;
        if (at + length >= value.size()) throw Error("the channel list is not terminated within its size");
        if (length > kLongNameLength) throw Error("a channel name is longer than 255 characters");
        at += length + 1;
        if (length == 0) break;
        if (value.size() - at < kChannelRecordBytes) throw Error("the channel list is truncated");
        at += kChannelRecordBytes;
    }
    if (at != value.size()) throw Error("the channel list ends before its declared size");
}

// OpenEXR reads (length, bytes) pairs until it has read the declared size; a negative length
// would become a huge allocation.
void checkStringVector(const std::vector<unsigned char>& value) {
    std::size_t at = 0;
    while (at < value.size()) {
        if (value.size() - at < 4) throw Error("a string vector entry is truncated");
        const std::int32_t length = littleI32(value.data() + at);
        at += 4;
        if (length < 0 || static_cast<std::size_t>(length) > value.size() - at) {
            throw Error("a string vector entry has length " + std::to_string(length) + " beyond its attribute");
        }
        at += static_cast<std::size_t>(length);
    }
}

// Reads one attribute value, checking that OpenEXR will consume exactly `size` bytes for it
// and allocate no more than that.
void checkAttributeValue(HeaderReader& reader, const std::string& name, const std::string& type, std::uint32_t size) {
    const auto found = knownTypes().find(type);
    const ValueLayout layout = found == knownTypes().end() ? ValueLayout::Bytes : found->second.layout;
    const auto mismatch = [&](const std::string& expected) {
        return Error("header attribute '" + name + "' of type '" + type + "' has size " + std::to_string(size) +
                     ", expected " + expected);
    };
    switch (layout) {
    case ValueLayout::Fixed:
        if (size != found->second.fixedSize) throw mismatch(std::to_string(found->second.fixedSize));
        reader.skip(size, "an attribute value");
        return;
    case ValueLayout::Bytes:
        reader.skip(size, "an attribute value");
        return;
    case ValueLayout::FloatVector:
        if (size % 4 != 0) throw mismatch("a multiple of 4");
        reader.skip(size, "an attribute value");
        return;
    case ValueLayout::IdManifest:
        if (size < 4) throw mismatch("at least 4");
        reader.skip(size, "an attribute value");
        return;
    case ValueLayout::ChannelList:
        checkChannelList(reader.bytes(size, "the channel list"));
        return;
    case ValueLayout::StringVector:
        checkStringVector(reader.bytes(size, "a string vector"));
        return;
    case ValueLayout::Preview: {
        if (size < 8) throw mismatch("at least 8");
        const std::vector<unsigned char> dims = reader.bytes(8, "a preview size");
        const std::uint64_t pixels = std::uint64_t(littleU32(dims.data())) * littleU32(dims.data() + 4);
        if (pixels * 4 != size - 8u) throw mismatch("8 + 4 * the preview's pixel count");
        reader.skip(size - 8u, "the preview pixels");
        return;
    }
    }
}

}  // namespace

void checkExrHeader(const std::string& path) {
    std::error_code error;
    const std::uintmax_t fileSize = std::filesystem::file_size(path, error);
    if (error) throw Error("cannot read the file size: " + error.message());
    HeaderReader reader(path, fileSize);
    reader.skip(4, "the magic number");  // checked by the caller
    const std::uint32_t version = reader.u32("the version field");
    if ((version & kVersionMask) != 2)
        throw Error("unsupported OpenEXR version " + std::to_string(version & kVersionMask));
    if ((version & ~kVersionMask & ~kKnownFlags) != 0) throw Error("unknown OpenEXR flags in the version field");
    if ((version & (kTiledFlag | kNonImageFlag | kMultiPartFlag)) != 0) {
        throw Error("a tiled, deep or multi-part OpenEXR file is not a frame file");
    }
    const std::size_t maxNameLength = (version & kLongNamesFlag) != 0 ? kLongNameLength : kShortNameLength;

    // OpenEXR's defaults when the header leaves them out: a 64 x 64 window and ZIP compression.
    std::int64_t window[4] = {0, 0, 63, 63};
    std::uint8_t compression = 3;
    for (;;) {
        const std::string name = reader.name(maxNameLength, "attribute name");
        if (name.empty()) break;
        const std::string type = reader.name(maxNameLength, "attribute type name");
        const std::int32_t size = littleI32(reader.bytes(4, "an attribute size").data());
        if (size < 0) throw Error("header attribute '" + name + "' has negative size " + std::to_string(size));
        const auto unsignedSize = static_cast<std::uint32_t>(size);
        if (unsignedSize > reader.remaining()) {
            throw Error("header attribute '" + name + "' claims " + std::to_string(size) + " bytes but only " +
                        std::to_string(reader.remaining()) + " are left in the file");
        }
        if ((name == "dataWindow" && type == "box2i") || (name == "compression" && type == "compression")) {
            const std::vector<unsigned char> value = reader.bytes(unsignedSize, "an attribute value");
            if (name == "compression" && value.size() == 1) compression = value[0];
            if (name == "dataWindow" && value.size() == 16) {
                for (int i = 0; i < 4; ++i) window[i] = littleI32(value.data() + 4 * i);
            } else if (value.size() != (name == "compression" ? 1u : 16u)) {
                throw Error("header attribute '" + name + "' has size " + std::to_string(size));
            }
            continue;
        }
        checkAttributeValue(reader, name, type, unsignedSize);
    }

    const std::int64_t width = window[2] - window[0] + 1;
    const std::int64_t height = window[3] - window[1] + 1;
    if (width < 1 || height < 1 || width > kMaxExrImageSide || height > kMaxExrImageSide) {
        throw Error("the data window is " + std::to_string(width) + " x " + std::to_string(height) +
                    "; frame files hold 1.." + std::to_string(kMaxExrImageSide) + " pixels per side");
    }
    // OpenEXR sizes the line offset table from the window before reading it.
    const std::int64_t chunks = (height + linesPerChunk(compression) - 1) / linesPerChunk(compression);
    if (static_cast<std::uintmax_t>(chunks) * 8 > reader.remaining()) {
        throw Error("the file is too short for the line offset table of " + std::to_string(chunks) + " chunks");
    }
}

}  // namespace affinity
