// Tests of BrickTraverser against analytic chords: random and adversarial rays through
// the unit cube cut into every cell shape, non-convex domains, clipping, unshared points,
// inverted cells, threads, and curved quadratic cells that represent a paraboloid
// exactly.
#include <gtest/gtest.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <random>
#include <string>

#include "elements/geometry.h"
#include "elements/mesh_geometry.h"
#include "mesh/builtin.h"
#include "trace/brick_traverser.h"
#include "trace_test_meshes.h"
#include "util/error.h"

namespace hpray {
namespace {

using testing::BoxChord;
using testing::CubeCut;
using testing::GridMesh;
using testing::MakeRay;
using testing::MakeRayDir;
using testing::Vec3;

const Box kUnitBox = {{0, 0, 0}, {1, 1, 1}};

// Segments must be sorted, of positive length, and never overlap; returns the maximal
// runs of exactly touching segments as intervals.
std::vector<std::array<double, 2>> Runs(const std::vector<Segment>& segs,
                                        const std::string& what) {
    std::vector<std::array<double, 2>> runs;
    for (std::size_t i = 0; i < segs.size(); ++i) {
        EXPECT_LT(segs[i].tEnter, segs[i].tExit) << what << " segment " << i;
        if (i > 0) {
            EXPECT_LE(segs[i - 1].tExit, segs[i].tEnter) << what << " overlap at " << i;
        }
        if (!runs.empty() && runs.back()[1] == segs[i].tEnter)
            runs.back()[1] = segs[i].tExit;
        else
            runs.push_back({segs[i].tEnter, segs[i].tExit});
    }
    return runs;
}

double Sum(const std::vector<Segment>& segs) {
    double s = 0;
    for (const auto& g : segs) s += g.tExit - g.tEnter;
    return s;
}

// Does the straight cell c contain X (corners' barycentrics for tets, bounding box else)?
bool CellContains(const Mesh& mesh, std::int64_t c, const double X[3], double tol) {
    const int nv = VertexCount(mesh.cellShape[c]);
    const int p = mesh.cellOrder[c];
    auto corner = [&](int k) {
        const auto lat = VertexLattice(mesh.cellShape[c], p)[k];
        const int node = InternalNodeIndex(mesh.cellShape[c], p, mesh.cellFamily[c], lat);
        return &mesh.points[3 * mesh.CellNodes(c)[node]];
    };
    if (mesh.cellShape[c] == CellShape::Tet) {
        const double *a = corner(0), *b = corner(1), *cc = corner(2), *d = corner(3);
        auto det = [](const double* o, const double* p1, const double* p2,
                      const double* p3) {
            double u[3], v[3], w[3];
            for (int i = 0; i < 3; ++i) {
                u[i] = p1[i] - o[i];
                v[i] = p2[i] - o[i];
                w[i] = p3[i] - o[i];
            }
            return u[0] * (v[1] * w[2] - v[2] * w[1]) -
                   u[1] * (v[0] * w[2] - v[2] * w[0]) +
                   u[2] * (v[0] * w[1] - v[1] * w[0]);
        };
        const double vol = det(a, b, cc, d);
        const double l[4] = {det(X, b, cc, d) / vol, det(a, X, cc, d) / vol,
                             det(a, b, X, d) / vol, det(a, b, cc, X) / vol};
        for (double x : l)
            if (x < -tol) return false;
        return true;
    }
    for (int d = 0; d < 3; ++d) {
        double lo = INFINITY, hi = -INFINITY;
        for (int k = 0; k < nv; ++k) {
            lo = std::min(lo, corner(k)[d]);
            hi = std::max(hi, corner(k)[d]);
        }
        if (X[d] < lo - tol || X[d] > hi + tol) return false;
    }
    return true;
}

// Checks one ray through a mesh of the unit cube: one run equal to the box chord (or,
// for rays lying in the boundary, either the chord or nothing), every segment inside its
// cell.
void CheckCubeRay(const Mesh& mesh, const BrickTraverser& tr, const Ray& ray,
                  const std::string& what, std::vector<Segment>& segs,
                  bool checkCells = true) {
    tr.Trace(ray, -INFINITY, INFINITY, segs);
    const auto runs = Runs(segs, what);
    double t0, t1;
    const bool hit = BoxChord(ray, kUnitBox, t0, t1);
    const double chord = hit ? t1 - t0 : 0;
    // Rays in the boundary planes: the closed box and the open box disagree.
    const Box inner = {{1e-9, 1e-9, 1e-9}, {1 - 1e-9, 1 - 1e-9, 1 - 1e-9}};
    double s0, s1;
    const double innerChord = BoxChord(ray, inner, s0, s1) ? s1 - s0 : 0;
    const bool grazing = std::fabs(innerChord - chord) > 1e-6;
    const double sum = Sum(segs);
    const double tol = 1e-12 * std::max(1.0, chord);
    if (grazing) {
        EXPECT_TRUE(std::fabs(sum) <= tol || std::fabs(sum - chord) <= tol)
            << what << ": sum " << sum << " chord " << chord;
    } else {
        EXPECT_NEAR(sum, chord, tol) << what;
        if (chord > 1e-9) {
            ASSERT_EQ(runs.size(), 1u) << what;
            EXPECT_NEAR(runs[0][0], t0, tol) << what;
            EXPECT_NEAR(runs[0][1], t1, tol) << what;
        }
    }
    for (const auto& g : segs) {
        if (!checkCells) break;
        const double tm = 0.5 * (g.tEnter + g.tExit);
        const double X[3] = {ray.origin[0] + tm * ray.dir[0],
                             ray.origin[1] + tm * ray.dir[1],
                             ray.origin[2] + tm * ray.dir[2]};
        EXPECT_TRUE(CellContains(mesh, g.cell, X, 1e-7)) << what << " cell " << g.cell;
    }
}

struct CubeCase {
    std::string name;
    int randomRays;
};

Mesh MakeCubeMesh(const std::string& name) {
    if (name == "builtin-tets") return MakeBuiltin("builtin:cube-tets-8");
    if (name == "tets-jitter")
        return GridMesh(6, 0.2, [](int, int, int) { return CubeCut::Tets5; });
    if (name == "hex-jitter")
        return GridMesh(7, 0.25, [](int, int, int) { return CubeCut::Hex; });
    if (name == "wedge-jitter")
        return GridMesh(6, 0.2, [](int, int, int) { return CubeCut::Wedges; });
    if (name == "pyramid-tet-jitter")
        return GridMesh(5, 0.2, [](int, int, int) { return CubeCut::PyramidsTetsX; });
    if (name == "hex-straight")
        return GridMesh(5, 0.0, [](int, int, int) { return CubeCut::Hex; });
    // Mixed: columns of hexes, pyramids, wedges and pyramids split into tets along z.
    return GridMesh(6, 0.2, [](int a, int b, int) {
        switch ((a + 2 * b) % 4) {
            case 0:
                return CubeCut::Hex;
            case 1:
                return CubeCut::Pyramids;
            case 2:
                return CubeCut::Wedges;
            default:
                return CubeCut::PyramidsTetsZ;
        }
    });
}

class CubeMeshTest : public ::testing::TestWithParam<CubeCase> {};

TEST_P(CubeMeshTest, RandomRaysGiveTheBoxChord) {
    const Mesh mesh = MakeCubeMesh(GetParam().name);
    const BrickTraverser tr(Brick::WholeMesh(mesh));
    std::mt19937_64 rng(42);
    std::uniform_real_distribution<double> uni(0, 1);
    std::normal_distribution<double> gauss;
    std::vector<Segment> segs;
    for (int i = 0; i < GetParam().randomRays; ++i) {
        Vec3 from, to;
        double len = 0;
        for (int d = 0; d < 3; ++d) {
            from[d] = gauss(rng);
            len += from[d] * from[d];
        }
        // Origins outside (radius 3) and, one in four, inside the cube.
        const bool inside = i % 4 == 0;
        for (int d = 0; d < 3; ++d) {
            from[d] = inside ? uni(rng) : 0.5 + 3 * from[d] / std::sqrt(len);
            to[d] = -0.2 + 1.4 * uni(rng);
        }
        CheckCubeRay(mesh, tr, MakeRay(from, to),
                     GetParam().name + " ray " + std::to_string(i), segs);
        if (::testing::Test::HasFailure()) return;
    }
    const TraceCounters counters = tr.Counters();
    EXPECT_EQ(counters.walkFailures, 0);
}

TEST_P(CubeMeshTest, AdversarialRaysThroughVerticesEdgesAndFaces) {
    const Mesh mesh = MakeCubeMesh(GetParam().name);
    const BrickTraverser tr(Brick::WholeMesh(mesh));
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> uni(0, 1);
    std::vector<Segment> segs;
    auto corner = [&](std::int64_t c, int k) {
        const auto lat = VertexLattice(mesh.cellShape[c], mesh.cellOrder[c])[k];
        const int node = InternalNodeIndex(mesh.cellShape[c], mesh.cellOrder[c],
                                           mesh.cellFamily[c], lat);
        const double* x = &mesh.points[3 * mesh.CellNodes(c)[node]];
        return Vec3{x[0], x[1], x[2]};
    };
    auto randomDir = [&]() {
        return Vec3{uni(rng) - 0.5, uni(rng) - 0.5, uni(rng) - 0.5};
    };
    for (int i = 0; i < 6000; ++i) {
        const std::int64_t c = std::int64_t(uni(rng) * mesh.CellCount());
        const int nv = VertexCount(mesh.cellShape[c]);
        const int ka = int(uni(rng) * nv), kb = (ka + 1 + int(uni(rng) * (nv - 1))) % nv;
        int kc = int(uni(rng) * nv);
        while (kc == ka || kc == kb) kc = (kc + 1) % nv;
        const Vec3 A = corner(c, ka), B = corner(c, kb), C = corner(c, kc);
        Vec3 through, dir;
        std::string kind;
        switch (i % 4) {
            case 0:  // through a vertex
                through = A;
                dir = randomDir();
                kind = "vertex";
                break;
            case 1:  // along the line of two corners (edges and face diagonals)
                through = A;
                for (int d = 0; d < 3; ++d) dir[d] = B[d] - A[d];
                kind = "edge";
                break;
            case 2: {  // inside the plane of three corners (faces)
                const double s = uni(rng), r = uni(rng) * (1 - s);
                for (int d = 0; d < 3; ++d) {
                    through[d] = A[d] + s * (B[d] - A[d]) + r * (C[d] - A[d]);
                    dir[d] = (B[d] - A[d]) + (2 * uni(rng) - 1) * (C[d] - A[d]);
                }
                kind = "face";
                break;
            }
            default: {  // through a point of an edge
                const double s = uni(rng);
                for (int d = 0; d < 3; ++d) through[d] = A[d] + s * (B[d] - A[d]);
                dir = randomDir();
                kind = "edge point";
            }
        }
        // A ray lying along an edge of non-planar (bilinear) faces lies in those faces:
        // its crossings with them are ill-conditioned in t, so only the chord is checked,
        // not which of the cells around the edge each piece is given to.
        const bool planarFaces = tr.Stats().bilinearFaces == 0;
        CheckCubeRay(mesh, tr, MakeRayDir(through, dir),
                     GetParam().name + " " + kind + " ray " + std::to_string(i), segs,
                     planarFaces || kind != "edge");
        if (::testing::Test::HasFailure()) return;
    }
    // Rays inside the boundary planes and along boundary edges, and axis-parallel rays
    // along grid lines and planes (edges and faces of unjittered meshes).
    for (int i = 0; i < 2000; ++i) {
        const int axis = i % 3, other = (axis + 1) % 3, third = (axis + 2) % 3;
        Vec3 through{uni(rng), uni(rng), uni(rng)}, dir{0, 0, 0};
        const double grid[] = {0, 0.125, 0.25, 0.5, 0.75, 1};
        const int mode = (i / 3) % 4;
        if (mode == 0) {  // boundary plane, in-plane direction
            through[axis] = uni(rng) < 0.5 ? 0 : 1;
            dir[other] = uni(rng) - 0.5;
            dir[third] = uni(rng) - 0.5;
        } else if (mode == 1) {  // boundary edge
            through[axis] = uni(rng) < 0.5 ? 0 : 1;
            through[other] = uni(rng) < 0.5 ? 0 : 1;
            dir[third] = 1;
        } else if (mode == 2) {  // grid line parallel to an axis
            through[other] = grid[i % 6];
            through[third] = grid[(i / 6) % 6];
            dir[axis] = i % 2 ? 1 : -1;
        } else {  // grid plane, diagonal in-plane direction
            through[axis] = grid[i % 6];
            dir[other] = 1;
            dir[third] = uni(rng) < 0.5 ? 1 : -1;
        }
        CheckCubeRay(mesh, tr, MakeRayDir(through, dir),
                     GetParam().name + " boundary/grid ray " + std::to_string(i), segs);
        if (::testing::Test::HasFailure()) return;
    }
}

INSTANTIATE_TEST_SUITE_P(
    Shapes, CubeMeshTest,
    ::testing::Values(CubeCase{"builtin-tets", 100000}, CubeCase{"tets-jitter", 100000},
                      CubeCase{"hex-jitter", 100000}, CubeCase{"wedge-jitter", 100000},
                      CubeCase{"pyramid-tet-jitter", 100000}, CubeCase{"mixed", 100000},
                      CubeCase{"hex-straight", 5000}),
    [](const auto& info) {
        std::string s = info.param.name;
        std::replace(s.begin(), s.end(), '-', '_');
        return s;
    });

TEST(BrickTraverser, FaceCountsOfCubeTets) {
    for (int n : {1, 3}) {
        const Mesh mesh = MakeBuiltin("builtin:cube-tets-" + std::to_string(n));
        const BrickTraverser tr(Brick::WholeMesh(mesh));
        const auto& s = tr.Stats();
        EXPECT_EQ(s.cells, 5 * n * n * n);
        EXPECT_EQ(s.boundaryFaces, 12 * n * n);  // 6 sides, n^2 squares, 2 triangles
        EXPECT_EQ(s.faces, (4 * 5 * n * n * n + 12 * n * n) / 2);
        EXPECT_EQ(s.mergedPoints, (n + 1) * (n + 1) * (n + 1));
        EXPECT_EQ(s.curvedFaces, 0);
        EXPECT_GT(s.Bytes(), 0u);
    }
}

TEST(BrickTraverser, FiveTetsAndFiveTimes40CubedTetsGiveTheSameChords) {
    const Mesh coarse = MakeBuiltin("builtin:cube-tets-1");
    const Mesh fine = MakeBuiltin("builtin:cube-tets-40");
    const BrickTraverser a(Brick::WholeMesh(coarse)), b(Brick::WholeMesh(fine));
    std::mt19937_64 rng(9);
    std::uniform_real_distribution<double> uni(-0.3, 1.3);
    std::vector<Segment> sa, sb;
    for (int i = 0; i < 2000; ++i) {
        const Ray ray = MakeRay({uni(rng) * 4 - 2, uni(rng) * 4 - 2, -2.5},
                                {uni(rng), uni(rng), uni(rng)});
        a.Trace(ray, -INFINITY, INFINITY, sa);
        b.Trace(ray, -INFINITY, INFINITY, sb);
        double t0, t1;
        const double chord = BoxChord(ray, kUnitBox, t0, t1) ? t1 - t0 : 0;
        EXPECT_NEAR(Sum(sa), chord, 1e-12 * std::max(1.0, chord)) << i;
        EXPECT_NEAR(Sum(sb), Sum(sa), 1e-12 * std::max(1.0, chord)) << i;
        EXPECT_LE(Runs(sb, "fine").size(), 1u);
    }
}

// The union of the kept cubes' chords, as merged intervals.
std::vector<std::array<double, 2>> CubeUnionIntervals(
    const Ray& ray, int n, const std::function<bool(int, int, int)>& keep) {
    std::vector<std::array<double, 2>> iv;
    for (int c = 0; c < n; ++c)
        for (int b = 0; b < n; ++b)
            for (int a = 0; a < n; ++a) {
                if (!keep(a, b, c)) continue;
                const Box box = {{double(a) / n, double(b) / n, double(c) / n},
                                 {double(a + 1) / n, double(b + 1) / n, double(c + 1) / n}};
                double t0, t1;
                if (BoxChord(ray, box, t0, t1) && t1 > t0) iv.push_back({t0, t1});
            }
    std::sort(iv.begin(), iv.end());
    std::vector<std::array<double, 2>> merged;
    for (const auto& x : iv) {
        if (!merged.empty() && x[0] <= merged.back()[1] + 1e-12)
            merged.back()[1] = std::max(merged.back()[1], x[1]);
        else
            merged.push_back(x);
    }
    return merged;
}

TEST(BrickTraverser, NonConvexDisconnectedMeshWithCavity) {
    const int n = 4;
    // An L-shaped prism (cubes with a, b >= 2 removed), a closed cavity at (1,1,1), and a
    // disconnected bar (the slab a = 2 removed for b < 2 cuts off a = 3).
    const auto keep = [](int a, int b, int c) {
        if (a >= 2 && b >= 2) return false;
        if (a == 1 && b == 1 && c == 1) return false;
        if (a == 2) return false;
        return true;
    };
    for (CubeCut cut : {CubeCut::Hex, CubeCut::Tets5}) {
        const Mesh mesh = GridMesh(
            n, 0.0, [cut](int, int, int) { return cut; }, keep);
        const BrickTraverser tr(Brick::WholeMesh(mesh));
        std::mt19937_64 rng(5);
        std::uniform_real_distribution<double> uni(0, 1);
        std::vector<Segment> segs;
        int multi = 0;
        for (int i = 0; i < 5000; ++i) {
            const Ray ray =
                MakeRay({uni(rng) * 3 - 1, uni(rng) * 3 - 1, uni(rng) * 3 - 1},
                        {uni(rng), uni(rng), uni(rng)});
            tr.Trace(ray, -INFINITY, INFINITY, segs);
            const auto runs = Runs(segs, "non-convex");
            const auto truth = CubeUnionIntervals(ray, n, keep);
            // Intervals shorter than rounding can vanish; compare the others.
            std::vector<std::array<double, 2>> expect;
            for (const auto& x : truth)
                if (x[1] - x[0] > 1e-9) expect.push_back(x);
            std::vector<std::array<double, 2>> got;
            for (const auto& x : runs)
                if (x[1] - x[0] > 1e-9) got.push_back(x);
            ASSERT_EQ(got.size(), expect.size()) << i;
            for (std::size_t k = 0; k < got.size(); ++k) {
                EXPECT_NEAR(got[k][0], expect[k][0], 1e-12) << i;
                EXPECT_NEAR(got[k][1], expect[k][1], 1e-12) << i;
            }
            multi += expect.size() > 1;
        }
        EXPECT_GT(multi, 500);
    }
}

TEST(BrickTraverser, ClipsToSubBoxAndRange) {
    const Mesh mesh = GridMesh(6, 0.2, [](int, int, int) { return CubeCut::Wedges; });
    const Box sub = {{0.2, 0.1, 0.3}, {0.7, 0.9, 0.6}};
    const BrickTraverser tr(Brick{&mesh, sub});
    const BrickTraverser whole(Brick::WholeMesh(mesh));
    std::mt19937_64 rng(13);
    std::uniform_real_distribution<double> uni(0, 1);
    std::vector<Segment> segs, all;
    for (int i = 0; i < 5000; ++i) {
        const Ray ray = MakeRay({uni(rng) * 3 - 1, uni(rng) * 3 - 1, -1.5},
                                {uni(rng), uni(rng), uni(rng)});
        const double tMin = 1.0 + uni(rng), tMax = tMin + 1.5 * uni(rng);
        tr.Trace(ray, tMin, tMax, segs);
        double t0, t1;
        double expect = 0;
        if (BoxChord(ray, sub, t0, t1))
            expect = std::max(0.0, std::min(t1, tMax) - std::max(t0, tMin));
        EXPECT_NEAR(Sum(segs), expect, 1e-12) << i;
        EXPECT_LE(Runs(segs, "clip").size(), 1u) << i;
        // The clipped segments are the whole-mesh segments cut at the clip range.
        whole.Trace(ray, -INFINITY, INFINITY, all);
        std::vector<Segment> cut;
        const double a = std::max(t0, tMin), b = std::min(t1, tMax);
        for (const auto& g : all) {
            const double x = std::max(g.tEnter, a), y = std::min(g.tExit, b);
            if (x < y) cut.push_back({g.cell, x, y});
        }
        ASSERT_EQ(cut.size(), segs.size()) << i;
        for (std::size_t k = 0; k < cut.size(); ++k) {
            EXPECT_EQ(cut[k].cell, segs[k].cell) << i;
            EXPECT_EQ(cut[k].tEnter, segs[k].tEnter) << i;
            EXPECT_EQ(cut[k].tExit, segs[k].tExit) << i;
        }
    }
}

// Every cell gets private copies of its nodes, as deal.II writes them; optionally the
// copies are moved by `noise` (much less than the merge tolerance).
Mesh Unshare(const Mesh& in, double noise) {
    Mesh out;
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> uni(-1, 1);
    for (std::int64_t c = 0; c < in.CellCount(); ++c) {
        std::vector<std::int64_t> nodes;
        for (int k = 0; k < in.CellNodeCount(c); ++k) {
            const std::int64_t p = in.CellNodes(c)[k];
            for (int d = 0; d < 3; ++d)
                out.points.push_back(in.points[3 * p + d] + noise * uni(rng));
            nodes.push_back(out.PointCount() - 1);
        }
        out.AddCell(in.cellShape[c], in.cellOrder[c], in.cellFamily[c], nodes.data(),
                    int(nodes.size()));
    }
    return out;
}

TEST(BrickTraverser, UnsharedPointsAreMergedByPosition) {
    const Mesh shared = MakeCubeMesh("mixed");
    for (double noise : {0.0, 1e-14}) {
        const Mesh unshared = Unshare(shared, noise);
        const BrickTraverser a(Brick::WholeMesh(shared)), b(Brick::WholeMesh(unshared));
        EXPECT_EQ(b.Stats().mergedPoints, a.Stats().mergedPoints);
        EXPECT_EQ(b.Stats().boundaryFaces, a.Stats().boundaryFaces);
        std::mt19937_64 rng(21);
        std::uniform_real_distribution<double> uni(0, 1);
        std::vector<Segment> sa, sb;
        for (int i = 0; i < 3000; ++i) {
            const Ray ray = MakeRay({uni(rng) * 3 - 1, uni(rng) * 3 - 1, -1.5},
                                    {uni(rng), uni(rng), uni(rng)});
            a.Trace(ray, -INFINITY, INFINITY, sa);
            b.Trace(ray, -INFINITY, INFINITY, sb);
            // Faces are canonical by position, so bitwise equal positions give bitwise
            // equal segments; copies moved by 1e-14 give the same chords (which cell a
            // ray grazing a non-planar face is in may change with the split diagonal).
            if (noise == 0) {
                ASSERT_EQ(sa.size(), sb.size()) << i;
                for (std::size_t k = 0; k < sa.size(); ++k) {
                    EXPECT_EQ(sa[k].cell, sb[k].cell) << i;
                    EXPECT_EQ(sa[k].tEnter, sb[k].tEnter) << i;
                    EXPECT_EQ(sa[k].tExit, sb[k].tExit) << i;
                }
            }
            EXPECT_NEAR(Sum(sa), Sum(sb), 1e-12) << "noise " << noise << " ray " << i;
            EXPECT_EQ(Runs(sb, "unshared").size(), Runs(sa, "shared").size());
        }
    }
}

// The face points of a tet walk: the segments are the plain Trace's; every face point is
// a convex combination of its face's corners (which are corners of the segment's cell)
// that lies on the ray at its t, to rounding; the exit of a segment is bitwise the entry
// of the next one; and a segment clipped by the range or the box lies between them.
TEST(BrickTraverser, FacePointsOfTetsLieOnTheRayAndAreSharedByNeighbours) {
    const Mesh mesh = GridMesh(5, 0.3, [](int, int, int) { return CubeCut::Tets5; });
    Box sub{{0.1, -1, 0.2}, {0.95, 2, 0.8}};
    std::mt19937_64 rng(8);
    std::uniform_real_distribution<double> uni(0, 1);
    for (const Box& box : {mesh.Bounds(), sub}) {
        const BrickTraverser tr(Brick{&mesh, box});
        ASSERT_TRUE(tr.FacePoints());
        std::vector<Segment> plain, segs;
        std::vector<SegmentEnds> ends;
        std::size_t checked = 0;
        for (int i = 0; i < 2000; ++i) {
            const Ray ray = MakeRay({uni(rng) * 3 - 1, uni(rng) * 3 - 1, -1.5},
                                    {uni(rng), uni(rng), uni(rng)});
            const double tMin = i % 3 == 0 ? 1.6 + uni(rng) : -INFINITY;
            const double tMax = i % 5 == 0 ? 2.2 + uni(rng) : INFINITY;
            tr.Trace(ray, tMin, tMax, plain);
            tr.Trace(ray, tMin, tMax, segs, &ends);
            ASSERT_EQ(segs.size(), plain.size()) << i;
            ASSERT_EQ(ends.size(), segs.size()) << i;
            for (std::size_t k = 0; k < segs.size(); ++k) {
                const Segment& s = segs[k];
                EXPECT_EQ(s.cell, plain[k].cell);
                EXPECT_EQ(s.tEnter, plain[k].tEnter);
                EXPECT_EQ(s.tExit, plain[k].tExit);
                const FacePoint* fp[2] = {&ends[k].enter, &ends[k].exit};
                ASSERT_TRUE(fp[0]->Valid() && fp[1]->Valid()) << i << " " << k;
                EXPECT_LE(fp[0]->t, s.tEnter);
                EXPECT_GE(fp[1]->t, s.tExit);
                const std::int64_t* nodes = mesh.CellNodes(s.cell);
                for (const FacePoint* p : fp) {
                    double sum = 0, x[3] = {0, 0, 0};
                    for (int m = 0; m < 3; ++m) {
                        EXPECT_GE(p->w[m], 0.0);
                        sum += p->w[m];
                        EXPECT_TRUE(std::find(nodes, nodes + 4, p->v[m]) != nodes + 4)
                            << "corner " << p->v[m] << " is not a node of cell "
                            << s.cell;
                        for (int d = 0; d < 3; ++d)
                            x[d] += p->w[m] * mesh.points[3 * p->v[m] + d];
                    }
                    EXPECT_NEAR(sum, 1.0, 1e-15);
                    double dist = 0;
                    for (int d = 0; d < 3; ++d)
                        dist = std::max(
                            dist, std::abs(x[d] - (ray.origin[d] + p->t * ray.dir[d])));
                    EXPECT_LE(dist, 1e-14) << i << " " << k;
                    EXPECT_GT(p->cornerError, 0.0);
                    EXPECT_LE(p->cornerError, 1e-14);
                }
                if (k + 1 < segs.size() && segs[k + 1].tEnter == s.tExit) {
                    const FacePoint& a = ends[k].exit;
                    const FacePoint& b = ends[k + 1].enter;
                    EXPECT_EQ(a.t, b.t);
                    for (int m = 0; m < 3; ++m) {
                        EXPECT_EQ(a.v[m], b.v[m]);
                        EXPECT_EQ(a.w[m], b.w[m]);
                    }
                }
                ++checked;
            }
        }
        EXPECT_GT(checked, 10000u);
    }
    // Points merged by position are not the mesh's own: no face points.
    const Mesh unshared = Unshare(MakeBuiltin("builtin:cube-tets-3"), 0.0);
    const BrickTraverser merged(Brick::WholeMesh(unshared));
    EXPECT_FALSE(merged.FacePoints());
    std::vector<Segment> segs;
    std::vector<SegmentEnds> ends;
    merged.Trace(MakeRay({0.3, 0.4, -1}, {0.6, 0.5, 2}), -INFINITY, INFINITY, segs,
                 &ends);
    ASSERT_FALSE(segs.empty());
    for (const SegmentEnds& e : ends) EXPECT_FALSE(e.enter.Valid() || e.exit.Valid());
}

// A tet entered from a wedge or a pyramid through a triangle has its face points too
// (which let the volume take its linear field from them): the exit point of the cell
// before, on the ray, convex in the entry face's corners. Cells of other shapes have
// one only on a face into a tet.
TEST(BrickTraverser, TetsEnteredFromOtherShapesHaveFacePoints) {
    // Wedges, pyramids and pyramids split into tets (planar faces). A pyramid's base
    // against two tets' triangles does not match: the walk ends and starts again there.
    const Mesh mesh = GridMesh(5, 0.0, [](int a, int b, int c) {
        switch ((a + 2 * b + c) % 3) {
            case 0:
                return CubeCut::Wedges;
            case 1:
                return CubeCut::Pyramids;
            default:
                return CubeCut::PyramidsTetsZ;
        }
    });
    const BrickTraverser tr(Brick::WholeMesh(mesh));
    ASSERT_TRUE(tr.FacePoints());
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> uni(0, 1);
    std::vector<Segment> segs;
    std::vector<SegmentEnds> ends;
    std::size_t fromOthers = 0;
    for (int i = 0; i < 3000; ++i) {
        const Ray ray = MakeRay({uni(rng) * 3 - 1, uni(rng) * 3 - 1, -1.5},
                                {uni(rng), uni(rng), uni(rng)});
        tr.Trace(ray, -INFINITY, INFINITY, segs, &ends);
        ASSERT_EQ(ends.size(), segs.size());
        for (std::size_t k = 0; k + 1 < segs.size(); ++k) {
            const Segment& s = segs[k];
            const FacePoint& q = ends[k].exit;
            if (mesh.cellShape[s.cell] == CellShape::Tet || !q.Valid()) continue;
            // A face point on another cell's exit: into a tet, the next segment's entry.
            const Segment& next = segs[k + 1];
            ASSERT_EQ(mesh.cellShape[next.cell], CellShape::Tet) << i << " " << k;
            ASSERT_EQ(next.tEnter, s.tExit);
            ++fromOthers;
            const FacePoint& p = ends[k + 1].enter;
            ASSERT_TRUE(p.Valid() && ends[k + 1].exit.Valid()) << i << " " << k;
            EXPECT_EQ(q.t, p.t);
            EXPECT_EQ(p.t, next.tEnter);
            const std::int64_t* nodes = mesh.CellNodes(next.cell);
            const std::int64_t* before = mesh.CellNodes(s.cell);
            const int beforeCount = mesh.CellNodeCount(s.cell);
            double x[3] = {0, 0, 0}, sum = 0;
            for (int m = 0; m < 3; ++m) {
                EXPECT_EQ(q.v[m], p.v[m]);
                EXPECT_EQ(q.w[m], p.w[m]);
                EXPECT_GE(p.w[m], 0.0);
                sum += p.w[m];
                // A corner of the face the two cells share.
                EXPECT_TRUE(std::find(nodes, nodes + 4, p.v[m]) != nodes + 4);
                EXPECT_TRUE(std::find(before, before + beforeCount, p.v[m]) !=
                            before + beforeCount);
                for (int d = 0; d < 3; ++d) x[d] += p.w[m] * mesh.points[3 * p.v[m] + d];
            }
            EXPECT_NEAR(sum, 1.0, 1e-15);
            for (int d = 0; d < 3; ++d)
                EXPECT_NEAR(x[d], ray.origin[d] + p.t * ray.dir[d], 1e-14)
                    << i << " " << k;
        }
    }
    EXPECT_GT(fromOthers, 500u);
}

TEST(BrickTraverser, InvertedCellsAreTraversedLikePositiveOnes) {
    const Mesh mesh = MakeBuiltin("builtin:cube-tets-4");
    Mesh flipped = mesh;
    for (std::int64_t c = 0; c < flipped.CellCount(); c += 2)
        std::swap(flipped.connectivity[flipped.cellOffsets[c] + 1],
                  flipped.connectivity[flipped.cellOffsets[c] + 2]);
    const BrickTraverser a(Brick::WholeMesh(mesh)), b(Brick::WholeMesh(flipped));
    std::mt19937_64 rng(4);
    std::uniform_real_distribution<double> uni(0, 1);
    std::vector<Segment> sa, sb;
    for (int i = 0; i < 2000; ++i) {
        const Ray ray = MakeRay({uni(rng) * 3 - 1, uni(rng) * 3 - 1, -1.5},
                                {uni(rng), uni(rng), uni(rng)});
        a.Trace(ray, -INFINITY, INFINITY, sa);
        b.Trace(ray, -INFINITY, INFINITY, sb);
        ASSERT_EQ(sa.size(), sb.size()) << i;
        for (std::size_t k = 0; k < sa.size(); ++k)
            EXPECT_EQ(sa[k].cell, sb[k].cell) << i;
        EXPECT_NEAR(Sum(sa), Sum(sb), 1e-13);
    }
}

// Two tetrahedra on one shared triangle, the second's apex at (0.2, 0.2, z), each with
// its corners given in either orientation: the pair is valid exactly when the apexes lie
// on opposite sides of the triangle, whichever way each cell lists its corners.
TEST(BrickTraverser, TetsOnTheSameSideOfTheirSharedFaceAreRejected) {
    for (double z : {-0.5, 0.5})
        for (int flipA = 0; flipA < 2; ++flipA)
            for (int flipB = 0; flipB < 2; ++flipB) {
                Mesh mesh;
                mesh.points = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0.2, 0.2, z};
                std::int64_t a[4] = {0, 1, 2, 3}, b[4] = {1, 0, 2, 4};
                if (flipA) std::swap(a[1], a[2]);
                if (flipB) std::swap(b[1], b[2]);
                mesh.AddCell(CellShape::Tet, 1, CellFamily::Lagrange, a, 4);
                mesh.AddCell(CellShape::Tet, 1, CellFamily::Lagrange, b, 4);
                const std::string what = "z " + std::to_string(z) + " flips " +
                                         std::to_string(flipA) + std::to_string(flipB);
                if (z > 0) {
                    EXPECT_THROW(BrickTraverser{Brick::WholeMesh(mesh)}, InputError)
                        << what;
                    continue;
                }
                const BrickTraverser tr(Brick::WholeMesh(mesh));
                EXPECT_EQ(tr.Stats().faces, 7) << what;
                EXPECT_EQ(tr.Stats().boundaryFaces, 6) << what;
                // Up through both cells: below the shared face, then above it.
                std::vector<Segment> segs;
                tr.Trace(MakeRay({0.15, 0.15, -1}, {0.15, 0.15, 1}), -INFINITY, INFINITY,
                         segs);
                ASSERT_EQ(segs.size(), 2u) << what;
                EXPECT_EQ(segs[0].cell, 1) << what;
                EXPECT_EQ(segs[1].cell, 0) << what;
                EXPECT_DOUBLE_EQ(segs[0].tExit, 1.0) << what;
                EXPECT_EQ(segs[0].tExit, segs[1].tEnter) << what;
            }
}

// A triangle that three tetrahedra share (a non-manifold mesh) is an input error naming
// the lowest of them; with any two of them the mesh is valid (the other faces are each
// one cell's). A tetrahedron of its own comes first, so that the lowest is not cell 0.
TEST(BrickTraverser, AFaceSharedByThreeCellsIsRejectedNamingTheLowest) {
    for (int third = 0; third < 2; ++third) {
        Mesh mesh;
        mesh.points = {0,   0,   0,   1, 0, 0, 0, 1, 0, 0.2, 0.2, 1, 0.2, 0.2, -1,
                       0.3, 0.3, 0.5, 5, 5, 5, 6, 5, 5, 5,   6,   5, 5,   5,   6};
        const std::int64_t own[4] = {6, 7, 8, 9}, up[4] = {0, 1, 2, 3},
                           down[4] = {1, 0, 2, 4}, again[4] = {0, 1, 2, 5};
        mesh.AddCell(CellShape::Tet, 1, CellFamily::Lagrange, own, 4);
        mesh.AddCell(CellShape::Tet, 1, CellFamily::Lagrange, down, 4);
        mesh.AddCell(CellShape::Tet, 1, CellFamily::Lagrange, up, 4);
        if (third) mesh.AddCell(CellShape::Tet, 1, CellFamily::Lagrange, again, 4);
        if (!third) {
            const BrickTraverser tr(Brick::WholeMesh(mesh));
            EXPECT_EQ(tr.Stats().faces, 11);
            continue;
        }
        try {
            BrickTraverser{Brick::WholeMesh(mesh)};
            ADD_FAILURE() << "no error";
        } catch (const InputError& e) {
            const std::string what = e.what();
            EXPECT_NE(what.find("cell 1"), std::string::npos) << what;
            EXPECT_NE(what.find("more than two cells"), std::string::npos) << what;
        }
    }
}

TEST(BrickTraverser, ConcurrentQueriesMatchSerialOnes) {
    const Mesh mesh = MakeCubeMesh("mixed");
    const BrickTraverser tr(Brick::WholeMesh(mesh));
    const int n = 4000;
    std::vector<Ray> rays(n);
    std::mt19937_64 rng(8);
    std::uniform_real_distribution<double> uni(0, 1);
    for (auto& r : rays)
        r = MakeRay({uni(rng) * 3 - 1, uni(rng) * 3 - 1, -1.5},
                    {uni(rng), uni(rng), uni(rng)});
    std::vector<std::vector<Segment>> serial(n), parallel(n);
    for (int i = 0; i < n; ++i) tr.Trace(rays[i], 0, INFINITY, serial[i]);
    tbb::parallel_for(0, n, [&](int i) { tr.Trace(rays[i], 0, INFINITY, parallel[i]); });
    for (int i = 0; i < n; ++i) {
        ASSERT_EQ(serial[i].size(), parallel[i].size());
        for (std::size_t k = 0; k < serial[i].size(); ++k) {
            EXPECT_EQ(serial[i][k].cell, parallel[i][k].cell);
            EXPECT_EQ(serial[i][k].tEnter, parallel[i][k].tEnter);
        }
    }
}

TEST(BrickTraverser, StraightHighOrderCellsHaveStraightFaces) {
    // Straight quadratic tets on [-1,1]^3, and order-2 hexes with displaced vertices
    // (bilinear faces carrying order-2 nodes).
    for (const char* spec : {"builtin:ball-p2?n=3", "builtin:nk-quartic?order=2"}) {
        const Mesh mesh = MakeBuiltin(spec);
        const BrickTraverser tr(Brick::WholeMesh(mesh));
        EXPECT_EQ(tr.Stats().curvedFaces, 0) << spec;
        const auto box = mesh.Bounds();
        std::mt19937_64 rng(2);
        std::uniform_real_distribution<double> uni(0, 1);
        std::vector<Segment> segs;
        for (int i = 0; i < 3000; ++i) {
            Vec3 from, to;
            for (int d = 0; d < 3; ++d) {
                const double w = box.hi[d] - box.lo[d];
                from[d] = box.lo[d] + w * (3 * uni(rng) - 1);
                to[d] = box.lo[d] + w * uni(rng);
            }
            const Ray ray = MakeRay(from, to);
            tr.Trace(ray, -INFINITY, INFINITY, segs);
            double t0, t1;
            const double chord = BoxChord(ray, box, t0, t1) ? t1 - t0 : 0;
            EXPECT_NEAR(Sum(segs), chord, 1e-12 * std::max(1.0, chord))
                << spec << " " << i;
            EXPECT_LE(Runs(segs, spec).size(), 1u);
        }
    }
}

// ---------------------------------------------------------------------------------------
// Curved cells. A map (x, y, z) -> (x, y, s z + z0 + q(x, y)) with a quadratic q is exact
// in quadratic tets and hexes, so cells with mapped nodes represent its image exactly:
// the region between two level sets of g = z - q(x, y), q = cx (x - xc)^2 + cy (y -
// yc)^2, over a square. The chords of that region are analytic.

struct QuadricSlab {
    double xy[2];  // |x|, |y| range: [xy0, xy1]
    double g[2];   // [gLo, gHi]
    double cx = 1, cy = 1, xc = 0, yc = 0;

    double G(const double* x) const {
        return x[2] - cx * (x[0] - xc) * (x[0] - xc) - cy * (x[1] - yc) * (x[1] - yc);
    }
    // g(origin + t dir) - level = a t^2 + b t + c.
    void Coefficients(const Ray& ray, double level, double& a, double& b,
                      double& c) const {
        const double *o = ray.origin, *d = ray.dir;
        a = -(cx * d[0] * d[0] + cy * d[1] * d[1]);
        b = d[2] - 2 * (cx * (o[0] - xc) * d[0] + cy * (o[1] - yc) * d[1]);
        c = G(o) - level;
    }
};

// The analytic intervals of the ray inside the slab: breakpoints are the square's slab
// planes and the roots of g(t) = gLo and g(t) = gHi; between breakpoints, test the
// middle.
std::vector<std::array<double, 2>> SlabIntervals(const Ray& ray, const QuadricSlab& s) {
    std::vector<double> br;
    const Box square = {{s.xy[0], s.xy[0], -1e300}, {s.xy[1], s.xy[1], 1e300}};
    RaySpan span;
    if (!ClipRayToBox(ray, square, span)) return {};
    const double t0 = span.t0, t1 = span.t1;
    br.push_back(t0);
    br.push_back(t1);
    for (double level : {s.g[0], s.g[1]}) {
        double a, b, c;
        s.Coefficients(ray, level, a, b, c);
        if (a == 0) {
            if (b != 0) br.push_back(-c / b);
            continue;
        }
        const double disc = b * b - 4 * a * c;
        if (disc < 0) continue;
        const double q = -0.5 * (b + std::copysign(std::sqrt(disc), b));
        br.push_back(q / a);
        if (q != 0) br.push_back(c / q);
    }
    std::sort(br.begin(), br.end());
    std::vector<std::array<double, 2>> out;
    for (std::size_t k = 0; k + 1 < br.size(); ++k) {
        const double lo = std::max(br[k], t0), hi = std::min(br[k + 1], t1);
        if (!(lo < hi)) continue;
        const double tm = 0.5 * (lo + hi);
        const double x[3] = {ray.origin[0] + tm * ray.dir[0],
                             ray.origin[1] + tm * ray.dir[1],
                             ray.origin[2] + tm * ray.dir[2]};
        const double g = s.G(x);
        if (g < s.g[0] || g > s.g[1]) continue;
        if (!out.empty() && out.back()[1] == lo)
            out.back()[1] = hi;
        else
            out.push_back({lo, hi});
    }
    return out;
}

// The tangency tolerance: a ray is excluded when it comes within kTangency (in g, i.e.
// vertical distance) of touching either bounding surface tangentially, i.e. when the
// extremum of g(t) - level lies in (-kTangency, kTangency). Such a ray's two crossings
// are closer than 2 sqrt(kTangency / curvature) and the chord depends on them to within
// rounding / |dg/dt| = rounding / (2 sqrt(curvature kTangency)).
constexpr double kTangency = 1e-8;

bool WellAway(const Ray& ray, const QuadricSlab& s) {
    for (double level : {s.g[0], s.g[1]}) {
        double a, b, c;
        s.Coefficients(ray, level, a, b, c);
        if (a > -1e-12) continue;  // (nearly) along the parabolas' axis: no tangency
        const double peak = c - b * b / (4 * a);
        if (std::fabs(peak) < kTangency) return false;
    }
    return true;
}

// Rays touching a bounding surface at a random point of the square, lifted by a signed
// vertical offset 10^-7.5 .. 10^-1 (peak of g(t) - level = the offset, just outside the
// tangency tolerance and beyond).
std::vector<Ray> NearTangentRays(const QuadricSlab& s, int n, std::mt19937_64& rng) {
    std::uniform_real_distribution<double> uni(0, 1);
    std::vector<Ray> rays;
    for (int i = 0; i < n; ++i) {
        const double level = s.g[i % 2];
        const double x = s.xy[0] + (s.xy[1] - s.xy[0]) * uni(rng);
        const double y = s.xy[0] + (s.xy[1] - s.xy[0]) * uni(rng);
        const double z =
            level + s.cx * (x - s.xc) * (x - s.xc) + s.cy * (y - s.yc) * (y - s.yc);
        // Tangent plane: dz = 2 cx (x - xc) dx + 2 cy (y - yc) dy.
        const double phi = 2 * M_PI * uni(rng);
        const double dx = std::cos(phi), dy = std::sin(phi);
        if (s.cx * dx * dx + s.cy * dy * dy < 1e-3) continue;
        const double dz = 2 * s.cx * (x - s.xc) * dx + 2 * s.cy * (y - s.yc) * dy;
        const double offset =
            (uni(rng) < 0.5 ? -1 : 1) * std::pow(10.0, -1 - 6.5 * uni(rng));
        rays.push_back(MakeRayDir({x, y, z + offset}, {dx, dy, dz}, 3));
    }
    return rays;
}

struct CurvedStats {
    int tested = 0, excluded = 0, multi = 0;
};

// Every ray well away from tangency gives the analytic intervals to 1e-10: the same
// number of runs of touching segments (no gap, no overlap), each run's ends within 1e-10.
CurvedStats CheckSlabRays(const BrickTraverser& tr, const QuadricSlab& slab,
                          const std::vector<Ray>& rays, const std::string& what) {
    CurvedStats st;
    std::vector<Segment> segs;
    for (std::size_t i = 0; i < rays.size(); ++i) {
        const Ray& ray = rays[i];
        if (!WellAway(ray, slab)) {
            ++st.excluded;
            continue;
        }
        ++st.tested;
        tr.Trace(ray, -INFINITY, INFINITY, segs);
        const std::string rayText =
            what + " ray " + std::to_string(i) + " origin " +
            ::testing::PrintToString(std::vector<double>(ray.origin, ray.origin + 3)) +
            " dir " + ::testing::PrintToString(std::vector<double>(ray.dir, ray.dir + 3));
        // Rays through a boundary edge or vertex can meet the domain in a point:
        // intervals shorter than 1e-9 (rounding) are dropped on both sides.
        std::vector<std::array<double, 2>> runs, expect;
        for (const auto& x : Runs(segs, rayText))
            if (x[1] - x[0] > 1e-9) runs.push_back(x);
        for (const auto& x : SlabIntervals(ray, slab))
            if (x[1] - x[0] > 1e-9) expect.push_back(x);
        st.multi += expect.size() > 1;
        EXPECT_EQ(runs.size(), expect.size())
            << rayText << " first run " << (runs.empty() ? 0.0 : runs[0][1] - runs[0][0])
            << " first interval " << (expect.empty() ? 0.0 : expect[0][1] - expect[0][0]);
        for (std::size_t k = 0; k < std::min(runs.size(), expect.size()); ++k) {
            EXPECT_NEAR(runs[k][0], expect[k][0], 1e-10) << rayText << " run " << k;
            EXPECT_NEAR(runs[k][1], expect[k][1], 1e-10) << rayText << " run " << k;
        }
        if (::testing::Test::HasFailure()) return st;
    }
    return st;
}

// Random rays through the slab's square (one in ten nearly vertical), near-tangent rays,
// and rays in random directions through `targets` (points on curved edges, vertices and
// faces of the mesh).
void CheckCurvedMesh(const Mesh& mesh, const QuadricSlab& slab, int rays,
                     const std::vector<Vec3>& targets, const std::string& what) {
    const BrickTraverser tr(Brick::WholeMesh(mesh));
    EXPECT_GT(tr.Stats().curvedFaces, 0) << what;
    std::mt19937_64 rng(17);
    std::uniform_real_distribution<double> uni(0, 1);
    std::normal_distribution<double> gauss;
    const double lo = slab.xy[0], w = slab.xy[1] - slab.xy[0];
    std::vector<Ray> random;
    for (int i = 0; i < rays; ++i) {
        Vec3 from, to;
        for (int d = 0; d < 2; ++d) {
            from[d] = lo + w * (3 * uni(rng) - 1);
            to[d] = lo + w * (1.2 * uni(rng) - 0.1);
        }
        from[2] = -3 + 7 * uni(rng);
        to[2] = -1 + 3 * uni(rng);
        random.push_back(i % 10 == 0 ? MakeRayDir(to, {0.05 * (uni(rng) - 0.5), 0, -1}, 5)
                                     : MakeRay(from, to));
    }
    std::vector<Ray> through;
    for (std::size_t i = 0; i < targets.size(); ++i) {
        const Vec3 dir = {gauss(rng), gauss(rng), gauss(rng)};
        through.push_back(MakeRayDir(targets[i], dir, 3));
    }
    const CurvedStats a = CheckSlabRays(tr, slab, random, what + " random");
    const CurvedStats b = CheckSlabRays(tr, slab, NearTangentRays(slab, rays / 3, rng),
                                        what + " near-tangent");
    const CurvedStats c = CheckSlabRays(tr, slab, through, what + " through edges");
    std::printf(
        "%s: %d random, %d near-tangent, %d through nodes/edges/faces rays exact to "
        "1e-10; %d excluded within the tangency tolerance\n",
        what.c_str(), a.tested, b.tested, c.tested, a.excluded + b.excluded + c.excluded);
    EXPECT_GT(a.multi, 0) << what;
    EXPECT_GT(b.tested, rays / 4) << what;
    EXPECT_LT(a.excluded + c.excluded, (rays + int(targets.size())) / 100) << what;
    const TraceCounters counters = tr.Counters();
    EXPECT_EQ(counters.newtonFailures, 0) << what;
    EXPECT_EQ(counters.walkRepairs, 0) << what;
    EXPECT_EQ(counters.walkFailures, 0) << what;
}

// Points on the (mapped) corners, edges and faces of the cells of a straight mesh: the
// image under `map` of points on the straight reference cells' edges and faces.
std::vector<Vec3> MappedTargets(const Mesh& straight,
                                const std::function<Vec3(Vec3)>& map, int n,
                                unsigned seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> uni(0, 1);
    std::vector<Vec3> out;
    for (int i = 0; i < n; ++i) {
        const std::int64_t c =
            std::int64_t(uni(rng) * straight.CellCount()) % straight.CellCount();
        const int nv = VertexCount(straight.cellShape[c]);
        auto corner = [&](int k) {
            const auto lat =
                VertexLattice(straight.cellShape[c], straight.cellOrder[c])[k];
            const int node =
                InternalNodeIndex(straight.cellShape[c], straight.cellOrder[c],
                                  straight.cellFamily[c], lat);
            const double* x = &straight.points[3 * straight.CellNodes(c)[node]];
            return Vec3{x[0], x[1], x[2]};
        };
        const int a = int(uni(rng) * nv) % nv,
                  b = (a + 1 + int(uni(rng) * (nv - 1))) % nv;
        const Vec3 A = corner(a), B = corner(b);
        Vec3 X;
        switch (i % 3) {
            case 0:
                X = A;
                break;  // a vertex
            case 1: {   // a point on an edge (or a diagonal of a hex)
                const double s = uni(rng);
                for (int d = 0; d < 3; ++d) X[d] = A[d] + s * (B[d] - A[d]);
                break;
            }
            default: {  // a point on a triangle of three corners (a face of a tet)
                const int e = (b + 1 + int(uni(rng) * (nv - 1))) % nv;
                const Vec3 C = corner(e == a ? (e + 1) % nv : e);
                double l1 = uni(rng), l2 = uni(rng);
                if (l1 + l2 > 1) l1 = 1 - l1, l2 = 1 - l2;
                for (int d = 0; d < 3; ++d)
                    X[d] = A[d] + l1 * (B[d] - A[d]) + l2 * (C[d] - A[d]);
            }
        }
        out.push_back(map(X));
    }
    return out;
}

TEST(BrickTraverser, QuadraticTetsReproduceParaboloidChords) {
    // Straight quadratic tets on [-1,1]^3 mapped by z -> (z - 1) / 2 + x^2 + y^2: the
    // slab x^2 + y^2 - 1 <= z <= x^2 + y^2 over the square [-1,1]^2.
    const Mesh straight = MakeBuiltin("builtin:ball-p2?n=3");
    const auto map = [](Vec3 x) {
        return Vec3{x[0], x[1], 0.5 * (x[2] - 1) + x[0] * x[0] + x[1] * x[1]};
    };
    Mesh mesh = straight;
    for (std::int64_t i = 0; i < mesh.PointCount(); ++i) {
        double* x = &mesh.points[3 * i];
        const Vec3 y = map({x[0], x[1], x[2]});
        std::copy(y.begin(), y.end(), x);
    }
    CheckCurvedMesh(mesh, QuadricSlab{{-1, 1}, {-1, 0}}, 6000,
                    MappedTargets(straight, map, 3000, 5), "p2 tets");
}

// Order-2 hexes on an n^3 grid of [0,1]^3 (nodes of the straight grid, then `map`);
// serendipity: the 20-node hexes (no face or body centres).
Mesh GridHexes(int n, const std::function<Vec3(Vec3)>& map, bool serendipity = false) {
    const int p = 2, g = n * p + 1;
    Mesh mesh;
    for (int k = 0; k < g; ++k)
        for (int j = 0; j < g; ++j)
            for (int i = 0; i < g; ++i) {
                const Vec3 y =
                    map({double(i) / (g - 1), double(j) / (g - 1), double(k) / (g - 1)});
                mesh.points.insert(mesh.points.end(), y.begin(), y.end());
            }
    for (int c = 0; c < n; ++c)
        for (int b = 0; b < n; ++b)
            for (int a = 0; a < n; ++a) {
                std::vector<std::int64_t> nodes;
                for (int k = 0; k <= p; ++k)
                    for (int j = 0; j <= p; ++j)
                        for (int i = 0; i <= p; ++i) {
                            if (serendipity && (i == 1) + (j == 1) + (k == 1) >= 2)
                                continue;
                            nodes.push_back((a * p + i) +
                                            g * ((b * p + j) + g * (c * p + k)));
                        }
                mesh.AddCell(CellShape::Hex, p,
                             serendipity ? CellFamily::Serendipity : CellFamily::Lagrange,
                             nodes.data(), int(nodes.size()));
            }
    return mesh;
}

// Non-conforming curved output, as deal.II writes with its default curved_boundary
// patches: cells at the boundary of the domain place their edge and face nodes on a
// curved map, interior cells on straight lines, so a boundary cell and its interior
// neighbour disagree on their shared face and edges (here by up to 6% of a cell) while
// their corners agree. The traversal uses one representation of each edge and face, so
// the cells still close up: every ray crosses the cube in one unbroken run of segments
// whose length is the cube's chord (the map fixes the cube's own faces), with no repair.
TEST(BrickTraverser, NonConformingCurvedNeighboursStayWatertight) {
    const Mesh grid = GridHexes(3, [](Vec3 x) { return x; });
    const Mesh unshared = Unshare(grid, 0.0);
    Mesh mesh = unshared;
    const auto bulge = [](const double* x, double* y) {
        const double s = std::sin(M_PI * x[0]) * std::sin(M_PI * x[1]) * std::sin(M_PI * x[2]);
        y[0] = x[0] + 0.02 * s;
        y[1] = x[1] - 0.015 * s;
        y[2] = x[2] + 0.01 * s;
    };
    for (std::int64_t c = 0; c < mesh.CellCount(); ++c) {
        if (c == 13) continue;  // the interior cell of the 3^3 grid stays straight
        for (int node = 0; node < 27; ++node) {
            const int i = node % 3, j = (node / 3) % 3, k = node / 9;
            if (i != 1 && j != 1 && k != 1) continue;  // corners are shared exactly
            const std::int64_t q = mesh.CellNodes(c)[node];
            bulge(&unshared.points[3 * q], &mesh.points[3 * q]);
        }
    }
    const BrickTraverser tr(Brick::WholeMesh(mesh));
    // The interior cell's 6 faces are written two ways; of its 12 edges, the 9 on the
    // 3 faces it builds itself (towards higher-numbered cells) meet a second version.
    EXPECT_EQ(tr.Stats().nonConformingFaces, 6);
    EXPECT_EQ(tr.Stats().nonConformingEdges, 9);
    EXPECT_GT(tr.Stats().nonConformity, 0.01);
    std::mt19937_64 rng(17);
    std::uniform_real_distribution<double> uni(0, 1);
    std::vector<Segment> segs;
    int crossing = 0;
    for (int r = 0; r < 4000; ++r) {
        // Rays through random points of the middle third, where the disagreement is.
        const Vec3 target{(1 + uni(rng)) / 3, (1 + uni(rng)) / 3, (1 + uni(rng)) / 3};
        const Vec3 from{3 * uni(rng) - 1, 3 * uni(rng) - 1, -1.5};
        const Ray ray = MakeRay(from, target);
        tr.Trace(ray, -INFINITY, INFINITY, segs);
        double t0, t1;
        ASSERT_TRUE(BoxChord(ray, kUnitBox, t0, t1));
        const auto runs = Runs(segs, "ray " + std::to_string(r));
        ASSERT_EQ(runs.size(), 1u) << "ray " << r;
        EXPECT_NEAR(runs[0][0], t0, 1e-12) << "ray " << r;
        EXPECT_NEAR(runs[0][1], t1, 1e-12) << "ray " << r;
        ++crossing;
    }
    EXPECT_EQ(crossing, 4000);
    EXPECT_EQ(tr.Counters().walkRepairs, 0);
    EXPECT_EQ(tr.Counters().walkFailures, 0);
    // A filter of every other cell gives the walk's segments of those cells here too
    // (cells whose crossings do not pair up would be answered by the walk).
    std::vector<std::uint8_t> keep(mesh.CellCount());
    for (std::int64_t c = 0; c < mesh.CellCount(); ++c) keep[c] = c % 2 == 1 || c == 13;
    const auto filter = tr.MakeCellFilter(keep);
    std::vector<Segment> all;
    for (int r = 0; r < 2000; ++r) {
        const Vec3 target{(1 + uni(rng)) / 3, (1 + uni(rng)) / 3, (1 + uni(rng)) / 3};
        const Vec3 from{3 * uni(rng) - 1, 3 * uni(rng) - 1, -1.5};
        const Ray ray = MakeRay(from, target);
        tr.Trace(ray, -INFINITY, INFINITY, segs, *filter);
        tr.Trace(ray, -INFINITY, INFINITY, all);
        std::vector<Segment> kept;
        for (const auto& g : all)
            if (keep[g.cell]) kept.push_back(g);
        ASSERT_EQ(kept.size(), segs.size()) << "ray " << r;
        for (std::size_t k = 0; k < kept.size(); ++k) {
            EXPECT_EQ(kept[k].cell, segs[k].cell) << "ray " << r;
            EXPECT_EQ(kept[k].tEnter, segs[k].tEnter) << "ray " << r;
            EXPECT_EQ(kept[k].tExit, segs[k].tExit) << "ray " << r;
        }
    }
}

TEST(BrickTraverser, ConcurrentCurvedQueriesMatchSerialOnes) {
    // Curved faces use per-thread scratch and a per-ray cache of face crossings: parallel
    // queries must give bitwise the serial segments.
    Mesh mesh = MakeBuiltin("builtin:ball-p2?n=3");
    for (std::int64_t i = 0; i < mesh.PointCount(); ++i) {
        double* x = &mesh.points[3 * i];
        x[2] = 0.5 * (x[2] - 1) + x[0] * x[0] + x[1] * x[1];
    }
    const BrickTraverser tr(Brick::WholeMesh(mesh));
    const int n = 4000;
    std::vector<Ray> rays(n);
    std::mt19937_64 rng(9);
    std::uniform_real_distribution<double> uni(-1, 1);
    for (auto& r : rays)
        r = MakeRay({3 * uni(rng), 3 * uni(rng), 3 + uni(rng)},
                    {uni(rng), uni(rng), uni(rng)});
    std::vector<std::vector<Segment>> serial(n), parallel(n);
    for (int i = 0; i < n; ++i) tr.Trace(rays[i], -INFINITY, INFINITY, serial[i]);
    tbb::parallel_for(
        0, n, [&](int i) { tr.Trace(rays[i], -INFINITY, INFINITY, parallel[i]); });
    int nonEmpty = 0;
    for (int i = 0; i < n; ++i) {
        ASSERT_EQ(serial[i].size(), parallel[i].size()) << i;
        nonEmpty += !serial[i].empty();
        for (std::size_t k = 0; k < serial[i].size(); ++k) {
            EXPECT_EQ(serial[i][k].cell, parallel[i][k].cell) << i;
            EXPECT_EQ(serial[i][k].tEnter, parallel[i][k].tEnter) << i;
            EXPECT_EQ(serial[i][k].tExit, parallel[i][k].tExit) << i;
        }
    }
    EXPECT_GT(nonEmpty, n / 4);
}

TEST(BrickTraverser, QuadraticHexesReproduceParaboloidChords) {
    // z -> z + x^2 + y^2 on [0,1]^3: the slab 0 <= z - x^2 - y^2 <= 1 over [0,1]^2.
    const auto map = [](Vec3 x) {
        return Vec3{x[0], x[1], x[2] + x[0] * x[0] + x[1] * x[1]};
    };
    const Mesh straight = GridHexes(3, [](Vec3 x) { return x; });
    CheckCurvedMesh(GridHexes(3, map), QuadricSlab{{0, 1}, {0, 1}}, 6000,
                    MappedTargets(straight, map, 3000, 6), "q2 hexes");
}

TEST(BrickTraverser, SerendipityHexesReproduceParaboloidChords) {
    // 20-node hexes: x^2 + y^2 lies in the serendipity space, so the same slab is exact.
    const auto map = [](Vec3 x) {
        return Vec3{x[0], x[1], x[2] + x[0] * x[0] + x[1] * x[1]};
    };
    const Mesh straight = GridHexes(
        3, [](Vec3 x) { return x; }, true);
    CheckCurvedMesh(GridHexes(3, map, true), QuadricSlab{{0, 1}, {0, 1}}, 3000,
                    MappedTargets(straight, map, 1500, 7), "hex20");
}

// Rays that leave a curved cell and re-enter it: the valley 0 <= z - 4 (x - 1/2)^2 <= 1
// over [0,1]^2 as ONE quadratic hex, and as quadratic tets. A ray above the valley
// floor's rim runs inside near x = 0, outside over the middle, inside again near x = 1.
TEST(BrickTraverser, RaysLeaveAndReenterTheSameCurvedCell) {
    const QuadricSlab valley{{0, 1}, {0, 1}, 4, 0, 0.5, 0};
    const auto map = [](Vec3 x) {
        return Vec3{x[0], x[1], x[2] + 4 * (x[0] - 0.5) * (x[0] - 0.5)};
    };
    std::mt19937_64 rng(29);
    std::uniform_real_distribution<double> uni(0, 1);
    std::vector<Ray> rays;
    for (int i = 0; i < 3000; ++i) {
        // Through the top surface's valley: height in (1, 2), a direction mostly along x.
        const Vec3 at = {0.5, uni(rng), 1 + uni(rng)};
        rays.push_back(
            MakeRayDir(at, {1, 0.3 * (uni(rng) - 0.5), 0.4 * (uni(rng) - 0.5)}, 2));
    }
    {
        const Mesh hex = GridHexes(1, map);
        const BrickTraverser tr(Brick::WholeMesh(hex));
        EXPECT_EQ(tr.Stats().cells, 1);
        const CurvedStats st = CheckSlabRays(tr, valley, rays, "valley hex");
        EXPECT_GT(st.tested, 2900);
        // The single cell is left and re-entered: two runs, both of cell 0.
        std::vector<Segment> segs;
        int twice = 0;
        for (const Ray& ray : rays) {
            if (!WellAway(ray, valley) || SlabIntervals(ray, valley).size() != 2)
                continue;
            tr.Trace(ray, -INFINITY, INFINITY, segs);
            ASSERT_EQ(segs.size(), 2u);
            EXPECT_EQ(segs[0].cell, 0);
            EXPECT_EQ(segs[1].cell, 0);
            EXPECT_LT(segs[0].tExit, segs[1].tEnter);
            ++twice;
        }
        EXPECT_GT(twice, 1000);
        EXPECT_EQ(tr.Counters().newtonFailures, 0);
        EXPECT_EQ(tr.Counters().walkFailures, 0);
    }
    {
        Mesh tets = MakeBuiltin("builtin:cube-tets-2?order=2");
        for (std::int64_t i = 0; i < tets.PointCount(); ++i) {
            double* x = &tets.points[3 * i];
            const Vec3 y = map({x[0], x[1], x[2]});
            std::copy(y.begin(), y.end(), x);
        }
        const BrickTraverser tr(Brick::WholeMesh(tets));
        const CurvedStats st = CheckSlabRays(tr, valley, rays, "valley tets");
        EXPECT_GT(st.multi, 1000);
        EXPECT_EQ(tr.Counters().newtonFailures, 0);
        EXPECT_EQ(tr.Counters().walkFailures, 0);
    }
}

// Straight, curved and mixed meshes for the located-start and filtered queries.
std::vector<std::pair<std::string, Mesh>> StartMeshes() {
    const auto map = [](Vec3 x) {
        return Vec3{x[0], x[1], x[2] + x[0] * x[0] + x[1] * x[1]};
    };
    std::vector<std::pair<std::string, Mesh>> meshes;
    meshes.emplace_back("q2 hexes", GridHexes(3, map));
    meshes.emplace_back("ball-p2", MakeBuiltin("builtin:ball-p2?n=3"));
    meshes.emplace_back("mixed", MakeCubeMesh("mixed"));
    return meshes;
}

// StartMeshes and one of planar tetrahedra only, whose walk steps from tet to tet by the
// entry face's corners and edge signs (bitwise CrossTriangle face by face, which starts
// each walk).
std::vector<std::pair<std::string, Mesh>> StartMeshesAndTets() {
    auto meshes = StartMeshes();
    meshes.emplace_back("tets", MakeCubeMesh("tets-jitter"));
    return meshes;
}

// Ray i of a set through a box: from outside it (beyond the face across axis i % 3)
// towards a random point inside.
Ray RayIntoBox(const Box& box, int i, std::mt19937_64& rng) {
    std::uniform_real_distribution<double> uni(0, 1);
    Vec3 target, from;
    for (int d = 0; d < 3; ++d) {
        target[d] = box.lo[d] + (box.hi[d] - box.lo[d]) * uni(rng);
        from[d] = box.lo[d] + (box.hi[d] - box.lo[d]) * (3 * uni(rng) - 1);
    }
    from[i % 3] = box.hi[i % 3] + 1;
    return MakeRay(from, target);
}

// A span that starts inside the mesh (tMin past the boundary, as a clip box makes it) is
// begun at the cell located there: its segments must be bitwise those of a walk from the
// boundary cut at tMin, on straight, curved and mixed meshes, and the located start must
// be what happened (its counter).
TEST(BrickTraverser, SpansStartingInsideTheMeshMatchTheWalkFromTheBoundary) {
    for (const auto& [name, mesh] : StartMeshesAndTets()) {
        const BrickTraverser tr(Brick::WholeMesh(mesh));
        const Box box = Brick::WholeMesh(mesh).box;
        std::mt19937_64 rng(41);
        std::uniform_real_distribution<double> uni(0, 1);
        std::vector<Segment> segs, all;
        int inside = 0;
        for (int i = 0; i < 3000; ++i) {
            // From outside the box towards a point inside it; tMin somewhere along the
            // chord through the box.
            const Ray ray = RayIntoBox(box, i, rng);
            double t0, t1;
            if (!BoxChord(ray, box, t0, t1)) continue;
            const double tMin = t0 + (t1 - t0) * uni(rng);
            tr.Trace(ray, tMin, INFINITY, segs);
            tr.Trace(ray, -INFINITY, INFINITY, all);
            std::vector<Segment> cut;
            for (const auto& g : all) {
                const double x = std::max(g.tEnter, tMin), y = g.tExit;
                if (x < y) cut.push_back({g.cell, x, y});
            }
            ASSERT_EQ(cut.size(), segs.size()) << name << " ray " << i;
            for (std::size_t k = 0; k < cut.size(); ++k) {
                EXPECT_EQ(cut[k].cell, segs[k].cell) << name << " ray " << i;
                EXPECT_EQ(cut[k].tEnter, segs[k].tEnter) << name << " ray " << i;
                EXPECT_EQ(cut[k].tExit, segs[k].tExit) << name << " ray " << i;
            }
            inside += !all.empty() && all.front().tEnter < tMin && !segs.empty() &&
                      segs.front().tEnter == tMin;
        }
        // Most spans that start inside the mesh were begun at a located cell.
        EXPECT_GT(inside, 300) << name;
        EXPECT_GE(tr.Counters().locatedStarts, inside * 9 / 10) << name;
        EXPECT_EQ(tr.Counters().walkFailures, 0) << name;
    }
}

// A cell filter's Trace gives the segments of the filter's cells only: bitwise the walk's
// segments of those cells (their faces' crossings paired as the walk pairs them), found
// without walking the others, on straight, curved and mixed meshes.
TEST(BrickTraverser, FilteredTraceGivesTheWalksSegmentsOfTheKeptCells) {
    for (const auto& [name, mesh] : StartMeshesAndTets()) {
        const BrickTraverser tr(Brick::WholeMesh(mesh));
        const Box box = Brick::WholeMesh(mesh).box;
        // Every third cell, and the cells of one corner octant (a connected block).
        const std::int64_t cells = mesh.CellCount();
        std::vector<std::uint8_t> keep(cells, 0);
        for (std::int64_t c = 0; c < cells; ++c) {
            const std::int64_t* nodes = mesh.CellNodes(c);
            bool octant = true;
            for (int d = 0; d < 3; ++d)
                octant = octant &&
                         mesh.points[3 * nodes[0] + d] < 0.5 * (box.lo[d] + box.hi[d]);
            keep[c] = c % 3 == 0 || octant;
        }
        const auto filter = tr.MakeCellFilter(keep);
        std::mt19937_64 rng(43);
        std::uniform_real_distribution<double> uni(0, 1);
        std::vector<Segment> segs, all;
        std::size_t total = 0;
        for (int i = 0; i < 3000; ++i) {
            const Ray ray = RayIntoBox(box, i, rng);
            const double tMin = i % 2 ? 0.0 : 1.0 + uni(rng);
            tr.Trace(ray, tMin, INFINITY, segs, *filter);
            tr.Trace(ray, tMin, INFINITY, all);
            std::vector<Segment> kept;
            for (const auto& g : all)
                if (keep[g.cell]) kept.push_back(g);
            ASSERT_EQ(kept.size(), segs.size()) << name << " ray " << i;
            for (std::size_t k = 0; k < kept.size(); ++k) {
                EXPECT_EQ(kept[k].cell, segs[k].cell) << name << " ray " << i;
                EXPECT_EQ(kept[k].tEnter, segs[k].tEnter) << name << " ray " << i;
                EXPECT_EQ(kept[k].tExit, segs[k].tExit) << name << " ray " << i;
            }
            total += segs.size();
        }
        EXPECT_GT(total, 2000u) << name;
    }
}

// Hexahedra, wedges and pyramids with planar faces (unjittered grids; with tetrahedra
// too) are left by their faces' crossings decided together: each walk step must pair
// bitwise the crossings (t and face parameters, as the segments' seeds give them) that
// the cell's faces crossed one by one give (a filter of every cell), for random rays and
// for rays through grid vertices, along grid lines and in grid planes, where edge signs
// tie. (The segments' ends may differ: the walk never steps back in t.)
TEST(BrickTraverser, PlanarCellsAreLeftAsTheirFacesCrossingsPair) {
    struct Grid {
        std::string name;
        int n;
        Mesh mesh;
    };
    std::vector<Grid> meshes;
    meshes.push_back(
        {"hexes", 5, GridMesh(5, 0.0, [](int, int, int) { return CubeCut::Hex; })});
    meshes.push_back(
        {"wedges", 5, GridMesh(5, 0.0, [](int, int, int) { return CubeCut::Wedges; })});
    meshes.push_back({"pyramids", 4,
                      GridMesh(4, 0.0, [](int, int, int) { return CubeCut::Pyramids; })});
    meshes.push_back({"mixed", 6, GridMesh(6, 0.0, [](int a, int b, int c) {
                          switch ((a + 2 * b + c) % 4) {
                              case 0:
                                  return CubeCut::Hex;
                              case 1:
                                  return CubeCut::Wedges;
                              case 2:
                                  return CubeCut::Pyramids;
                              default:
                                  return CubeCut::PyramidsTetsZ;
                          }
                      })});
    const auto same = [](double a, double b) {
        return std::memcmp(&a, &b, sizeof a) == 0;
    };
    for (const auto& [name, n, mesh] : meshes) {
        const BrickTraverser tr(Brick::WholeMesh(mesh));
        ASSERT_EQ(tr.Stats().bilinearFaces, 0) << name;
        // The grid's coordinates as GridMesh computes them.
        const auto grid = [n = n](int k) { return k % (n + 1) * (1.0 / n); };
        const auto filter =
            tr.MakeCellFilter(std::vector<std::uint8_t>(mesh.CellCount(), 1));
        std::mt19937_64 rng(53);
        std::uniform_real_distribution<double> uni(0, 1);
        std::vector<Segment> segs, filtered;
        std::vector<SegmentSeed> seeds, filteredSeeds;
        std::size_t total = 0;
        for (int i = 0; i < 4000; ++i) {
            Vec3 through{uni(rng), uni(rng), uni(rng)};
            Vec3 dir{uni(rng) - 0.5, uni(rng) - 0.5, uni(rng) - 0.5};
            const int axis = i % 3, other = (axis + 1) % 3, third = (axis + 2) % 3;
            switch ((i / 3) % 4) {
                case 0:  // random
                    break;
                case 1:  // through a grid vertex
                    for (int d = 0; d < 3; ++d) through[d] = grid(i / (7 + d));
                    break;
                case 2:  // along a grid line
                    through[other] = grid(i);
                    through[third] = grid(i / 7);
                    dir = {0, 0, 0};
                    dir[axis] = i % 2 ? 1 : -1;
                    break;
                default:  // in a grid plane
                    through[axis] = grid(i);
                    dir[axis] = 0;
            }
            const Ray ray = MakeRayDir(through, dir);
            tr.Trace(ray, -INFINITY, INFINITY, segs, nullptr, &seeds);
            tr.Trace(ray, -INFINITY, INFINITY, filtered, *filter, &filteredSeeds);
            const std::string what = name + " ray " + std::to_string(i);
            ASSERT_EQ(seeds.size(), segs.size()) << what;
            ASSERT_EQ(filteredSeeds.size(), filtered.size()) << what;
            // Each walk segment is a pair of the filter's, with the same crossings (the
            // walk may drop a pair that it would step back in t for, and so may start
            // the next one later: compare the crossings, not the segments' ends).
            for (std::size_t k = 0; k < segs.size(); ++k) {
                const SegmentSeed& a = seeds[k];
                std::size_t j = 0;
                while (j < filtered.size() && !(filtered[j].cell == segs[k].cell &&
                                                same(filteredSeeds[j].tEnter, a.tEnter)))
                    ++j;
                ASSERT_LT(j, filtered.size()) << what << " segment " << k;
                const SegmentSeed& b = filteredSeeds[j];
                EXPECT_TRUE(same(a.tExit, b.tExit)) << what;
                for (int d = 0; d < 3; ++d) {
                    EXPECT_TRUE(same(a.enter[d], b.enter[d])) << what;
                    EXPECT_TRUE(same(a.exit[d], b.exit[d])) << what;
                }
            }
            total += segs.size();
            if (::testing::Test::HasFailure()) return;
        }
        EXPECT_GT(total, 10000u) << name;
        EXPECT_EQ(tr.Counters().walkFailures, 0) << name;
    }
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// A segment's seeds are its cell's reference points where the ray crosses the faces: the
// cell's own map (not the face nets or patches the crossings were computed on) takes
// them to the ray's points at the crossings, to rounding, on bilinear and curved faces
// and triangles; on the jittered mixed mesh's planar quadrilaterals, which are not
// parallelograms, the triangles' parameters are an approximation (within 2% of the mesh
// size, where a wrong corner would be a cell size, 1/6, off). The filter's seeds are the
// walk's.
TEST(BrickTraverser, SegmentSeedsMapToTheRaysCrossingPoints) {
    std::vector<std::pair<std::string, Mesh>> meshes = StartMeshes();
    meshes.emplace_back("curved q4 hexes", testing::CurvedHexesWithFieldX(0.05, 4));
    for (const auto& [name, mesh] : meshes) {
        const BrickTraverser tr(Brick::WholeMesh(mesh));
        const MeshGeometry geometry = MeshGeometry::Build(mesh);
        const Box box = Brick::WholeMesh(mesh).box;
        const double size = box.Diagonal();
        const auto filter =
            tr.MakeCellFilter(std::vector<std::uint8_t>(mesh.CellCount(), 1));
        std::mt19937_64 rng(47);
        std::vector<Segment> segs, filtered;
        std::vector<SegmentSeed> seeds, filteredSeeds;
        CellScratch scratch;
        EvalWorkspace ws;
        double worst = 0;
        std::size_t ends = 0, seeded = 0;
        for (int i = 0; i < 1500; ++i) {
            const Ray ray = RayIntoBox(box, i, rng);
            tr.Trace(ray, -INFINITY, INFINITY, segs, nullptr, &seeds);
            tr.Trace(ray, -INFINITY, INFINITY, filtered, *filter, &filteredSeeds);
            ASSERT_EQ(seeds.size(), segs.size()) << name;
            ASSERT_EQ(filtered.size(), segs.size()) << name;
            ASSERT_EQ(filteredSeeds.size(), segs.size()) << name;
            for (std::size_t k = 0; k < segs.size(); ++k) {
                const SegmentSeed& sd = seeds[k];
                const CellShape shape = mesh.cellShape[segs[k].cell];
                const bool linearTet =
                    shape == CellShape::Tet && mesh.cellOrder[segs[k].cell] == 1;
                for (int e = 0; e < 2; ++e) {
                    const double* ref = e == 0 ? sd.enter : sd.exit;
                    const double t = e == 0 ? sd.tEnter : sd.tExit;
                    const double* other =
                        e == 0 ? filteredSeeds[k].enter : filteredSeeds[k].exit;
                    if (shape != CellShape::Pyramid && !linearTet) ends += 1;
                    if (!std::isfinite(ref[0])) {
                        EXPECT_FALSE(std::isfinite(other[0])) << name;
                        continue;
                    }
                    seeded += 1;
                    for (int d = 0; d < 3; ++d) EXPECT_EQ(ref[d], other[d]) << name;
                    double world[3];
                    WorldFromRef(geometry.Cell(segs[k].cell, scratch), ref, ws, world,
                                 nullptr);
                    double dist = 0;
                    for (int d = 0; d < 3; ++d)
                        dist = std::max(
                            dist, std::abs(world[d] - (ray.origin[d] + t * ray.dir[d])));
                    worst = std::max(worst, dist / size);
                }
            }
        }
        SCOPED_TRACE(name);
        EXPECT_LE(worst, name == "mixed" ? 2e-2 : 1e-9);
        // Seeds wherever a cell needs them: every end in a hexahedron, a wedge or a
        // curved tetrahedron (not in pyramids, nor linear tetrahedra, whose maps are
        // inverted in closed form).
        EXPECT_GT(ends, 1000u);
        EXPECT_GE(seeded, ends * 95 / 100);
    }
}

// A sink (SegmentSink) takes each segment as soon as it is found: in order, final when
// taken (what it saw then is what the Trace ends with), the same segments and seeds as
// without a sink, and stopping where the sink says so; for the walk and for cell filters
// (of whole cells and of sub-boxes, whose cells' segments start before their boxes), on
// straight, curved and mixed meshes.
TEST(BrickTraverser, SinksTakeEachSegmentAsFoundAndStopTheTrace) {
    for (const auto& [name, mesh] : StartMeshesAndTets()) {
        const BrickTraverser tr(Brick::WholeMesh(mesh));
        const Box box = Brick::WholeMesh(mesh).box;
        const std::int64_t cells = mesh.CellCount();
        std::vector<std::uint8_t> every(cells, 1), some(cells, 0);
        for (std::int64_t c = 0; c < cells; ++c) some[c] = c % 3 != 1;
        // Sub-boxes: the upper half (in z) of each kept cell's box, and its lower
        // quarter.
        std::vector<std::int64_t> boxStart(cells + 1, 0);
        std::vector<float> boxes;
        for (std::int64_t c = 0; c < cells; ++c) {
            boxStart[c + 1] = boxStart[c];
            if (!some[c] || c % 2 == 0) continue;
            double lo[3] = {INFINITY, INFINITY, INFINITY},
                   hi[3] = {-INFINITY, -INFINITY, -INFINITY};
            const std::int64_t* nodes = mesh.CellNodes(c);
            for (int k = 0; k < mesh.CellNodeCount(c); ++k)
                for (int d = 0; d < 3; ++d) {
                    lo[d] = std::min(lo[d], mesh.points[3 * nodes[k] + d]);
                    hi[d] = std::max(hi[d], mesh.points[3 * nodes[k] + d]);
                }
            const double mid = 0.5 * (lo[2] + hi[2]),
                         quarter = 0.75 * lo[2] + 0.25 * hi[2];
            const double parts[2][2] = {{mid, hi[2]}, {lo[2], quarter}};
            for (const auto& z : parts) {
                for (double v : {lo[0], lo[1], z[0], hi[0], hi[1], z[1]})
                    boxes.push_back(float(v));
                boxStart[c + 1] += 1;
            }
        }
        const auto all = tr.MakeCellFilter(every);
        const auto kept = tr.MakeCellFilter(some);
        const auto parts = tr.MakeCellFilter(some, &boxStart, &boxes);
        std::mt19937_64 rng(53);
        std::uniform_real_distribution<double> uni(0, 1);
        std::vector<Segment> want, got;
        std::vector<SegmentSeed> wantSeeds, gotSeeds;
        std::size_t taken = 0, stopped = 0;
        for (int i = 0; i < 1500; ++i) {
            const Ray ray = RayIntoBox(box, i, rng);
            const double tMin = i % 2 ? 0.0 : 1.0 + uni(rng);
            for (int way = 0; way < 4; ++way) {
                const CellFilter* filter = way == 1   ? all.get()
                                           : way == 2 ? kept.get()
                                           : way == 3 ? parts.get()
                                                      : nullptr;
                auto trace = [&](std::vector<Segment>& out, std::vector<SegmentSeed>& sd,
                                 SegmentSink* sink) {
                    if (filter)
                        tr.Trace(ray, tMin, INFINITY, out, *filter, &sd, sink);
                    else
                        tr.Trace(ray, tMin, INFINITY, out, nullptr, &sd, sink);
                };
                trace(want, wantSeeds, nullptr);
                ASSERT_EQ(wantSeeds.size(), want.size());
                // Stop at the last segment (or never, for a ray with none), else halfway.
                const std::size_t stop = i % 3 == 0 ? want.size() : want.size() / 2;
                struct Recorder final : SegmentSink {
                    std::vector<Segment>* out = nullptr;
                    std::vector<SegmentSeed>* seeds = nullptr;
                    std::vector<Segment> seen;
                    std::vector<SegmentSeed> seenSeeds;
                    std::size_t stopAt = 0;
                    bool inOrder = true;
                    bool Take(std::size_t index) override {
                        inOrder = inOrder && index == seen.size() &&
                                  out->size() == index + 1 && seeds->size() == index + 1;
                        seen.push_back((*out)[index]);
                        seenSeeds.push_back((*seeds)[index]);
                        return index != stopAt;
                    }
                } sink;
                sink.out = &got;
                sink.seeds = &gotSeeds;
                sink.stopAt = stop;
                trace(got, gotSeeds, &sink);
                const std::string what =
                    name + " way " + std::to_string(way) + " ray " + std::to_string(i);
                EXPECT_TRUE(sink.inOrder) << what;
                const std::size_t expect = std::min(want.size(), stop + 1);
                ASSERT_EQ(got.size(), expect) << what;
                ASSERT_EQ(sink.seen.size(), expect) << what;
                for (std::size_t k = 0; k < expect; ++k) {
                    for (const Segment* g : {&got[k], &sink.seen[k]}) {
                        EXPECT_EQ(g->cell, want[k].cell) << what;
                        EXPECT_EQ(g->tEnter, want[k].tEnter) << what;
                        EXPECT_EQ(g->tExit, want[k].tExit) << what;
                    }
                    for (const SegmentSeed* sd : {&gotSeeds[k], &sink.seenSeeds[k]}) {
                        EXPECT_EQ(sd->tEnter, wantSeeds[k].tEnter) << what;
                        EXPECT_EQ(sd->tExit, wantSeeds[k].tExit) << what;
                        for (int d = 0; d < 3; ++d) {
                            EXPECT_EQ(std::isnan(sd->enter[d]),
                                      std::isnan(wantSeeds[k].enter[d]))
                                << what;
                            if (!std::isnan(sd->enter[d])) {
                                EXPECT_EQ(sd->enter[d], wantSeeds[k].enter[d]) << what;
                            }
                            if (!std::isnan(sd->exit[d])) {
                                EXPECT_EQ(sd->exit[d], wantSeeds[k].exit[d]) << what;
                            }
                        }
                    }
                }
                taken += expect;
                stopped += expect < want.size();
            }
        }
        EXPECT_GT(taken, 3000u) << name;
        EXPECT_GT(stopped, 1000u) << name;
    }
}

}  // namespace
}  // namespace hpray
