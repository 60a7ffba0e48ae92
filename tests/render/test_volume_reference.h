// Independent reference for volume-rendering tests: the integrals of docs/contracts.md ("Volume
// semantics") along one ray, by adaptive Bulirsch-Stoer extrapolation in long double on
// the ODE  phi' = tau(t),  C' = emission(t) exp(-phi),  restarted at every kink of the
// integrand (cell faces, transfer-function breakpoints) and at embedded surfaces.
#pragma once

#include <algorithm>
#include <array>
#include <boost/numeric/odeint.hpp>
#include <cmath>
#include <functional>
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

}  // namespace hpray::testing
