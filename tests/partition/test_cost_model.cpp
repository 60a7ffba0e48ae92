// The partitioner's cost model: hull areas, the view-averaged segment count it assumes
// (Cauchy's formula, checked by tracing), and its fit to the committed calibration.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>
#include <vector>

#include "cost_model.h"
#include "mesh/builtin.h"
#include "trace/brick_traverser.h"

namespace hpray::partition {
namespace {

TEST(CostModel, HullSurfaceAreasOfUnitCells) {
    const double tet[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
    EXPECT_NEAR(HullSurfaceArea(CellShape::Tet, tet), 1.5 + std::sqrt(3.0) / 2, 1e-15);
    // Corners in the internal order: (0,0,0) (1,0,0) (0,1,0) (1,1,0), then at z = 1.
    const double hex[] = {0, 0, 0, 2, 0, 0, 0, 1, 0, 2, 1, 0,
                          0, 0, 3, 2, 0, 3, 0, 1, 3, 2, 1, 3};
    EXPECT_NEAR(HullSurfaceArea(CellShape::Hex, hex), 2 * (2 + 6 + 3), 1e-14);
    const double wedge[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 2, 1, 0, 2, 0, 1, 2};
    EXPECT_NEAR(HullSurfaceArea(CellShape::Wedge, wedge), 1 + 2 + 2 + 2 * std::sqrt(2.0),
                1e-14);
    const double pyramid[] = {0, 0, 0, 2, 0, 0, 0, 2, 0, 2, 2, 0, 1, 1, 1};
    // Four triangles of base 2 and slant height sqrt(2).
    EXPECT_NEAR(HullSurfaceArea(CellShape::Pyramid, pyramid), 4 + 4 * std::sqrt(2.0),
                1e-14);
}

TEST(CostModel, LinearTetCostEqualsTheGeneralOne) {
    // The partitioner's shortcut for order-1 tets gives the same doubles as the lookup by
    // kind, on random tets of any size and orientation.
    std::mt19937_64 rng(31);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int t = 0; t < 10000; ++t) {
        const double scale = std::pow(10.0, (t % 13) - 6);
        double xyz[12];
        for (double& v : xyz) v = (t % 7) + scale * u(rng);
        const CellCostInput general =
            CellCostFromNodes(CellShape::Tet, 1, CellFamily::Lagrange, xyz);
        const CellCostInput fast = LinearTetCost(xyz);
        ASSERT_EQ(fast.area, general.area) << t;
        ASSERT_EQ(fast.parts.setup, general.parts.setup);
        ASSERT_EQ(fast.parts.perSegment, general.parts.perSegment);
    }
}

TEST(CostModel, HullAreaOfHighOrderCellsUsesTheirCorners) {
    // cube-tets-1 of order 3: five tets filling the unit cube; the hulls of the four
    // corner tets have area 1.5 + sqrt(3)/2, the middle one 4 * sqrt(3)/2.
    const Mesh mesh = MakeBuiltin("builtin:cube-tets-1?order=3");
    ASSERT_EQ(mesh.CellCount(), 5);
    double sum = 0;
    std::vector<double> xyz;
    for (std::int64_t c = 0; c < 5; ++c) {
        xyz.clear();
        for (std::int64_t k = mesh.cellOffsets[c]; k < mesh.cellOffsets[c + 1]; ++k)
            for (int d = 0; d < 3; ++d)
                xyz.push_back(mesh.points[3 * mesh.connectivity[k] + d]);
        sum += CellHullSurfaceArea(CellShape::Tet, 3, CellFamily::Lagrange, xyz.data());
    }
    EXPECT_NEAR(sum, 4 * (1.5 + std::sqrt(3.0) / 2) + 2 * std::sqrt(3.0), 1e-13);
}

// The model's segment count: a view of the data with pixel size h crosses a convex cell
// with S / (4 h^2) rays on average over directions (Cauchy). Checked by tracing parallel
// rays on a grid of spacing h in 200 random directions through the unit cube as 5 * 3^3
// tets: per cell, the mean count over directions against S / (4 h^2).
TEST(CostModel, SegmentsPerCellAverageAQuarterOfTheSurfaceOverThePixelArea) {
    const Mesh mesh = MakeBuiltin("builtin:cube-tets-3");
    const BrickTraverser traverser(Brick::WholeMesh(mesh));
    const std::int64_t cells = mesh.CellCount();
    std::vector<double> count(cells, 0.0), area(cells);
    for (std::int64_t c = 0; c < cells; ++c) {
        double v[12];
        for (int k = 0; k < 4; ++k)
            for (int d = 0; d < 3; ++d)
                v[3 * k + d] =
                    mesh.points[3 * mesh.connectivity[mesh.cellOffsets[c] + k] + d];
        area[c] = HullSurfaceArea(CellShape::Tet, v);
    }
    std::mt19937 rng(11);
    std::normal_distribution<double> normal;
    std::uniform_real_distribution<double> jitter(0, 1);
    const double h = 0.0125;
    const int directions = 200;
    std::vector<Segment> segments;
    for (int k = 0; k < directions; ++k) {
        double d[3], n = 0;
        for (double& x : d) {
            x = normal(rng);
            n += x * x;
        }
        for (double& x : d) x /= std::sqrt(n);
        // An orthonormal frame (u, w) across the direction.
        double u[3] = {-d[1], d[0], 0};
        if (std::abs(d[2]) > 0.9) {
            u[0] = 0;
            u[1] = -d[2];
            u[2] = d[1];
        }
        const double un = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        for (double& x : u) x /= un;
        const double w[3] = {d[1] * u[2] - d[2] * u[1], d[2] * u[0] - d[0] * u[2],
                             d[0] * u[1] - d[1] * u[0]};
        // A randomly shifted grid covering the cube's shadow (radius sqrt(3) / 2).
        const double s0 = jitter(rng) * h, s1 = jitter(rng) * h;
        const int m = static_cast<int>(std::ceil(0.87 / h)) + 1;
        for (int i = -m; i <= m; ++i)
            for (int j = -m; j <= m; ++j) {
                Ray ray;
                for (int a = 0; a < 3; ++a) {
                    ray.origin[a] =
                        0.5 + (i * h + s0) * u[a] + (j * h + s1) * w[a] - 2 * d[a];
                    ray.dir[a] = d[a];
                }
                traverser.Trace(ray, 0, 10, segments);
                for (const Segment& s : segments) count[s.cell] += 1;
            }
    }
    double worst = 0, total = 0, expected = 0;
    for (std::int64_t c = 0; c < cells; ++c) {
        const double model = area[c] / (4 * h * h);
        const double measured = count[c] / directions;
        worst = std::max(worst, std::abs(measured / model - 1));
        total += measured;
        expected += model;
    }
    // About 1,600 rays per cell per direction: the mean over 200 directions is within a
    // few per cent of the directional average for each cell, the total within 1%.
    EXPECT_LT(worst, 0.05) << "worst cell";
    EXPECT_NEAR(total / expected, 1.0, 0.01);
}

// The fit reproduces the measurements it was made from (partition/cost_calibration.csv,
// written by scripts/calibrate_cost.sh): the model's seconds per segment against each
// class measured on at least 10,000 segments (smaller classes are too noisy to judge),
// and the setup of single-class data sets. The median ratio is near one and no class is
// off by more than the spread the model leaves unexplained (curvature severity, cache
// misses of million-cell meshes: see the note in cost_model.h).
TEST(CostModel, ReproducesTheCommittedCalibration) {
    std::ifstream in(std::string(HPRAY_SOURCE_DIR) + "/partition/cost_calibration.csv");
    ASSERT_TRUE(in) << "partition/cost_calibration.csv";
    std::string line;
    std::getline(in, line);
    std::vector<double> ratios, setupRatios;
    while (std::getline(in, line)) {
        std::stringstream ss(line);
        std::vector<std::string> f;
        for (std::string x; std::getline(ss, x, ',');) f.push_back(x);
        ASSERT_EQ(f.size(), 11u) << line;
        const std::string shapeName = f[1];
        CellShape shape = CellShape::Tet;
        for (int s = 0; s < kNumCellShapes; ++s)
            if (shapeName == ShapeName(static_cast<CellShape>(s)))
                shape = static_cast<CellShape>(s);
        const int order = std::stoi(f[2]);
        const CellFamily family =
            f[3] == "serendipity" ? CellFamily::Serendipity : CellFamily::Lagrange;
        const bool curved = f[4] == "1";
        const CellCostParts parts = CellCostModel(shape, order, family, curved);
        const double segments = std::stod(f[9]), perSegment = std::stod(f[10]);
        if (segments >= 10000) ratios.push_back(parts.perSegment / perSegment);
        if (f[7] == "1") setupRatios.push_back(parts.setup / std::stod(f[8]));
    }
    ASSERT_GE(ratios.size(), 25u);
    ASSERT_GE(setupRatios.size(), 15u);
    for (auto* r : {&ratios, &setupRatios}) {
        std::sort(r->begin(), r->end());
        EXPECT_GT((*r)[r->size() / 2], 0.8);
        EXPECT_LT((*r)[r->size() / 2], 1.25);
        EXPECT_GT(r->front(), 1 / 2.5);
        EXPECT_LT(r->back(), 2.5);
    }
}

}  // namespace
}  // namespace hpray::partition
