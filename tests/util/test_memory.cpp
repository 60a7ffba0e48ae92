// ReuseFreedMemory: while it lasts, a large freed block stays with the allocator and
// serves the next one; when it ends, the free memory goes back to the system.
#include <gtest/gtest.h>

#include <cstddef>
#include <cstring>
#include <memory>

#include "util/memory.h"

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace hpray {
namespace {

#if defined(__GLIBC__)
// Bytes the allocator holds free (in its heaps, not given back to the system).
std::size_t FreeHeld() { return mallinfo2().fordblks; }

// A block of n bytes, written, that the compiler may not elide.
char* volatile gSink = nullptr;
std::unique_ptr<char[]> Block(std::size_t n) {
    std::unique_ptr<char[]> block(new char[n]);
    std::memset(block.get(), 1, n);
    gSink = block.get();
    return block;
}

TEST(ReuseFreedMemory, KeepsLargeFreedBlocksWhileItLastsAndReturnsThemAfter) {
    constexpr std::size_t kBlock = 48u << 20;
    const std::size_t before = FreeHeld();
    {
        ReuseFreedMemory reuse;
        Block(kBlock);
        // Freed, but held for the next large block.
        EXPECT_GE(FreeHeld(), before + kBlock);
        const std::unique_ptr<char[]> again = Block(kBlock);
        // Served from what was held.
        EXPECT_LT(FreeHeld(), before + kBlock);
    }
    // Ended: what is free went back.
    EXPECT_LT(FreeHeld(), before + (8u << 20));
}

TEST(ReuseFreedMemory, WithoutItALargeBlockGoesStraightBack) {
    constexpr std::size_t kBlock = 48u << 20;
    const std::size_t before = FreeHeld();
    Block(kBlock);
    EXPECT_LT(FreeHeld(), before + (8u << 20));
}
#endif

}  // namespace
}  // namespace hpray
