#include "mesh/mesh_order.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <numeric>

namespace hpray {
namespace {

// Spreads the low 21 bits of v to every third bit.
std::uint64_t Spread3(std::uint64_t v) {
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffULL;
    v = (v | v << 16) & 0x1f0000ff0000ffULL;
    v = (v | v << 8) & 0x100f00f00f00f00fULL;
    v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
    v = (v | v << 2) & 0x1249249249249249ULL;
    return v;
}

template <typename Body>
void ParallelFor(std::int64_t n, Body body) {
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, n, 4096),
                      [&](const tbb::blocked_range<std::int64_t>& r) {
                          for (std::int64_t i = r.begin(); i < r.end(); ++i) body(i);
                      });
}

// Sorts keys whose bits below `from` are each item's index in `keys` (so no two are
// equal, and the order of the bits from `from` up, ties by index, is the order of the
// whole keys): a least-significant-digit radix sort of those bits, stable, 11 bits a
// pass, each pass a parallel count and scatter over chunks of the keys.
void SortIndexedKeys(std::vector<std::uint64_t>& keys, int from) {
    constexpr int kDigit = 11, kBuckets = 1 << kDigit, kChunks = 16;
    const std::int64_t n = static_cast<std::int64_t>(keys.size());
    std::vector<std::uint64_t> other(keys.size());
    const std::int64_t chunk = (n + kChunks - 1) / kChunks;
    std::vector<std::int64_t> count(std::size_t(kChunks) * kBuckets);
    for (int shift = from; shift < 64; shift += kDigit) {
        const auto digit = [&](std::uint64_t key) {
            return static_cast<int>(key >> shift & (kBuckets - 1));
        };
        std::fill(count.begin(), count.end(), 0);
        tbb::parallel_for(0, kChunks, [&](int k) {
            std::int64_t* h = &count[std::size_t(k) * kBuckets];
            for (std::int64_t i = k * chunk, end = std::min(n, i + chunk); i < end; ++i)
                ++h[digit(keys[i])];
        });
        // Where chunk k's keys of each digit go: after every smaller digit's keys and the
        // earlier chunks' keys of that digit.
        std::int64_t at = 0;
        for (int b = 0; b < kBuckets; ++b)
            for (int k = 0; k < kChunks; ++k) {
                std::int64_t& c = count[std::size_t(k) * kBuckets + b];
                const std::int64_t m = c;
                c = at;
                at += m;
            }
        tbb::parallel_for(0, kChunks, [&](int k) {
            std::int64_t* next = &count[std::size_t(k) * kBuckets];
            for (std::int64_t i = k * chunk, end = std::min(n, i + chunk); i < end; ++i)
                other[next[digit(keys[i])]++] = keys[i];
        });
        keys.swap(other);
    }
}

template <typename T>
void PermuteBlocks(std::vector<T>& values, const std::vector<std::int64_t>& oldOf,
                   std::size_t block) {
    if (values.empty()) return;
    std::vector<T> out(values.size());
    ParallelFor(static_cast<std::int64_t>(oldOf.size()), [&](std::int64_t i) {
        std::copy_n(values.begin() + static_cast<std::ptrdiff_t>(oldOf[i] * block), block,
                    out.begin() + static_cast<std::ptrdiff_t>(i * block));
    });
    values.swap(out);
}

}  // namespace

std::vector<std::int64_t> OrderSpatially(Mesh& mesh) {
    const std::int64_t nCells = mesh.CellCount(), nPoints = mesh.PointCount();
    std::vector<std::int64_t> cellOld(nCells);
    std::iota(cellOld.begin(), cellOld.end(), 0);
    if (nCells == 0) return cellOld;
    // Keys of 3 x 11 bits of Morton code over 31 bits of index: sorting them orders ties
    // by index. (A brick holds fewer than 2^31 cells; see BrickTraverser.)
    constexpr int kBits = 11;
    if (nCells >= (std::int64_t(1) << 31)) return cellOld;
    const Box box = mesh.Bounds();
    double extent = 0;
    for (int d = 0; d < 3; ++d) extent = std::max(extent, box.hi[d] - box.lo[d]);
    const double top = double((1 << kBits) - 1);
    const double scale = extent > 0 ? top / extent : 0.0;
    // The sort key of item `index` at position x.
    auto keyOf = [&](const double x[3], std::int64_t index) {
        std::uint64_t key = 0;
        for (int d = 0; d < 3; ++d) {
            const double q = (x[d] - box.lo[d]) * scale;
            key |= Spread3(static_cast<std::uint64_t>(std::clamp(q, 0.0, top))) << d;
        }
        return key << 31 | static_cast<std::uint64_t>(index);
    };
    std::vector<std::uint64_t> keyed(nCells);
    ParallelFor(nCells, [&](std::int64_t c) {
        const std::int64_t* nodes = mesh.CellNodes(c);
        const int n = mesh.CellNodeCount(c);
        double centre[3] = {box.lo[0], box.lo[1], box.lo[2]};
        if (n > 0) {
            centre[0] = centre[1] = centre[2] = 0;
            for (int k = 0; k < n; ++k)
                for (int d = 0; d < 3; ++d) centre[d] += mesh.points[3 * nodes[k] + d];
            for (double& x : centre) x /= n;
        }
        keyed[c] = keyOf(centre, c);
    });
    SortIndexedKeys(keyed, 31);
    ParallelFor(nCells, [&](std::int64_t i) {
        cellOld[i] = static_cast<std::int64_t>(keyed[i] & ((std::uint64_t(1) << 31) - 1));
    });
    keyed.clear();
    keyed.shrink_to_fit();

    // Points along the same curve (their own positions).
    std::vector<std::int64_t> newPoint(nPoints), pointOld(nPoints);
    if (nPoints < (std::int64_t(1) << 31)) {
        std::vector<std::uint64_t> pointKey(nPoints);
        ParallelFor(nPoints,
                    [&](std::int64_t p) { pointKey[p] = keyOf(&mesh.points[3 * p], p); });
        SortIndexedKeys(pointKey, 31);
        ParallelFor(nPoints, [&](std::int64_t i) {
            pointOld[i] =
                static_cast<std::int64_t>(pointKey[i] & ((std::uint64_t(1) << 31) - 1));
            newPoint[pointOld[i]] = i;
        });
    } else {
        std::iota(pointOld.begin(), pointOld.end(), 0);
        std::iota(newPoint.begin(), newPoint.end(), 0);
    }

    // Cells: connectivity in the new order with new point indices.
    // The counts in parallel (each a read at a random old cell), then their running sum
    // along the new order in one pass.
    std::vector<std::int64_t> offsets(nCells + 1), connectivity(mesh.connectivity.size());
    offsets[0] = 0;
    ParallelFor(nCells,
                [&](std::int64_t i) { offsets[i + 1] = mesh.CellNodeCount(cellOld[i]); });
    for (std::int64_t i = 0; i < nCells; ++i) offsets[i + 1] += offsets[i];
    ParallelFor(nCells, [&](std::int64_t i) {
        const std::int64_t* nodes = mesh.CellNodes(cellOld[i]);
        const int n = mesh.CellNodeCount(cellOld[i]);
        for (int k = 0; k < n; ++k) connectivity[offsets[i] + k] = newPoint[nodes[k]];
    });
    mesh.cellOffsets.swap(offsets);
    mesh.connectivity.swap(connectivity);
    PermuteBlocks(mesh.cellShape, cellOld, 1);
    PermuteBlocks(mesh.cellOrder, cellOld, 1);
    PermuteBlocks(mesh.cellFamily, cellOld, 1);
    if (static_cast<std::int64_t>(mesh.ghost.size()) == nCells)
        PermuteBlocks(mesh.ghost, cellOld, 1);
    if (static_cast<std::int64_t>(mesh.vtkType.size()) == nCells)
        PermuteBlocks(mesh.vtkType, cellOld, 1);
    for (Field& f : mesh.cellFields)
        PermuteBlocks(f.values, cellOld, static_cast<std::size_t>(f.components));
    PermuteBlocks(mesh.points, pointOld, 3);
    for (Field& f : mesh.pointFields)
        PermuteBlocks(f.values, pointOld, static_cast<std::size_t>(f.components));
    return cellOld;
}

}  // namespace hpray
