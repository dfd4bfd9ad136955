#include "io/exr_threads.h"

#include <OpenEXR/ImfThreading.h>
#include <omp.h>

#include <mutex>

namespace affinity {

void useExrWorkerThreads() {
    static std::once_flag once;
    std::call_once(once, [] {
        if (Imf::globalThreadCount() == 0) Imf::setGlobalThreadCount(omp_get_max_threads());
    });
}

}  // namespace affinity
