#pragma once
// Memory for feature maps: small ones from the heap, 64-byte aligned; large ones mapped
// directly, aligned to 2 MiB and advised onto transparent huge pages (Linux), which cuts the TLB
// misses of the stages that read across a whole map (warps, convolutions' row windows, the
// affinity taps). Measured at 1080p, 4 spp, small model (bench_denoiser, 3 interleaved pairs):
// whole frames 628-637 -> 612-619 ms, lent frames 634-661 -> 608-619 ms; peak memory +6-8 MiB.
#include <cstddef>

namespace affinity {

// At least `floats` floats, contents undefined; throws std::bad_alloc.
float* allocateMapMemory(std::size_t floats);
// Gives back what allocateMapMemory(floats) returned (nullptr is ignored).
void releaseMapMemory(float* memory, std::size_t floats) noexcept;

}  // namespace affinity
