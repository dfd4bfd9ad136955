// The affinity filter's AVX-512 path: affinity_strips.h with 16-lane vectors. Built with
// -march=x86-64-v4 (core/CMakeLists.txt) and entered only after a run-time CPU check.
#include "kernels/affinity_strips.h"

namespace affinity {

FilterRowFunction filterRowFunctionAvx512(bool temporal, int features) {
    return filterRowFunction<16>(temporal, features);
}

}  // namespace affinity
