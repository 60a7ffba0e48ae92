// RenumberPoints: ranks from a bitmap over the ids' span, or from a sorted copy.
#include "renumber.h"

#include <algorithm>

namespace hpray::partition {

void RenumberPoints(std::vector<std::int64_t>& connectivity, std::vector<std::int64_t>& ids,
                    std::size_t bitmapBytes) {
    ids.clear();
    if (connectivity.empty()) return;
    const auto [lowest, highest] =
        std::minmax_element(connectivity.begin(), connectivity.end());
    const std::int64_t base = *lowest;
    const std::uint64_t words = (static_cast<std::uint64_t>(*highest - base) >> 6) + 1;
    if (words <= bitmapBytes / 16) {
        std::vector<std::uint64_t> bits(words, 0);
        for (const std::int64_t p : connectivity) {
            const std::uint64_t o = static_cast<std::uint64_t>(p - base);
            bits[o >> 6] |= std::uint64_t(1) << (o & 63);
        }
        std::vector<std::uint64_t> before(words);  // ids set in the words before
        std::uint64_t count = 0;
        for (std::uint64_t w = 0; w < words; ++w) {
            before[w] = count;
            count += static_cast<std::uint64_t>(__builtin_popcountll(bits[w]));
        }
        ids.resize(count);
        std::size_t k = 0;
        for (std::uint64_t w = 0; w < words; ++w)
            for (std::uint64_t word = bits[w]; word != 0; word &= word - 1)
                ids[k++] = base + static_cast<std::int64_t>(64 * w) +
                           __builtin_ctzll(word);
        for (std::int64_t& p : connectivity) {
            const std::uint64_t o = static_cast<std::uint64_t>(p - base);
            const std::uint64_t below = bits[o >> 6] & ((std::uint64_t(1) << (o & 63)) - 1);
            p = static_cast<std::int64_t>(before[o >> 6] +
                                          static_cast<std::uint64_t>(__builtin_popcountll(below)));
        }
        return;
    }
    ids = connectivity;
    std::sort(ids.begin(), ids.end());
    ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
    ids.shrink_to_fit();
    for (std::int64_t& p : connectivity)
        p = std::lower_bound(ids.begin(), ids.end(), p) - ids.begin();
}

}  // namespace hpray::partition
