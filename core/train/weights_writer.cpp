#include "train/weights_writer.h"

#include <cerrno>
#include <cstring>
#include <fstream>
#include <set>

#include "affinity/atomic_file.h"
#include "affinity/error.h"

namespace affinity::train {
namespace {

std::uint64_t alignUp(std::uint64_t value) {
    const std::uint64_t alignment = WeightsFormat::kDataAlignment;
    return (value + alignment - 1) / alignment * alignment;
}

// Writes little-endian fields into a buffer sized in advance.
class ByteWriter {
public:
    explicit ByteWriter(std::vector<std::uint8_t>& out) : out_(out) {}
    void bytes(const void* data, std::size_t size) {
        if (size > 0) std::memcpy(out_.data() + position_, data, size);
        position_ += size;
    }
    void u32(std::uint32_t value) { little(value, 4); }
    void u64(std::uint64_t value) { little(value, 8); }
    void seek(std::size_t position) { position_ = position; }

private:
    void little(std::uint64_t value, int count) {
        for (int i = 0; i < count; ++i) out_[position_++] = static_cast<std::uint8_t>(value >> (8 * i));
    }
    std::vector<std::uint8_t>& out_;
    std::size_t position_ = 0;
};

// Checks the tensor and returns its element count.
std::uint64_t checkedElementCount(const NamedTensor& tensor) {
    const std::string label = "tensor '" + tensor.name + "'";
    if (tensor.name.empty()) throw Error("a tensor has an empty name");
    if (tensor.name.find('\0') != std::string::npos) throw Error(label + ": the name contains a NUL byte");
    if (tensor.shape.empty() || tensor.shape.size() > WeightsFormat::kMaxRank) {
        throw Error(label + " has rank " + std::to_string(tensor.shape.size()) + ", expected 1.." +
                    std::to_string(WeightsFormat::kMaxRank));
    }
    std::uint64_t count = 1;
    for (const std::int64_t dim : tensor.shape) {
        if (dim < 1) throw Error(label + " has dimension " + std::to_string(dim) + ", expected >= 1");
        if (static_cast<std::uint64_t>(dim) > UINT64_MAX / 4 / count) throw Error(label + ": the shape is too large");
        count *= static_cast<std::uint64_t>(dim);
    }
    const bool isFloat = tensor.dtype == DType::Float32;
    if (!isFloat && tensor.dtype != DType::Int32) throw Error(label + " has an unknown dtype");
    const std::size_t held = isFloat ? tensor.floats.size() : tensor.ints.size();
    const std::size_t other = isFloat ? tensor.ints.size() : tensor.floats.size();
    if (held != count || other != 0) {
        throw Error(label + " holds " + std::to_string(tensor.floats.size()) + " floats and " +
                    std::to_string(tensor.ints.size()) + " ints, but its shape needs " + std::to_string(count) +
                    (isFloat ? " floats" : " ints") + " only");
    }
    return count;
}

}  // namespace

std::vector<std::uint8_t> serializeWeights(const std::vector<NamedTensor>& tensors) {
    std::set<std::string> names;
    std::vector<std::uint64_t> byteSizes;
    std::uint64_t recordsSize = 0;
    for (const NamedTensor& tensor : tensors) {
        byteSizes.push_back(4 * checkedElementCount(tensor));
        if (!names.insert(tensor.name).second) throw Error("duplicate tensor name '" + tensor.name + "'");
        recordsSize += 4 + tensor.name.size() + 4 + 4 + 8 * tensor.shape.size() + 8 + 8;
    }
    if (tensors.size() > UINT32_MAX) throw Error("too many tensors");

    // Lay the data out first: each tensor at the next multiple of 64 after the previous one.
    const std::uint64_t dataBegin = alignUp(WeightsFormat::kHeaderSize + recordsSize);
    std::vector<std::uint64_t> offsets;
    std::uint64_t dataEnd = dataBegin;
    for (const std::uint64_t byteSize : byteSizes) {
        dataEnd = alignUp(dataEnd);
        offsets.push_back(dataEnd);
        dataEnd += byteSize;
    }
    const std::uint64_t fileSize = dataEnd + WeightsFormat::kChecksumSize;

    // Padding and gaps stay zero.
    std::vector<std::uint8_t> out(static_cast<std::size_t>(fileSize), 0);
    ByteWriter writer(out);
    writer.bytes(WeightsFormat::kMagic, sizeof WeightsFormat::kMagic);
    writer.u32(WeightsFormat::kVersion);
    writer.u32(static_cast<std::uint32_t>(tensors.size()));
    writer.u64(dataBegin);
    writer.u64(fileSize);
    for (std::size_t i = 0; i < tensors.size(); ++i) {
        const NamedTensor& tensor = tensors[i];
        writer.u32(static_cast<std::uint32_t>(tensor.name.size()));
        writer.bytes(tensor.name.data(), tensor.name.size());
        writer.u32(static_cast<std::uint32_t>(tensor.dtype));
        writer.u32(static_cast<std::uint32_t>(tensor.shape.size()));
        for (const std::int64_t dim : tensor.shape) writer.u64(static_cast<std::uint64_t>(dim));
        writer.u64(offsets[i]);
        writer.u64(byteSizes[i]);
    }
    // The element bytes go in as the (little-endian) host holds them.
    for (std::size_t i = 0; i < tensors.size(); ++i) {
        const NamedTensor& tensor = tensors[i];
        writer.seek(static_cast<std::size_t>(offsets[i]));
        if (tensor.dtype == DType::Float32) {
            writer.bytes(tensor.floats.data(), tensor.floats.size() * sizeof(float));
        } else {
            writer.bytes(tensor.ints.data(), tensor.ints.size() * sizeof(std::int32_t));
        }
    }
    writer.seek(static_cast<std::size_t>(dataEnd));
    writer.u64(weightsChecksum(out.data(), static_cast<std::size_t>(dataEnd)));
    return out;
}

void writeWeightsFile(const std::string& path, const std::vector<NamedTensor>& tensors) {
    const std::string context = "cannot write weights file '" + path + "': ";
    try {
        const std::vector<std::uint8_t> bytes = serializeWeights(tensors);
        writeAtomically(path, [&](const std::string& temporaryPath) {
            std::ofstream stream(temporaryPath, std::ios::binary | std::ios::trunc);
            if (!stream) throw Error("cannot create '" + temporaryPath + "': " + std::strerror(errno));
            stream.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
            stream.close();
            if (stream.fail()) throw Error("writing '" + temporaryPath + "' failed");
        });
    } catch (const std::bad_alloc&) {
        throw Error(context + "out of memory");
    } catch (const std::exception& e) {
        throw Error(context + e.what());
    }
}

}  // namespace affinity::train
