// Independent references for volume-rendering tests: the integrals of docs/contracts.md
// ("Volume semantics") along one ray, in long double. ReferenceRay: adaptive
// Bulirsch-Stoer extrapolation on the ODE  phi' = tau(t),  C' = emission(t) exp(-phi),
// restarted at every kink of the integrand (cell faces, transfer-function breakpoints) and
// at embedded surfaces. NkSincSeriesReference: for nk-sinc's polynomial field, the field's
// exact series along each cell segment, the optical depth in closed form from the
// extinction's exact series, and the emission by adaptive many-node Gauss-Legendre
// quadrature (much faster than the ODE at the same accuracy).
#pragma once

#include <algorithm>
#include <array>
#include <boost/numeric/odeint.hpp>
#include <cmath>
#include <functional>
#include <map>
#include <vector>

#include "scene/scene.h"

namespace hpray::testing {

using LD = long double;

/// A piecewise-linear transfer function (clamped), written independently of the renderer.
struct RefTf {
    std::vector<LD> scalars;
    std::vector<std::array<LD, 3>> values;

    static RefTf Color(const std::vector<ColorControlPoint>& points) {
        RefTf tf;
        for (const auto& p : points) {
            tf.scalars.push_back(p.scalar);
            tf.values.push_back({p.rgb[0], p.rgb[1], p.rgb[2]});
        }
        return tf;
    }
    static RefTf Extinction(const std::vector<ExtinctionControlPoint>& points) {
        RefTf tf;
        for (const auto& p : points) {
            tf.scalars.push_back(p.scalar);
            tf.values.push_back({p.extinction, 0, 0});
        }
        return tf;
    }
    std::array<LD, 3> operator()(LD s) const {
        if (s <= scalars.front()) return values.front();
        if (s >= scalars.back()) return values.back();
        std::size_t k = 0;
        while (scalars[k + 1] < s) ++k;
        const LD w = (s - scalars[k]) / (scalars[k + 1] - scalars[k]);
        std::array<LD, 3> out;
        for (int c = 0; c < 3; ++c)
            out[c] = values[k][c] + w * (values[k + 1][c] - values[k][c]);
        return out;
    }
};

/// A surface composited at depth t: radiance `color` (not premultiplied), `opacity`.
struct RefSurface {
    LD t;
    std::array<LD, 3> color;
    LD opacity;
};

struct RefPixel {
    LD rgb[3] = {0, 0, 0};
    LD alpha = 0;
};

/// The pixel of a ray whose inside-the-data part is [t0, t1]: colour field c(t),
/// extinction field e(t), transfer functions, glow model; `kinks` are the t where the
/// integrand is not smooth (need not be sorted; those outside (t0, t1) are ignored). The
/// integration is controlled to `relTolerance` relative (and 1e-6 of that absolute).
inline RefPixel ReferenceRay(LD t0, LD t1, const std::function<LD(LD)>& colorField,
                             const std::function<LD(LD)>& extinctionField,
                             const RefTf& colorTf, const RefTf& extinctionTf,
                             bool williamsMax, std::vector<LD> kinks,
                             std::vector<RefSurface> surfaces = {},
                             LD relTolerance = 1e-18L) {
    namespace ode = boost::numeric::odeint;
    using State = std::array<LD, 4>;
    RefPixel out;
    if (!(t1 > t0)) return out;
    std::vector<LD> cuts = {t0, t1};
    for (LD k : kinks)
        if (k > t0 && k < t1) cuts.push_back(k);
    for (const RefSurface& s : surfaces)
        if (s.t > t0 && s.t < t1) cuts.push_back(s.t);
    std::sort(cuts.begin(), cuts.end());
    std::sort(surfaces.begin(), surfaces.end(),
              [](const RefSurface& a, const RefSurface& b) { return a.t < b.t; });
    auto rhs = [&](const State& x, State& dx, LD t) {
        const LD tau = std::max<LD>(0, extinctionTf(extinctionField(t))[0]);
        const auto c = colorTf(colorField(t));
        const LD att = std::exp(-x[0]);
        dx[0] = tau;
        for (int k = 0; k < 3; ++k) dx[1 + k] = (williamsMax ? c[k] * tau : c[k]) * att;
    };
    LD T = 1;
    std::size_t nextSurface = 0;
    for (std::size_t p = 0; p + 1 < cuts.size(); ++p) {
        const LD a = cuts[p], b = cuts[p + 1];
        while (nextSurface < surfaces.size() && surfaces[nextSurface].t <= a) {
            const RefSurface& s = surfaces[nextSurface++];
            if (s.t < a) continue;
            for (int k = 0; k < 3; ++k) out.rgb[k] += T * s.opacity * s.color[k];
            out.alpha += T * s.opacity;
            T *= 1 - s.opacity;
        }
        if (!(b > a)) continue;
        State x = {0, 0, 0, 0};
        // Bulirsch-Stoer: extrapolation of modified-midpoint steps, whose error estimate
        // (unlike Fehlberg 7(8)'s) stays honest when the right-hand side does not depend
        // on the state, as here.
        ode::bulirsch_stoer<State, LD> stepper(1e-6L * relTolerance, relTolerance);
        ode::integrate_adaptive(stepper, rhs, x, a, b, (b - a) / 8);
        for (int k = 0; k < 3; ++k) out.rgb[k] += T * x[1 + k];
        out.alpha += T * -std::expm1(-x[0]);
        T *= std::exp(-x[0]);
    }
    while (nextSurface < surfaces.size()) {
        const RefSurface& s = surfaces[nextSurface++];
        if (s.t != t1) continue;
        for (int k = 0; k < 3; ++k) out.rgb[k] += T * s.opacity * s.color[k];
        out.alpha += T * s.opacity;
        T *= 1 - s.opacity;
    }
    return out;
}

/// The chord [t0, t1] of a ray through the closed box [lo, hi] (long double slabs).
inline bool RefBoxChord(const std::array<double, 3>& origin,
                        const std::array<double, 3>& dir, const std::array<LD, 3>& lo,
                        const std::array<LD, 3>& hi, LD& t0, LD& t1) {
    t0 = -INFINITY;
    t1 = INFINITY;
    for (int a = 0; a < 3; ++a) {
        if (dir[a] == 0) {
            if (origin[a] < lo[a] || origin[a] > hi[a]) return false;
            continue;
        }
        LD u = (lo[a] - LD(origin[a])) / LD(dir[a]),
           v = (hi[a] - LD(origin[a])) / LD(dir[a]);
        if (u > v) std::swap(u, v);
        t0 = std::max(t0, u);
        t1 = std::min(t1, v);
    }
    return t0 < t1;
}

/// nk-sinc (builtin:nk-sinc): 5^3 axis-aligned boxes of order 8 on [0, 1]^3; the truth is
/// the tensor-product equispaced Lagrange interpolant of u = 2 (y - 0.3) - sinc(|(x, z) -
/// (0.5, 0.5)|) on each box (its nodal values in double, as the mesh has them), evaluated
/// here in long double independently of the library's bases.
class NkSincTruth {
  public:
    static constexpr double kBreaks[6] = {0.0, 0.27, 0.44, 0.56, 0.73, 1.0};
    static constexpr int kOrder = 8;

    static double U(double x, double y, double z) {
        const double pi = std::acos(-1.0);
        const double r = std::hypot(x - 0.5, z - 0.5);
        const double sinc = r == 0 ? 1.0 : std::sin(pi * r) / (pi * r);
        return 2.0 * (y - 0.3) - sinc;
    }
    static int Box(double x) {
        int b = 0;
        while (b < 4 && x > kBreaks[b + 1]) ++b;
        return b;
    }
    /// The interpolant at (x, y, z) in box (bx, by, bz), in long double.
    LD Eval(const LD x[3], const int box[3]) {
        const std::vector<double>& nodal = Nodal(box);
        LD l[3][kOrder + 1];
        for (int a = 0; a < 3; ++a) {
            const LD lo = kBreaks[box[a]], hi = kBreaks[box[a] + 1];
            const LD r = (x[a] - lo) / (hi - lo);
            for (int i = 0; i <= kOrder; ++i) {
                LD v = 1;
                for (int m = 0; m <= kOrder; ++m)
                    if (m != i) v *= (r * kOrder - m) / LD(i - m);
                l[a][i] = v;
            }
        }
        LD sum = 0;
        for (int k = 0; k <= kOrder; ++k)
            for (int j = 0; j <= kOrder; ++j) {
                const LD w = l[2][k] * l[1][j];
                const double* row = &nodal[((k * (kOrder + 1)) + j) * (kOrder + 1)];
                LD s = 0;
                for (int i = 0; i <= kOrder; ++i) s += row[i] * l[0][i];
                sum += w * s;
            }
        return sum;
    }

  private:
    const std::vector<double>& Nodal(const int box[3]) {
        const int key = box[0] + 5 * (box[1] + 5 * box[2]);
        auto it = cache_.find(key);
        if (it != cache_.end()) return it->second;
        std::vector<double> v;
        for (int k = 0; k <= kOrder; ++k)
            for (int j = 0; j <= kOrder; ++j)
                for (int i = 0; i <= kOrder; ++i) {
                    const int idx[3] = {i, j, k};
                    double x[3];
                    for (int a = 0; a < 3; ++a) {
                        const double lo = kBreaks[box[a]], hi = kBreaks[box[a] + 1];
                        const double r = double(idx[a]) / kOrder;
                        x[a] = lo * (1 - r) + hi * r;
                    }
                    v.push_back(U(x[0], x[1], x[2]));
                }
        return cache_[key] = std::move(v);
    }
    std::map<int, std::vector<double>> cache_;
};


/// Gauss-Legendre nodes and weights on [-1, 1] in long double (Newton on P_n from the
/// Chebyshev guesses), cached per n (not thread-safe: tests call it from one thread).
inline const std::pair<std::vector<LD>, std::vector<LD>>& GaussRuleLD(int n) {
    static std::map<int, std::pair<std::vector<LD>, std::vector<LD>>> cache;
    auto it = cache.find(n);
    if (it != cache.end()) return it->second;
    std::vector<LD> x(n), w(n);
    const LD pi = 3.141592653589793238462643383279502884L;
    for (int i = 0; i < n; ++i) {
        LD z = std::cos(pi * (i + 0.75L) / (n + 0.5L)), dp = 1;
        for (int it = 0; it < 100; ++it) {
            LD p0 = 1, p1 = z;
            for (int k = 2; k <= n; ++k) {
                const LD p2 = ((2 * k - 1) * z * p1 - (k - 1) * p0) / k;
                p0 = p1;
                p1 = p2;
            }
            dp = n * (z * p1 - p0) / (z * z - 1);
            const LD dz = p1 / dp;
            z -= dz;
            if (std::abs(dz) < 1e-21L) break;
        }
        x[i] = z;
        w[i] = 2 / ((1 - z * z) * dp * dp);
    }
    return cache[n] = {std::move(x), std::move(w)};
}

/// A polynomial on [a, b] as a Legendre series in long double.
struct RefSeries {
    LD a = 0, b = 1;
    std::vector<LD> c;
    LD operator()(LD t) const {
        // P_k = (2 - 1/k) x P_{k-1} - (1 - 1/k) P_{k-2}.
        static const std::vector<LD> inverse = [] {
            std::vector<LD> r(256);
            for (std::size_t k = 1; k < r.size(); ++k) r[k] = 1 / LD(k);
            return r;
        }();
        const LD x = (2 * t - a - b) / (b - a);
        LD p0 = 1, p1 = x, v = c[0];
        if (c.size() > 1) v += c[1] * x;
        for (std::size_t k = 2; k < c.size(); ++k) {
            const LD p2 = (2 - inverse[k]) * x * p1 - (1 - inverse[k]) * p0;
            v += c[k] * p2;
            p0 = p1;
            p1 = p2;
        }
        return v;
    }
    /// integral_a^t of the series.
    RefSeries Antiderivative() const {
        RefSeries r{a, b, std::vector<LD>(c.size() + 1, 0)};
        const LD h = (b - a) / 2;
        r.c[0] += h * c[0];
        r.c[1] += h * c[0];
        for (std::size_t k = 1; k < c.size(); ++k) {
            r.c[k + 1] += h * c[k] / (2 * k + 1);
            r.c[k - 1] -= h * c[k] / (2 * k + 1);
        }
        return r;
    }
};

/// The Legendre series of degree n of f on [a, b] by the (n + 1)-point Gauss rule: f
/// itself when f is a polynomial of degree <= n (the products with P_k are integrated
/// exactly).
inline RefSeries FitRefSeries(const std::function<LD(LD)>& f, LD a, LD b, int n) {
    const auto& [x, w] = GaussRuleLD(n + 1);
    RefSeries s{a, b, std::vector<LD>(n + 1, 0)};
    for (int i = 0; i <= n; ++i) {
        const LD v = f((a + b) / 2 + (b - a) / 2 * x[i]);
        LD p0 = 1, p1 = x[i];
        for (int k = 0; k <= n; ++k) {
            const LD pk = k == 0 ? 1 : k == 1 ? x[i] : p1;
            s.c[k] += (2 * k + 1) / LD(2) * w[i] * v * pk;
            if (k >= 1) {
                const LD p2 = ((2 * k + 1) * x[i] * p1 - k * p0) / (k + 1);
                p0 = p1;
                p1 = p2;
            }
        }
    }
    return s;
}

/// The pixel of a camera ray (origin, unit direction) through nk-sinc: on each box the
/// ray crosses, the interpolant along it is a polynomial of degree 3 * 8 = 24, fitted
/// exactly from 25 samples of `truth`; every transfer-function breakpoint crossing is
/// found on that series (sign changes at 256 points, bisection to long double); on each
/// piece between them the extinction is a polynomial of degree 24 too, fitted exactly,
/// whose antiderivative is the optical depth; the emission integral (transfer functions
/// evaluated on the field, clamped) by Gauss-Legendre rules of 48 and 64 nodes, bisected
/// until they agree to 1e-20 absolute + 1e-18 relative.
inline RefPixel NkSincSeriesReference(NkSincTruth& truth, const std::array<double, 3>& origin,
                                      const std::array<double, 3>& dir, const RefTf& colorTf,
                                      const RefTf& extinctionTf, bool williamsMax) {
    RefPixel out;
    LD t0, t1;
    if (!RefBoxChord(origin, dir, {0, 0, 0}, {1, 1, 1}, t0, t1)) return out;
    std::vector<LD> cuts = {t0, t1};
    for (int a = 0; a < 3; ++a)
        for (double b : NkSincTruth::kBreaks)
            if (dir[a] != 0) {
                const LD t = (LD(b) - origin[a]) / LD(dir[a]);
                if (t > t0 && t < t1) cuts.push_back(t);
            }
    std::sort(cuts.begin(), cuts.end());
    std::vector<LD> levels = colorTf.scalars;
    levels.insert(levels.end(), extinctionTf.scalars.begin(), extinctionTf.scalars.end());
    LD T = 1;
    for (std::size_t k = 0; k + 1 < cuts.size(); ++k) {
        const LD a = cuts[k], b = cuts[k + 1];
        if (!(b > a)) continue;
        int box[3];
        for (int d = 0; d < 3; ++d)
            box[d] = NkSincTruth::Box(double(origin[d] + (a + b) / 2 * dir[d]));
        const RefSeries u = FitRefSeries(
            [&](LD t) {
                LD x[3];
                for (int d = 0; d < 3; ++d) x[d] = origin[d] + t * dir[d];
                return truth.Eval(x, box);
            },
            a, b, 3 * NkSincTruth::kOrder);
        // Breakpoint crossings.
        std::vector<LD> pieces = {a, b};
        constexpr int kScan = 256;
        std::vector<LD> scan(kScan + 1);
        for (int m = 0; m <= kScan; ++m) scan[m] = u(a + (b - a) * m / kScan);
        for (LD level : levels) {
            LD ta = a, fa = scan[0] - level;
            for (int m = 1; m <= kScan; ++m) {
                const LD tb = a + (b - a) * m / kScan, fb = scan[m] - level;
                if ((fa < 0) != (fb < 0)) {
                    LD lo = ta, hi = tb, flo = fa;
                    for (int it = 0; it < 100 && hi - lo > 1e-19L * (b - a); ++it) {
                        const LD mid = (lo + hi) / 2, fm = u(mid) - level;
                        if ((fm < 0) == (flo < 0)) {
                            lo = mid;
                            flo = fm;
                        } else {
                            hi = mid;
                        }
                    }
                    pieces.push_back((lo + hi) / 2);
                }
                ta = tb;
                fa = fb;
            }
        }
        std::sort(pieces.begin(), pieces.end());
        for (std::size_t m = 0; m + 1 < pieces.size(); ++m) {
            const LD p = pieces[m], q = pieces[m + 1];
            if (!(q > p)) continue;
            auto tau = [&](LD t) { return std::max<LD>(0, extinctionTf(u(t))[0]); };
            const RefSeries depth =
                FitRefSeries(tau, p, q, 3 * NkSincTruth::kOrder).Antiderivative();
            auto integrate = [&](LD lo, LD hi, int n, std::array<LD, 3>& sum) {
                const auto& [x, w] = GaussRuleLD(n);
                sum = {0, 0, 0};
                for (int i = 0; i < n; ++i) {
                    const LD t = (lo + hi) / 2 + (hi - lo) / 2 * x[i];
                    const LD v = u(t);
                    const auto c = colorTf(v);
                    const LD tauHere = std::max<LD>(0, extinctionTf(v)[0]);
                    const LD weight = (williamsMax ? tauHere : 1) * std::exp(-depth(t));
                    for (int ch = 0; ch < 3; ++ch) sum[ch] += w[i] * c[ch] * weight;
                }
                for (LD& s : sum) s *= (hi - lo) / 2;
            };
            std::vector<std::array<LD, 3>> stack = {{p, q, 0}};
            while (!stack.empty()) {
                const auto [lo, hi, depthLevel] = stack.back();
                stack.pop_back();
                std::array<LD, 3> coarse, fine;
                integrate(lo, hi, 48, coarse);
                integrate(lo, hi, 64, fine);
                LD diff = 0, size = 0;
                for (int ch = 0; ch < 3; ++ch) {
                    diff = std::max(diff, std::abs(fine[ch] - coarse[ch]));
                    size = std::max(size, std::abs(fine[ch]));
                }
                if (diff > 1e-20L + 1e-18L * size && depthLevel < 40) {
                    stack.push_back({(lo + hi) / 2, hi, depthLevel + 1});
                    stack.push_back({lo, (lo + hi) / 2, depthLevel + 1});
                    continue;
                }
                for (int ch = 0; ch < 3; ++ch) out.rgb[ch] += T * fine[ch];
            }
            const LD pieceDepth = depth(q);
            out.alpha += T * -std::expm1(-pieceDepth);
            T *= std::exp(-pieceDepth);
        }
    }
    return out;
}

/// The t where f crosses `level` between consecutive points of `grid` (ascending): each
/// sign change, bisected.
inline void GridCrossings(const std::function<LD(LD)>& f, LD level,
                          const std::vector<LD>& grid, std::vector<LD>& out) {
    LD a = grid[0], fa = f(a) - level;
    for (std::size_t k = 1; k < grid.size(); ++k) {
        const LD b = grid[k], fb = f(b) - level;
        if ((fa < 0) != (fb < 0)) {
            LD lo = a, hi = b, flo = fa;
            for (int it = 0; it < 80; ++it) {
                const LD mid = (lo + hi) / 2, fm = f(mid) - level;
                if ((fm < 0) == (flo < 0)) {
                    lo = mid;
                    flo = fm;
                } else {
                    hi = mid;
                }
            }
            out.push_back((lo + hi) / 2);
        }
        a = b;
        fa = fb;
    }
}

/// The t in (t0, t1) where a field along a ray crosses `level`, by sampling and bisection
/// (the field is smooth between t0 and t1).
inline void SampledCrossings(const std::function<LD(LD)>& f, LD t0, LD t1, LD level,
                             int samples, std::vector<LD>& out) {
    std::vector<LD> grid(std::size_t(samples) + 1);
    for (int k = 0; k <= samples; ++k)
        grid[std::size_t(k)] = t0 + (t1 - t0) * k / samples;
    GridCrossings(f, level, grid, out);
}

}  // namespace hpray::testing
