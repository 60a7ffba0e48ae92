// Helpers shared by the partition tests: scratch folders and an independent model of
// cells (node-coordinate keys, centroids, guaranteed boxes) to check bricks against.
#pragma once

#include <unistd.h>

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "elements/basis.h"
#include "elements/bounds.h"
#include "mesh/mesh.h"

namespace hpray::test {

/// A fresh folder under the system temporary folder, removed on destruction.
class ScratchDir {
  public:
    explicit ScratchDir(const std::string& name)
        : path_(std::filesystem::temp_directory_path() /
                ("hpray_test_" + name + "_" + std::to_string(::getpid()))) {
        std::filesystem::remove_all(path_);
        std::filesystem::create_directories(path_);
    }
    ~ScratchDir() {
        std::error_code ec;
        std::filesystem::remove_all(path_, ec);
    }
    std::string operator/(const std::string& name) const {
        return (path_ / name).string();
    }
    std::string str() const { return path_.string(); }

  private:
    std::filesystem::path path_;
};

/// A cell identified by its node coordinates in internal order (exact doubles: the
/// partitioner copies coordinates, never recomputes them).
using CellKey = std::vector<double>;

inline CellKey KeyOf(const Mesh& mesh, std::int64_t c) {
    CellKey key;
    key.push_back(static_cast<double>(mesh.cellShape[c]));
    key.push_back(mesh.cellOrder[c]);
    for (int k = 0; k < mesh.CellNodeCount(c); ++k) {
        const double* p = mesh.points.data() + 3 * mesh.CellNodes(c)[k];
        key.insert(key.end(), p, p + 3);
    }
    return key;
}

/// The mean of the cell's nodes (the partitioner's documented centroid).
inline std::array<double, 3> Centroid(const Mesh& mesh, std::int64_t c) {
    std::array<double, 3> s{0, 0, 0};
    const int n = mesh.CellNodeCount(c);
    for (int k = 0; k < n; ++k)
        for (int d = 0; d < 3; ++d) s[d] += mesh.points[3 * mesh.CellNodes(c)[k] + d];
    for (double& v : s) v /= n;
    return s;
}

/// The guaranteed geometry box: node bounds for order-1 Lagrange cells, the Bernstein
/// hull (plus the nodes) otherwise.
inline Box CellBox(const Mesh& mesh, std::int64_t c) {
    const int n = mesh.CellNodeCount(c);
    std::vector<double> xyz(3 * n);
    Box box;
    box.lo = {1e300, 1e300, 1e300};
    box.hi = {-1e300, -1e300, -1e300};
    for (int k = 0; k < n; ++k)
        for (int d = 0; d < 3; ++d) {
            const double v = mesh.points[3 * mesh.CellNodes(c)[k] + d];
            xyz[3 * k + d] = v;
            box.lo[d] = std::min(box.lo[d], v);
            box.hi[d] = std::max(box.hi[d], v);
        }
    if (mesh.cellOrder[c] > 1 || mesh.cellFamily[c] != CellFamily::Lagrange) {
        const Box g = GeometryBox(
            GetBasis(mesh.cellShape[c], mesh.cellOrder[c], mesh.cellFamily[c]),
            xyz.data());
        for (int d = 0; d < 3; ++d) {
            box.lo[d] = std::min(box.lo[d], g.lo[d]);
            box.hi[d] = std::max(box.hi[d], g.hi[d]);
        }
    }
    return box;
}

}  // namespace hpray::test
