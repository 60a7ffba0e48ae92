// Local point numbering of a brick: global point ids replaced by their rank among the
// brick's sorted unique ids.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace hpray::partition {

/// Replaces every global point id in `connectivity` by its rank among the sorted unique
/// ids, which it stores in `ids`. When a bitmap over the ids' span (with a running count
/// per 64-bit word) fits `bitmapBytes`, ranks come from the bitmap in linear time;
/// otherwise from a sorted copy of the ids. Both give the same numbering.
void RenumberPoints(std::vector<std::int64_t>& connectivity, std::vector<std::int64_t>& ids,
                    std::size_t bitmapBytes);

}  // namespace hpray::partition
