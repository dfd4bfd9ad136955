#pragma once
// Weights files: a versioned binary container of named tensors (docs/MODEL.md section 9).
// Tensor names are the training framework's parameter names. The parser checks every bound
// and throws affinity::Error naming the source and the problem; it never reads out of range.
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <new>
#include <string>
#include <vector>

namespace affinity {

enum class DType : std::uint32_t { Float32 = 0, Int32 = 1 };

// The layout constants of the file format, shared by the reader and the training-side writer.
struct WeightsFormat {
    static constexpr char kMagic[8] = {'A', 'F', 'F', 'W', 'G', 'H', 'T', 'S'};
    static constexpr std::uint32_t kVersion = 1;
    // magic, u32 version, u32 tensor count, u64 data section offset, u64 file size.
    static constexpr std::size_t kHeaderSize = 8 + 4 + 4 + 8 + 8;
    static constexpr std::size_t kChecksumSize = 8;
    static constexpr std::size_t kDataAlignment = 64;
    static constexpr std::uint32_t kMaxRank = 4;
};

// FNV-1a 64 of `size` bytes: the file's trailing checksum covers every byte before it.
std::uint64_t weightsChecksum(const void* bytes, std::size_t size);

struct TensorView {
    std::string name;
    DType dtype = DType::Float32;
    std::vector<std::int64_t> shape;
    const void* data = nullptr;  // 64-byte aligned, owned by the Weights object
    std::size_t count = 0;       // number of elements
};

// Move-only: the views point into the owned bytes, which a move hands over unchanged.
class Weights {
public:
    Weights() = default;
    Weights(Weights&&) noexcept = default;
    Weights& operator=(Weights&&) noexcept = default;
    Weights(const Weights&) = delete;
    Weights& operator=(const Weights&) = delete;

    static Weights fromFile(const std::string& path);
    static Weights fromMemory(const void* bytes, std::size_t size, const std::string& sourceName);

    const std::string& source() const { return source_; }
    bool has(const std::string& name) const { return tensors_.count(name) > 0; }
    std::vector<std::string> names() const;  // sorted
    // Throws naming the tensor when it is missing, of another dtype, or of another shape.
    const TensorView& tensor(const std::string& name) const;
    const float* floats(const std::string& name, const std::vector<std::int64_t>& shape) const;
    std::int32_t integer(const std::string& name) const;  // an int32 tensor of shape [1]

private:
    struct AlignedDelete {
        void operator()(std::byte* p) const { ::operator delete[](p, std::align_val_t(WeightsFormat::kDataAlignment)); }
    };
    using AlignedBytes = std::unique_ptr<std::byte[], AlignedDelete>;

    static AlignedBytes allocate(std::size_t size);
    // Validates the whole file held in `bytes` and builds the views into it.
    static Weights parse(AlignedBytes bytes, std::size_t size, const std::string& sourceName);

    std::string source_;
    AlignedBytes storage_;  // the file's bytes; data offsets are multiples of 64 from its start
    std::map<std::string, TensorView> tensors_;
};

}  // namespace affinity
