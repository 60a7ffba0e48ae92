// k-d decomposition (its issue has not landed: the entry point reports so).
#include "partition.h"

#include "util/error.h"

namespace hpray::partition {
void PartitionMesh(const std::string&, const PartitionOptions&) {
    throw NotImplementedError("'hpray partition'");
}
}  // namespace hpray::partition
