#pragma once
// Memory for feature maps: small ones from the heap, 64-byte aligned; large ones mapped
// directly, aligned to 2 MiB and advised onto transparent huge pages (Linux), which cuts the TLB
// misses of the stages that read across a whole map (warps, convolutions' row windows, the
// affinity taps): whole and lent 1080p frames ran faster in bench_denoiser for a few MiB more
// peak memory (docs/MODEL.md section 10, "Huge pages").
#include <cstddef>

namespace affinity {

// At least `floats` floats, contents undefined; throws std::bad_alloc.
float* allocateMapMemory(std::size_t floats);
// Gives back what allocateMapMemory(floats) returned (nullptr is ignored).
void releaseMapMemory(float* memory, std::size_t floats) noexcept;

}  // namespace affinity
