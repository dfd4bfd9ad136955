#pragma once
// Weights files: a versioned binary container of named tensors (docs/MODEL.md section 9).
// Tensor names are the training framework's parameter names. The parser checks every bound
// and throws affinity::Error naming the source and the problem; it never reads out of range.
#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace affinity {

enum class DType : std::uint32_t { Float32 = 0, Int32 = 1 };

struct TensorView {
    std::string name;
    DType dtype = DType::Float32;
    std::vector<std::int64_t> shape;
    const void* data = nullptr;  // 64-byte aligned, owned by the Weights object
    std::size_t count = 0;       // number of elements
};

class Weights {
public:
    static Weights fromFile(const std::string& path);
    static Weights fromMemory(const void* bytes, std::size_t size, const std::string& sourceName);

    const std::string& source() const { return source_; }
    bool has(const std::string& name) const { return tensors_.count(name) > 0; }
    std::vector<std::string> names() const;
    // Throws naming the tensor when it is missing, of another dtype, or of another shape.
    const TensorView& tensor(const std::string& name) const;
    const float* floats(const std::string& name, const std::vector<std::int64_t>& shape) const;
    std::int32_t integer(const std::string& name) const;  // an int32 tensor of shape [1]

private:
    std::string source_;
    std::vector<std::uint64_t> storage_;  // the file's bytes, 8-byte aligned (data offsets are 64-aligned)
    std::map<std::string, TensorView> tensors_;
};

}  // namespace affinity
