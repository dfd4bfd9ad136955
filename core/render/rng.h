#pragma once
// Deterministic random numbers: PCG32 streams keyed by (seed, frame, pixel, sample), so the
// image does not depend on thread count or scheduling.
#include <cstdint>

namespace affinity::render {

// SplitMix64 finaliser: a good 64-bit mix for building stream keys.
constexpr std::uint64_t mix64(std::uint64_t z) {
    z += 0x9e3779b97f4a7c15ull;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

class Pcg32 {
public:
    Pcg32(std::uint64_t seed, std::uint64_t stream) : inc_((stream << 1u) | 1u) {
        nextUint();
        state_ += seed;
        nextUint();
    }
    std::uint32_t nextUint() {
        std::uint64_t old = state_;
        state_ = old * 6364136223846793005ull + inc_;
        auto xorshifted = std::uint32_t(((old >> 18u) ^ old) >> 27u);
        auto rot = std::uint32_t(old >> 59u);
        return (xorshifted >> rot) | (xorshifted << ((32u - rot) & 31u));
    }
    // Uniform in [0, 1).
    float next() { return float(nextUint() >> 8) * 0x1p-24f; }

private:
    std::uint64_t state_ = 0;
    std::uint64_t inc_;
};

}  // namespace affinity::render
