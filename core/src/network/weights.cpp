#include "affinity/weights.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string_view>

#include "affinity/error.h"

namespace affinity {
namespace {

// Tensor data is handed out in place, so the host must share the file's byte order.
static_assert(std::endian::native == std::endian::little, "weights files are little-endian");

constexpr std::uint64_t kFnvOffsetBasis = 14695981039346656037ull;
constexpr std::uint64_t kFnvPrime = 1099511628211ull;

std::string shapeText(const std::vector<std::int64_t>& shape) {
    std::string text = "[";
    for (std::size_t i = 0; i < shape.size(); ++i) {
        if (i > 0) text += ", ";
        text += std::to_string(shape[i]);
    }
    return text + "]";
}

const char* dtypeName(DType dtype) { return dtype == DType::Float32 ? "float32" : "int32"; }

bool isValidUtf8(std::string_view text) {
    std::size_t i = 0;
    while (i < text.size()) {
        const auto lead = static_cast<unsigned char>(text[i]);
        std::size_t length = 0;
        std::uint32_t codePoint = 0;
        if (lead < 0x80) {
            ++i;
            continue;
        } else if ((lead & 0xE0) == 0xC0) {
            length = 2;
            codePoint = lead & 0x1Fu;
        } else if ((lead & 0xF0) == 0xE0) {
            length = 3;
            codePoint = lead & 0x0Fu;
        } else if ((lead & 0xF8) == 0xF0) {
            length = 4;
            codePoint = lead & 0x07u;
        } else {
            return false;
        }
        if (text.size() - i < length) return false;
        for (std::size_t k = 1; k < length; ++k) {
            const auto next = static_cast<unsigned char>(text[i + k]);
            if ((next & 0xC0) != 0x80) return false;
            codePoint = (codePoint << 6) | (next & 0x3Fu);
        }
        // Overlong encodings, surrogates and values past U+10FFFF are not UTF-8.
        static constexpr std::uint32_t kSmallest[5] = {0, 0, 0x80, 0x800, 0x10000};
        if (codePoint < kSmallest[length] || codePoint > 0x10FFFF || (codePoint >= 0xD800 && codePoint <= 0xDFFF)) {
            return false;
        }
        i += length;
    }
    return true;
}

// Little-endian reads at a cursor confined to [position, end): every read checks that the
// bytes it needs are there, so no value taken from the file can move a read out of range.
class HeaderCursor {
public:
    HeaderCursor(const std::byte* bytes, std::size_t begin, std::size_t end)
        : bytes_(bytes), position_(begin), end_(end) {}

    std::size_t position() const { return position_; }

    std::uint32_t u32(const std::string& what) { return static_cast<std::uint32_t>(little(4, what)); }
    std::uint64_t u64(const std::string& what) { return little(8, what); }

    std::string text(std::size_t length, const std::string& what) {
        require(length, what);
        std::string value(reinterpret_cast<const char*>(bytes_ + position_), length);
        position_ += length;
        return value;
    }

private:
    void require(std::size_t count, const std::string& what) const {
        if (count > end_ - position_) {
            throw Error(what + " at byte " + std::to_string(position_) + " needs " + std::to_string(count) +
                        " bytes but the header ends at byte " + std::to_string(end_));
        }
    }

    std::uint64_t little(std::size_t count, const std::string& what) {
        require(count, what);
        std::uint64_t value = 0;
        for (std::size_t i = 0; i < count; ++i) {
            value |= std::uint64_t(std::to_integer<unsigned>(bytes_[position_ + i])) << (8 * i);
        }
        position_ += count;
        return value;
    }

    const std::byte* bytes_;
    std::size_t position_;
    std::size_t end_;
};

std::uint64_t readU64At(const std::byte* bytes, std::size_t offset) {
    std::uint64_t value = 0;
    for (std::size_t i = 0; i < 8; ++i) {
        value |= std::uint64_t(std::to_integer<unsigned>(bytes[offset + i])) << (8 * i);
    }
    return value;
}

struct TensorRecord {
    TensorView view;
    std::uint64_t offset = 0;
    std::uint64_t byteSize = 0;
};

// Reads record `index`; checks everything that does not depend on other records.
TensorRecord readRecord(HeaderCursor& cursor, std::uint32_t index, std::uint64_t dataBegin, std::uint64_t dataEnd) {
    const std::string label = "tensor record " + std::to_string(index);
    const std::uint32_t nameLength = cursor.u32(label + ": the name length");
    TensorRecord record;
    if (nameLength == 0) throw Error(label + " has an empty name");
    record.view.name = cursor.text(nameLength, label + ": the name of " + std::to_string(nameLength) + " bytes");
    const std::string tensorLabel = label + " ('" + record.view.name + "')";
    if (record.view.name.find('\0') != std::string::npos) {
        throw Error(label + ": the name contains a NUL byte");
    }
    if (!isValidUtf8(record.view.name)) throw Error(label + ": the name is not valid UTF-8");

    const std::uint32_t dtype = cursor.u32(tensorLabel + ": the dtype");
    if (dtype != static_cast<std::uint32_t>(DType::Float32) && dtype != static_cast<std::uint32_t>(DType::Int32)) {
        throw Error(tensorLabel + " has unknown dtype " + std::to_string(dtype) + " (0 = float32, 1 = int32)");
    }
    record.view.dtype = static_cast<DType>(dtype);

    const std::uint32_t rank = cursor.u32(tensorLabel + ": the rank");
    if (rank < 1 || rank > WeightsFormat::kMaxRank) {
        throw Error(tensorLabel + " has rank " + std::to_string(rank) + ", expected 1.." +
                    std::to_string(WeightsFormat::kMaxRank));
    }
    // Elements are 4 bytes; bounding the count by a quarter of the largest u64 keeps both the
    // dims product and the byte size free of overflow.
    constexpr std::uint64_t kMaxElements = std::numeric_limits<std::uint64_t>::max() / 4;
    std::uint64_t count = 1;
    for (std::uint32_t d = 0; d < rank; ++d) {
        const std::uint64_t dim = cursor.u64(tensorLabel + ": dimension " + std::to_string(d));
        if (dim == 0) throw Error(tensorLabel + ": dimension " + std::to_string(d) + " is zero");
        if (dim > kMaxElements / count) {
            throw Error(tensorLabel + ": the product of its dimensions overflows");
        }
        count *= dim;
        record.view.shape.push_back(static_cast<std::int64_t>(dim));
    }
    record.offset = cursor.u64(tensorLabel + ": the data offset");
    record.byteSize = cursor.u64(tensorLabel + ": the data byte size");
    if (record.byteSize != 4 * count) {
        throw Error(tensorLabel + " has data byte size " + std::to_string(record.byteSize) + " but its shape " +
                    shapeText(record.view.shape) + " needs " + std::to_string(4 * count));
    }
    if (record.offset % WeightsFormat::kDataAlignment != 0) {
        throw Error(tensorLabel + " has data offset " + std::to_string(record.offset) + ", not a multiple of " +
                    std::to_string(WeightsFormat::kDataAlignment));
    }
    // Written as subtractions so that no sum of file values can wrap around.
    if (record.offset < dataBegin || record.offset > dataEnd || record.byteSize > dataEnd - record.offset) {
        throw Error(tensorLabel + " has data at bytes [" + std::to_string(record.offset) + ", +" +
                    std::to_string(record.byteSize) + ") outside the data section [" + std::to_string(dataBegin) +
                    ", " + std::to_string(dataEnd) + ")");
    }
    record.view.count = static_cast<std::size_t>(count);
    return record;
}

void checkNoOverlap(std::vector<const TensorRecord*> records) {
    std::sort(records.begin(), records.end(),
              [](const TensorRecord* a, const TensorRecord* b) { return a->offset < b->offset; });
    for (std::size_t i = 1; i < records.size(); ++i) {
        const TensorRecord& before = *records[i - 1];
        const TensorRecord& after = *records[i];
        // Both ranges are inside the data section, so offset + byteSize cannot overflow here.
        if (after.offset < before.offset + before.byteSize) {
            throw Error("the data of tensors '" + before.view.name + "' and '" + after.view.name + "' overlap");
        }
    }
}

}  // namespace

std::uint64_t weightsChecksum(const void* bytes, std::size_t size) {
    const auto* data = static_cast<const unsigned char*>(bytes);
    std::uint64_t hash = kFnvOffsetBasis;
    for (std::size_t i = 0; i < size; ++i) {
        hash ^= data[i];
        hash *= kFnvPrime;
    }
    return hash;
}

Weights::AlignedBytes Weights::allocate(std::size_t size) {
    // At least one byte so that an empty source still yields a valid pointer.
    return AlignedBytes(static_cast<std::byte*>(
        ::operator new[](std::max<std::size_t>(size, 1), std::align_val_t(WeightsFormat::kDataAlignment))));
}

Weights Weights::fromMemory(const void* bytes, std::size_t size, const std::string& sourceName) {
    if (bytes == nullptr && size > 0) {
        throw Error("cannot load weights '" + sourceName + "': null buffer of " + std::to_string(size) + " bytes");
    }
    AlignedBytes copy;
    try {
        copy = allocate(size);
    } catch (const std::bad_alloc&) {
        throw Error("cannot load weights '" + sourceName + "': out of memory for " + std::to_string(size) + " bytes");
    }
    if (size > 0) std::memcpy(copy.get(), bytes, size);
    return parse(std::move(copy), size, sourceName);
}

Weights Weights::fromFile(const std::string& path) {
    const std::string context = "cannot load weights '" + path + "': ";
    std::error_code error;
    const auto status = std::filesystem::status(path, error);
    if (!std::filesystem::exists(status)) throw Error(context + "the file does not exist");
    if (!std::filesystem::is_regular_file(status)) throw Error(context + "not a regular file");
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> file(std::fopen(path.c_str(), "rb"), &std::fclose);
    if (!file) throw Error(context + "cannot open: " + std::strerror(errno));
    if (std::fseek(file.get(), 0, SEEK_END) != 0) throw Error(context + "cannot seek: " + std::strerror(errno));
    const long length = std::ftell(file.get());
    if (length < 0) throw Error(context + "cannot tell its size: " + std::strerror(errno));
    if (std::fseek(file.get(), 0, SEEK_SET) != 0) throw Error(context + "cannot seek: " + std::strerror(errno));
    const auto size = static_cast<std::size_t>(length);
    AlignedBytes bytes;
    try {
        bytes = allocate(size);
    } catch (const std::bad_alloc&) {
        throw Error(context + "out of memory for " + std::to_string(size) + " bytes");
    }
    if (size > 0 && std::fread(bytes.get(), 1, size, file.get()) != size) {
        throw Error(context + "read error or the file shrank while being read");
    }
    return parse(std::move(bytes), size, path);
}

Weights Weights::parse(AlignedBytes bytes, std::size_t size, const std::string& sourceName) {
    try {
        const std::byte* data = bytes.get();
        if (size < sizeof WeightsFormat::kMagic ||
            std::memcmp(data, WeightsFormat::kMagic, sizeof WeightsFormat::kMagic) != 0) {
            throw Error("not a weights file (wrong magic; expected \"AFFWGHTS\")");
        }
        constexpr std::size_t kMinimumSize = WeightsFormat::kHeaderSize + WeightsFormat::kChecksumSize;
        if (size < kMinimumSize) {
            throw Error("truncated: " + std::to_string(size) + " bytes, shorter than the " +
                        std::to_string(kMinimumSize) + "-byte header and checksum");
        }
        HeaderCursor header(data, sizeof WeightsFormat::kMagic, WeightsFormat::kHeaderSize);
        const std::uint32_t version = header.u32("the version");
        if (version != WeightsFormat::kVersion) {
            throw Error("unsupported version " + std::to_string(version) + " (this build reads version " +
                        std::to_string(WeightsFormat::kVersion) + ")");
        }
        const std::uint32_t tensorCount = header.u32("the tensor count");
        const std::uint64_t dataBegin = header.u64("the data section offset");
        const std::uint64_t declaredSize = header.u64("the file size");
        if (declaredSize != size) {
            throw Error("the file size field says " + std::to_string(declaredSize) + " bytes but there are " +
                        std::to_string(size) + " (truncated or padded)");
        }
        const std::size_t checksumOffset = size - WeightsFormat::kChecksumSize;
        const std::uint64_t storedChecksum = readU64At(data, checksumOffset);
        const std::uint64_t computedChecksum = weightsChecksum(data, checksumOffset);
        if (storedChecksum != computedChecksum) {
            throw Error("checksum mismatch (stored " + std::to_string(storedChecksum) + ", computed " +
                        std::to_string(computedChecksum) + "): the file is corrupt");
        }
        const std::uint64_t dataEnd = checksumOffset;
        if (dataBegin < WeightsFormat::kHeaderSize || dataBegin > dataEnd) {
            throw Error("the data section offset " + std::to_string(dataBegin) + " is outside [" +
                        std::to_string(WeightsFormat::kHeaderSize) + ", " + std::to_string(dataEnd) + "]");
        }

        // The records fill the bytes between the fixed header and the data section.
        HeaderCursor records(data, WeightsFormat::kHeaderSize, static_cast<std::size_t>(dataBegin));
        std::vector<TensorRecord> parsed;
        for (std::uint32_t i = 0; i < tensorCount; ++i) {
            parsed.push_back(readRecord(records, i, dataBegin, dataEnd));
        }

        Weights weights;
        weights.source_ = sourceName;
        std::vector<const TensorRecord*> byOffset;
        for (TensorRecord& record : parsed) {
            record.view.data = data + record.offset;
            const std::string name = record.view.name;
            if (!weights.tensors_.emplace(name, record.view).second) {
                throw Error("duplicate tensor name '" + name + "'");
            }
            byOffset.push_back(&record);
        }
        checkNoOverlap(std::move(byOffset));
        weights.storage_ = std::move(bytes);
        return weights;
    } catch (const Error& e) {
        throw Error("cannot load weights '" + sourceName + "': " + e.what());
    } catch (const std::bad_alloc&) {
        throw Error("cannot load weights '" + sourceName + "': out of memory");
    }
}

std::vector<std::string> Weights::names() const {
    std::vector<std::string> result;
    result.reserve(tensors_.size());
    for (const auto& entry : tensors_) result.push_back(entry.first);
    return result;
}

const TensorView& Weights::tensor(const std::string& name) const {
    const auto found = tensors_.find(name);
    if (found == tensors_.end()) {
        throw Error("weights '" + source_ + "': no tensor named '" + name + "'");
    }
    return found->second;
}

const float* Weights::floats(const std::string& name, const std::vector<std::int64_t>& shape) const {
    const TensorView& view = tensor(name);
    if (view.dtype != DType::Float32) {
        throw Error("weights '" + source_ + "': tensor '" + name + "' is " + dtypeName(view.dtype) +
                    ", expected float32");
    }
    if (view.shape != shape) {
        throw Error("weights '" + source_ + "': tensor '" + name + "' has shape " + shapeText(view.shape) +
                    ", expected " + shapeText(shape));
    }
    return static_cast<const float*>(view.data);
}

std::int32_t Weights::integer(const std::string& name) const {
    const TensorView& view = tensor(name);
    if (view.dtype != DType::Int32) {
        throw Error("weights '" + source_ + "': tensor '" + name + "' is " + dtypeName(view.dtype) +
                    ", expected int32");
    }
    if (view.shape != std::vector<std::int64_t>{1}) {
        throw Error("weights '" + source_ + "': tensor '" + name + "' has shape " + shapeText(view.shape) +
                    ", expected [1]");
    }
    std::int32_t value;
    std::memcpy(&value, view.data, sizeof value);
    return value;
}

}  // namespace affinity
