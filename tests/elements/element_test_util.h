// Shared helpers of the element tests: the cells to sweep, the spaces they must reproduce
// (written independently of src/elements) and random reference points.
#pragma once

#include <array>
#include <cmath>
#include <random>
#include <vector>

#include "mesh/cell.h"

namespace hpray::testing {

struct CellKind {
    CellShape shape;
    int order;
    CellFamily family;
};

/// Every (shape, order, family) the mesh model allows.
inline std::vector<CellKind> AllCellKinds() {
    std::vector<CellKind> kinds;
    for (CellShape s : {CellShape::Tet, CellShape::Hex, CellShape::Wedge, CellShape::Pyramid})
        for (int p = 1; p <= kMaxOrder; ++p) kinds.push_back({s, p, CellFamily::Lagrange});
    for (CellShape s : {CellShape::Hex, CellShape::Wedge, CellShape::Pyramid})
        kinds.push_back({s, 2, CellFamily::Serendipity});
    return kinds;
}

/// Closed reference cell of mesh/cell.h, with slack e.
inline bool InsideRef(CellShape shape, const std::array<double, 3>& x, double e = 0.0) {
    const double r = x[0], s = x[1], t = x[2];
    switch (shape) {
        case CellShape::Tet: return r >= -e && s >= -e && t >= -e && r + s + t <= 1 + e;
        case CellShape::Hex:
            return r >= -e && s >= -e && t >= -e && r <= 1 + e && s <= 1 + e && t <= 1 + e;
        case CellShape::Wedge:
            return r >= -e && s >= -e && r + s <= 1 + e && t >= -e && t <= 1 + e;
        case CellShape::Pyramid:
            return t >= -e && t <= 1 + e && r >= t / 2 - e && r <= 1 - t / 2 + e &&
                   s >= t / 2 - e && s <= 1 - t / 2 + e;
    }
    return false;
}

/// Uniform random point of the reference cell (rejection from the unit cube).
inline std::array<double, 3> RandomRefPoint(CellShape shape, std::mt19937_64& rng) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (;;) {
        std::array<double, 3> x{u(rng), u(rng), u(rng)};
        if (InsideRef(shape, x)) return x;
    }
}

/// A function of the cell's declared space with its analytic gradient in (r, s, t).
/// f = X^e0 Y^e1 t^e2 (1 - t)^e3 with X = r - shift t, Y = s - shift t (shift = 1/2 for
/// pyramids, 0 otherwise); e3 may be negative (pyramid rational functions).
struct SpaceFunction {
    int e[4];
    double shift;
    double Value(const std::array<double, 3>& x) const {
        const double X = x[0] - shift * x[2], Y = x[1] - shift * x[2], t = x[2];
        return std::pow(X, e[0]) * std::pow(Y, e[1]) * std::pow(t, e[2]) *
               std::pow(1.0 - t, e[3]);
    }
    std::array<double, 3> Gradient(const std::array<double, 3>& x) const {
        const double X = x[0] - shift * x[2], Y = x[1] - shift * x[2], t = x[2], u = 1.0 - t;
        auto pw = [](double b, int k) { return k == 0 ? 1.0 : std::pow(b, k); };
        const double fx = pw(X, e[0]), fy = pw(Y, e[1]), ft = pw(t, e[2]), fu = pw(u, e[3]);
        const double dx = e[0] ? e[0] * pw(X, e[0] - 1) : 0.0;
        const double dy = e[1] ? e[1] * pw(Y, e[1] - 1) : 0.0;
        const double dt = e[2] ? e[2] * pw(t, e[2] - 1) : 0.0;
        const double du = e[3] ? e[3] * pw(u, e[3] - 1) : 0.0;
        const double gr = dx * fy * ft * fu;
        const double gs = fx * dy * ft * fu;
        const double gt = -shift * (gr + gs) + fx * fy * (dt * fu - ft * du);
        return {gr, gs, gt};
    }
};

/// A basis of the space each cell kind must reproduce exactly (see elements/basis.h).
inline std::vector<SpaceFunction> SpaceOf(const CellKind& k) {
    std::vector<SpaceFunction> fs;
    const int p = k.order;
    if (k.shape == CellShape::Pyramid) {
        for (int i = 0; i <= p; ++i)
            for (int j = 0; j <= p; ++j) {
                const int mu = std::max(i, j);
                for (int kk = 0; kk + mu <= p; ++kk) {
                    if (k.family == CellFamily::Serendipity && i == 2 && j == 2) continue;
                    fs.push_back({{i, j, kk, mu - i - j}, 0.5});
                }
            }
        return fs;
    }
    for (int a = 0; a <= p; ++a)
        for (int b = 0; b <= p; ++b)
            for (int c = 0; c <= p; ++c) {
                bool in = false;
                if (k.family == CellFamily::Serendipity) {
                    const int super = (a >= 2 ? a : 0) + (b >= 2 ? b : 0) + (c >= 2 ? c : 0);
                    if (k.shape == CellShape::Hex) in = super <= 2;
                    else in = (a + b <= 2 && c <= 1) || (a + b <= 1 && c == 2);  // wedge15
                } else if (k.shape == CellShape::Tet) {
                    in = a + b + c <= p;
                } else if (k.shape == CellShape::Hex) {
                    in = true;
                } else {
                    in = a + b <= p;
                }
                if (in) fs.push_back({{a, b, c, 0}, 0.0});
            }
    return fs;
}

inline const char* FamilyName(CellFamily f) {
    return f == CellFamily::Lagrange ? "lagrange" : "serendipity";
}

}  // namespace hpray::testing
