// Test meshes for traversal: structured grids of the unit cube cut into every cell shape,
// with jittered interior vertices, and helpers for analytic chords.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "mesh/builtin.h"
#include "mesh/mesh.h"
#include "trace/ray.h"

namespace hpray::testing {

using Vec3 = std::array<double, 3>;

/// How each cube of a grid is cut.
enum class CubeCut { Hex, Wedges, Pyramids, PyramidsTetsX, PyramidsTetsZ, Tets5 };

/// An N^3 grid of cubes on [0,1]^3; interior grid vertices (and cube centres) jittered by
/// up to `jitter` cube widths per axis, so interior faces are not planar; boundary vertices
/// stay on the cube, so the domain is exactly [0,1]^3. `cut(a, b, c)` says how cube (a,b,c)
/// is cut; `keep(a, b, c)` drops cubes (non-convex domains). Faces between cubes match: a
/// quad is split into triangles along the diagonal through its smallest vertex id.
inline Mesh GridMesh(int n, double jitter, std::function<CubeCut(int, int, int)> cut,
                     std::function<bool(int, int, int)> keep = nullptr,
                     unsigned seed = 1) {
    Mesh mesh;
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> uni(-1.0, 1.0);
    const double h = 1.0 / n;
    auto vid = [n](int i, int j, int k) { return std::int64_t(i + (n + 1) * (j + (n + 1) * k)); };
    for (int k = 0; k <= n; ++k)
        for (int j = 0; j <= n; ++j)
            for (int i = 0; i <= n; ++i) {
                const int idx[3] = {i, j, k};
                for (int d = 0; d < 3; ++d) {
                    double x = idx[d] * h;
                    const bool interior = i > 0 && i < n && j > 0 && j < n && k > 0 && k < n;
                    if (interior) x += jitter * h * uni(rng);
                    mesh.points.push_back(x);
                }
            }
    auto pos = [&](std::int64_t v) {
        return Vec3{mesh.points[3 * v], mesh.points[3 * v + 1], mesh.points[3 * v + 2]};
    };
    auto addPoint = [&](const Vec3& x) {
        mesh.points.insert(mesh.points.end(), x.begin(), x.end());
        return mesh.PointCount() - 1;
    };
    auto orient = [&](std::int64_t a, std::int64_t b, std::int64_t c, std::int64_t d) {
        const Vec3 A = pos(a), B = pos(b), C = pos(c), D = pos(d);
        double u[3], v[3], w[3];
        for (int q = 0; q < 3; ++q) {
            u[q] = B[q] - A[q];
            v[q] = C[q] - A[q];
            w[q] = D[q] - A[q];
        }
        return u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
               u[2] * (v[0] * w[1] - v[1] * w[0]);
    };
    auto addTet = [&](std::int64_t a, std::int64_t b, std::int64_t c, std::int64_t d) {
        if (orient(a, b, c, d) < 0) std::swap(b, c);
        const std::int64_t nodes[4] = {a, b, c, d};
        mesh.AddCell(CellShape::Tet, 1, CellFamily::Lagrange, nodes, 4);
    };
    // Pyramid on the base cycle q0..q3 with apex e, oriented so the apex is above the base.
    auto addPyramid = [&](std::array<std::int64_t, 4> q, std::int64_t e) {
        if (orient(q[0], q[1], q[3], e) < 0) std::swap(q[1], q[3]);
        const std::int64_t nodes[5] = {q[0], q[1], q[3], q[2], e};
        mesh.AddCell(CellShape::Pyramid, 1, CellFamily::Lagrange, nodes, 5);
    };
    // Two tets on a base cycle split along the diagonal through its smallest vertex id.
    auto addSplitPyramid = [&](std::array<std::int64_t, 4> q, std::int64_t e) {
        const int m = int(std::min_element(q.begin(), q.end()) - q.begin());
        std::rotate(q.begin(), q.begin() + m, q.end());
        addTet(q[0], q[1], q[2], e);
        addTet(q[0], q[2], q[3], e);
    };
    for (int c = 0; c < n; ++c)
        for (int b = 0; b < n; ++b)
            for (int a = 0; a < n; ++a) {
                if (keep && !keep(a, b, c)) continue;
                std::int64_t v[8];
                for (int q = 0; q < 8; ++q) v[q] = vid(a + (q & 1), b + ((q >> 1) & 1), c + (q >> 2));
                const CubeCut kind = cut(a, b, c);
                if (kind == CubeCut::Hex) {
                    mesh.AddCell(CellShape::Hex, 1, CellFamily::Lagrange, v, 8);
                } else if (kind == CubeCut::Wedges) {
                    const std::int64_t w1[6] = {v[0], v[1], v[2], v[4], v[5], v[6]};
                    const std::int64_t w2[6] = {v[3], v[2], v[1], v[7], v[6], v[5]};
                    mesh.AddCell(CellShape::Wedge, 1, CellFamily::Lagrange, w1, 6);
                    mesh.AddCell(CellShape::Wedge, 1, CellFamily::Lagrange, w2, 6);
                } else if (kind == CubeCut::Tets5) {
                    static const int kA[5][4] = {{0, 1, 2, 4}, {3, 2, 1, 7}, {5, 4, 7, 1},
                                                 {6, 7, 4, 2}, {1, 2, 4, 7}};
                    static const int kB[5][4] = {{1, 0, 5, 3}, {2, 3, 6, 0}, {4, 5, 0, 6},
                                                 {7, 6, 3, 5}, {0, 3, 5, 6}};
                    const auto& split = (a + b + c) % 2 == 0 ? kA : kB;
                    for (const auto& t : split) addTet(v[t[0]], v[t[1]], v[t[2]], v[t[3]]);
                } else {
                    Vec3 ctr{0, 0, 0};
                    for (int q = 0; q < 8; ++q)
                        for (int d = 0; d < 3; ++d) ctr[d] += pos(v[q])[d] / 8;
                    for (int d = 0; d < 3; ++d) ctr[d] += 0.1 * jitter * h * uni(rng);
                    const std::int64_t e = addPoint(ctr);
                    // Faces: -x, +x, -y, +y, -z, +z as cycles of cube corners.
                    static const int kFaces[6][4] = {{0, 2, 6, 4}, {1, 3, 7, 5}, {0, 1, 5, 4},
                                                     {2, 3, 7, 6}, {0, 1, 3, 2}, {4, 5, 7, 6}};
                    for (int f = 0; f < 6; ++f) {
                        const std::array<std::int64_t, 4> q = {v[kFaces[f][0]], v[kFaces[f][1]],
                                                               v[kFaces[f][2]], v[kFaces[f][3]]};
                        const bool split = (kind == CubeCut::PyramidsTetsX && f < 2) ||
                                           (kind == CubeCut::PyramidsTetsZ && f >= 4);
                        if (split) addSplitPyramid(q, e);
                        else addPyramid(q, e);
                    }
                }
            }
    return mesh;
}

/// Chord of a ray through a closed box: [t0, t1] or false.
inline bool BoxChord(const Ray& ray, const Box& box, double& t0, double& t1) {
    RaySpan span;
    const bool hit = ClipRayToBox(ray, box, span);
    t0 = span.t0;
    t1 = span.t1;
    return hit;
}

inline Ray MakeRay(const Vec3& from, const Vec3& to) {
    Ray r;
    double len = 0;
    for (int d = 0; d < 3; ++d) len += (to[d] - from[d]) * (to[d] - from[d]);
    len = std::sqrt(len);
    for (int d = 0; d < 3; ++d) {
        r.origin[d] = from[d];
        r.dir[d] = (to[d] - from[d]) / len;
    }
    return r;
}

inline Ray MakeRayDir(const Vec3& through, Vec3 dir, double back = 3.0) {
    double len = std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
    Ray r;
    for (int d = 0; d < 3; ++d) {
        r.dir[d] = dir[d] / len;
        r.origin[d] = through[d] - back * r.dir[d];
    }
    return r;
}

/// Isoparametric curved hexes: builtin nk-sinc's hexes of `order` with every node moved by
/// a smooth bump of `amplitude` that vanishes on the cube's faces, and its field u set to
/// the moved node's x, so u is exactly the world x coordinate inside the curved cells.
inline Mesh CurvedHexesWithFieldX(double amplitude, int order = 4) {
    Mesh mesh = MakeBuiltin("builtin:nk-sinc?order=" + std::to_string(order));
    const double pi = std::acos(-1.0);
    for (std::int64_t i = 0; i < mesh.PointCount(); ++i) {
        double* x = &mesh.points[3 * i];
        const double bump = std::sin(pi * x[0]) * std::sin(pi * x[1]) * std::sin(pi * x[2]);
        const double X = x[0], Y = x[1], Z = x[2];
        x[0] = X + amplitude * bump * std::cos(3 * Y);
        x[1] = Y + amplitude * bump * std::sin(2 * Z);
        x[2] = Z + amplitude * bump * std::cos(2 * X);
        mesh.pointFields[0].values[i] = x[0];
    }
    return mesh;
}

}  // namespace hpray::testing
