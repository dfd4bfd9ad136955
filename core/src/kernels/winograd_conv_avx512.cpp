// The Winograd transforms' AVX-512 path: winograd_transforms.h and coarse_winograd_transforms.h
// with 16-lane vectors. Built with -march=x86-64-v4 (core/CMakeLists.txt) and entered only after
// a run-time CPU check.
#include "kernels/coarse_winograd_transforms.h"
#include "kernels/simd16.h"
#include "kernels/winograd_transforms.h"

namespace affinity {

WinogradTransforms winogradTransformsAvx512() {
    return {winograd_lines::transformPatch<Float16>, winograd_lines::transformOutput<Float16>};
}

CoarseWinogradTransforms coarseWinogradTransformsAvx512() {
    return {coarse_lines::transformPatch<Float16>, coarse_lines::transformOutput<Float16>};
}

}  // namespace affinity
