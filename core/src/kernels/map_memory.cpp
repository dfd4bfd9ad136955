#include "kernels/map_memory.h"

#include <sys/mman.h>

#include <cstdint>
#include <new>

#if defined(__SANITIZE_ADDRESS__)
#define AFFINITY_HEAP_ONLY 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define AFFINITY_HEAP_ONLY 1
#endif
#endif

namespace affinity {
namespace {

constexpr std::size_t kHugePage = std::size_t(2) << 20;
// Smaller maps stay on the heap: a huge page would be mostly empty.
[[maybe_unused]] constexpr std::size_t kHugePageFloats = 2 * kHugePage / sizeof(float);

std::size_t mappedBytes(std::size_t floats) { return (floats * sizeof(float) + kHugePage - 1) / kHugePage * kHugePage; }

bool onHugePages(std::size_t floats) {
#if defined(AFFINITY_HEAP_ONLY) || !defined(MADV_HUGEPAGE)
    (void)floats;
    return false;  // AddressSanitizer watches heap blocks only; no huge pages to ask for
#else
    return floats >= kHugePageFloats;
#endif
}

}  // namespace

float* allocateMapMemory(std::size_t floats) {
#ifdef MADV_HUGEPAGE
    if (onHugePages(floats)) {
        const std::size_t bytes = mappedBytes(floats);
        // One huge page more than needed, then the unaligned ends trimmed off.
        void* mapped = mmap(nullptr, bytes + kHugePage, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
        if (mapped == MAP_FAILED) throw std::bad_alloc();
        const auto start = reinterpret_cast<std::uintptr_t>(mapped);
        const std::uintptr_t aligned = (start + kHugePage - 1) / kHugePage * kHugePage;
        if (aligned > start) munmap(mapped, aligned - start);
        const std::uintptr_t end = start + bytes + kHugePage, alignedEnd = aligned + bytes;
        if (end > alignedEnd) munmap(reinterpret_cast<void*>(alignedEnd), end - alignedEnd);
        madvise(reinterpret_cast<void*>(aligned), bytes, MADV_HUGEPAGE);  // a hint: failure is harmless
        return reinterpret_cast<float*>(aligned);
    }
#endif
    return static_cast<float*>(::operator new[](floats * sizeof(float), std::align_val_t(64)));
}

void releaseMapMemory(float* memory, std::size_t floats) noexcept {
    if (!memory) return;
    if (onHugePages(floats))
        munmap(memory, mappedBytes(floats));
    else
        ::operator delete[](memory, std::align_val_t(64));
}

}  // namespace affinity
