// The allocator's handling of large blocks during set-up (see memory.h).
#include "util/memory.h"

#include <atomic>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace hpray {
namespace {

std::atomic<int> gAlive{0};

}  // namespace

ReuseFreedMemory::ReuseFreedMemory() {
#if defined(__GLIBC__)
    if (gAlive.fetch_add(1) == 0) {
        // Blocks below 1 GiB from the heap, and no heap given back while it lasts.
        mallopt(M_MMAP_THRESHOLD, 1 << 30);
        mallopt(M_TRIM_THRESHOLD, 1 << 30);
    }
#endif
}

ReuseFreedMemory::~ReuseFreedMemory() {
#if defined(__GLIBC__)
    if (gAlive.fetch_sub(1) == 1) {
        malloc_trim(0);
        // What glibc's own adaptation reaches once blocks this large have been freed
        // (its largest mmap threshold, and twice that for trimming); it adapts no more
        // once set.
        mallopt(M_MMAP_THRESHOLD, 32 << 20);
        mallopt(M_TRIM_THRESHOLD, 64 << 20);
    }
#endif
}

}  // namespace hpray
