// k-d decomposition of a mesh into load-balanced bricks (hpray partition).
#pragma once

#include <string>

namespace hpray::partition {

struct PartitionOptions {
    int bricks = 1;
    std::string outDir;
    std::size_t memoryLimitBytes = 0;  ///< 0: a quarter of physical memory
};

/// Not implemented yet: throws NotImplementedError.
void PartitionMesh(const std::string& meshPath, const PartitionOptions& options);

}  // namespace hpray::partition
