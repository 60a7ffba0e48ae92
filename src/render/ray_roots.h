// Root finding along a ray segment: adaptive Legendre projection of the true field, root
// isolation that cannot miss the nearest root, and polishing on the true field.
//
// The guarantee. On each piece [a, b] the projection p satisfies |f - p| <= eps (eps is
// measured: the trailing Legendre coefficients plus the largest discrepancy between f and p
// at check points between the interpolation nodes, times a safety factor). Isolation
// discards a sub-interval only when its Legendre re-expansion proves |p - C| > eps there
// (|P_k| <= 1), so f - C has no root in it. A bracket is accepted only where |p - C| > eps
// at both ends with opposite signs, which proves a sign change of f - C, and is then
// polished by TOMS 748 on the true field. The guarantee ends where f - C stays within eps
// of zero without changing sign (tangency within the tolerance): such a window shrinks to
// the root tolerance and is reported as a tangent hit when |f - C| there is within the
// tangent tolerance, else it is a root failure (counted, never silent).
#pragma once

#include <boost/math/tools/toms748_solve.hpp>

#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <type_traits>
#include <utility>
#include <vector>

#include "render/legendre.h"

namespace hpray {

struct ProjectionOptions {
    /// Relative tolerance of the projection against the field's scale on the piece.
    double tolerance = 1e-12;
    /// Degree used when the field is a polynomial of known degree along the ray (affine
    /// cells): the interpolant is then exact. <= 0: choose adaptively.
    int exactDegree = 0;
    /// The first degree of the adaptive projection, doubled (nested Chebyshev–Lobatto
    /// nodes: every sample is kept) until the tail converges or maxDegree is reached.
    int startDegree = 3;
    int maxDegree = 48;
    /// Pieces are halved when maxDegree does not reach the tolerance, down to this length.
    /// startDegree == maxDegree pins the degree (order studies): it then also overrides
    /// exactDegree, and pieces are not split.
    int maxSplits = 6;
    /// Levels the caller needs only to know are not crossed (isovalues): once a raised
    /// degree's interpolant keeps farther from every one of them than twice its change
    /// since the previous level (the sum of the coefficients' differences, a bound of
    /// |p_2n - p_n| on the piece) plus the rounding floor, and than twice its measured
    /// miss at the four checks a converged piece takes, the piece stops there with the
    /// larger as its error (the previous level's error bounds the new one's wherever the
    /// expansion converges). Not used below degree 6.
    const double* exclude = nullptr;
    int excludeCount = 0;
    /// The scale the tolerance is relative to is at least this (e.g. the magnitude of the
    /// field over the whole mesh), so pieces where the field is nearly zero converge.
    double scaleFloor = 0;
    /// Where > 0: a piece of degree 6 or more whose tail (its last two coefficients) is
    /// below checkMargin times the tolerance is taken without the checks that measure its
    /// miss (four more samples; its error is then twice the tail). For loose tolerances
    /// (accuracy.target_residual), where a tail that many orders of magnitude below what
    /// is asked leaves the checks nothing to decide.
    double checkMargin = 0;
};

/// A projected piece of the segment: p approximates f on [p.a, p.b] with |f - p| <= eps.
struct ProjectedPiece {
    LegendreSeries p;
    double eps = 0;
    bool converged = true;
};

struct ProjectionStats {
    std::int64_t evaluations = 0;
    int maxDegree = 0;
    double degreeSum = 0;
    int pieces = 0;
    int unconverged = 0;
    int excluded = 0;  ///< pieces stopped early, far from every level to exclude
};

struct RootOptions {
    /// Stop polishing when the bracket is below this fraction of the segment length.
    double rootTolerance = 1e-14;
    /// A tangent (double) root is accepted where |f - C| <= this + the piece's eps.
    double tangentTolerance = 0;
    /// Polish roots on the true field (TOMS 748 on f - C). false: report the root of the
    /// projection p - C in the bracket (for order studies); the residual is still that of
    /// the true field there.
    bool polish = true;
    /// > 0: a root is accepted as soon as |f - C| <= this at it (absolute), first tried at
    /// the projection's own root; 0: polished to the root tolerance.
    double residualTarget = 0;
};

enum class RootKind : std::uint8_t { None = 0, Simple = 1, Tangent = 2 };

struct RootResult {
    RootKind kind = RootKind::None;
    double t = std::numeric_limits<double>::infinity();
    double residual = std::numeric_limits<double>::quiet_NaN();  ///< |f(t) - C|, true field
    int failures = 0;  ///< windows that could be neither excluded nor resolved
};

namespace detail {
/// Samples f at n ray parameters: through f.SampleBatch(t, n, out) when F has it (a
/// batched evaluator), else one call per point.
template <typename F, typename = void>
struct HasSampleBatch : std::false_type {};
template <typename F>
struct HasSampleBatch<F, std::void_t<decltype(std::declval<F&>().SampleBatch(
                             std::declval<const double*>(), 0, std::declval<double*>()))>>
    : std::true_type {};

template <typename F>
void SampleMany(F& f, const double* t, int n, double* out) {
    if constexpr (HasSampleBatch<F>::value) {
        f.SampleBatch(t, n, out);
    } else {
        for (int i = 0; i < n; ++i) out[i] = f(t[i]);
    }
}

/// The largest |f - p| at the `count` points t (f's values into `out`), the samples
/// counted in `evaluations`: a projection's measured miss.
template <typename F>
double MeasuredMiss(F& f, const LegendreSeries& p, const double* t, int count,
                    double* out, std::int64_t& evaluations) {
    SampleMany(f, t, count, out);
    evaluations += count;
    double miss = 0;
    for (int k = 0; k < count; ++k) miss = std::max(miss, std::abs(out[k] - p(t[k])));
    return miss;
}

/// Candidate windows of p - C on [p.a, p.b], in increasing t. `visit(lo, hi, kind, tStar)`
/// returns true to stop. Kinds: 1 a proven sign change (|p - C| > eps at both ends,
/// opposite signs, p monotone); 2 a tangency within eps at the extremum tStar; 3 a monotone
/// window with an end tStar within eps of C; 4 an unresolved window of width <= minWidth.
template <typename Visit>
void IsolateRoots(const LegendreSeries& p, double C, double eps, double minWidth,
                  std::vector<double>& scratch, Visit&& visit);

double TailExcluded(const LegendreSeries& q, double C);
}  // namespace detail

/// Projects f on [a, b] into pieces (ordered, covering [a, b]). `f(t)` returns the true
/// field at ray parameter t. An adaptive piece's samples are Chebyshev–Lobatto nodes of
/// it (nested from level to level), a pinned or exact one's are LGL nodes.
template <typename F>
void ProjectSegment(F&& f, double a, double b, const ProjectionOptions& options,
                    std::vector<ProjectedPiece>& pieces, ProjectionStats& stats,
                    std::vector<double>& scratch);

/// The first root of f - C in [a, b] given its projection `pieces`, polished on the true
/// field f. Never skips a root that changes sign by more than the projection error.
template <typename F>
RootResult FirstRoot(F&& f, const std::vector<ProjectedPiece>& pieces, double C,
                     const RootOptions& options, std::vector<double>& scratch);

/// Every root of f - C on the pieces, in increasing t, each polished as by FirstRoot:
/// `onRoot(const RootResult&)` returns true to stop. Returns the number of root failures
/// (windows neither excluded nor resolved).
template <typename F, typename OnRoot>
int FindRoots(F&& f, const std::vector<ProjectedPiece>& pieces, double C,
              const RootOptions& options, std::vector<double>& scratch, OnRoot&& onRoot);

// ---------------------------------------------------------------------------------------
// Implementation.

template <typename F>
void ProjectSegment(F&& f, double a, double b, const ProjectionOptions& options,
                    std::vector<ProjectedPiece>& pieces, ProjectionStats& stats,
                    std::vector<double>& scratch) {
    pieces.clear();
    if (!(b > a)) return;
    struct Work {
        double lo, hi;
        int depth;
    };
    // Depth-first, left first, so pieces come out ordered.
    Work stack[64];
    int top = 0;
    stack[top++] = {a, b, 0};
    while (top > 0) {
        const Work w = stack[--top];
        const double mid = 0.5 * (w.lo + w.hi), half = 0.5 * (w.hi - w.lo);
        auto sample = [&](int n) {
            const LglRule& rule = LglNodes(n);
            scratch.resize(2 * (n + 1));
            double* ts = scratch.data() + n + 1;
            for (int i = 0; i <= n; ++i) ts[i] = mid + half * rule.nodes[i];
            detail::SampleMany(f, ts, n + 1, scratch.data());
            scratch.resize(n + 1);
            stats.evaluations += n + 1;
            return InterpolateLgl(scratch.data(), n, w.lo, w.hi);
        };
        ProjectedPiece piece;
        const bool pinned = options.startDegree == options.maxDegree;
        if (options.exactDegree > 0 && !pinned) {
            const int n = std::min(options.exactDegree, kMaxLegendreDegree);
            piece.p = sample(n);
            // The interpolant is exact up to rounding in the samples and the transform.
            double scale = 0;
            for (double v : scratch) scale = std::max(scale, std::abs(v));
            piece.eps = 64 * (n + 1) * std::numeric_limits<double>::epsilon() * scale;
        } else if (!pinned) {
            // Nested Chebyshev–Lobatto levels n, 2n, 4n, ...: raising the degree keeps
            // every sample taken, so a segment pays for the degree it needs and no more.
            double values[kMaxLegendreDegree + 1], ts[kMaxLegendreDegree + 1],
                fresh[kMaxLegendreDegree + 1];
            int n = std::max(1, std::min(options.startDegree, options.maxDegree));
            auto sampleLevel = [&](int degree) {
                const ChebyshevLobattoRule& rule = ChebyshevLobattoNodes(degree);
                for (int i = 0; i <= degree; ++i) ts[i] = mid + half * rule.nodes[i];
                detail::SampleMany(f, ts, degree + 1, values);
                stats.evaluations += degree + 1;
            };
            // Node j of level N: ChebyshevLobattoNodes' table, or (beyond it, for the
            // checks of the last level) its formula.
            auto node = [](int j, int N) {
                return N <= kMaxLegendreDegree
                           ? ChebyshevLobattoNodes(N).nodes[j]
                           : std::sin(M_PI * double(2 * j - N) / double(2 * N));
            };
            // The largest |f - p| (p: piece.p, of degree n) at about four nodes of level
            // 2n, each halfway in angle between two of level n's.
            auto measure = [&](int n) {
                const int checks = std::min(n, 4);
                for (int k = 0; k < checks; ++k) {
                    const int i = (2 * k + 1) * n / (2 * checks);
                    ts[k] = mid + half * node(2 * i + 1, 2 * n);
                }
                return detail::MeasuredMiss(f, piece.p, ts, checks, fresh,
                                            stats.evaluations);
            };
            // A piece far from every level to exclude ends early (see
            // ProjectionOptions::exclude), right after a raise to a degree of 6 or more:
            // `previous` then holds the level before's interpolant.
            LegendreSeries previous;
            // Whether piece.p (degree n) is taken without the checks (see checkMargin).
            auto trusted = [&](int n, double scale) {
                return options.checkMargin > 0 && n >= 6 &&
                       std::abs(piece.p.c[n]) + std::abs(piece.p.c[n - 1]) <=
                           options.checkMargin * options.tolerance * scale;
            };
            auto stopsFar = [&](int n, double scale) {
                double change = 0;
                for (int k = 0; k <= n; ++k)
                    change += std::abs(piece.p.c[k] - (2 * k <= n ? previous.c[k] : 0.0));
                const double eps =
                    2 * change +
                    2 * 64 * (n + 1) * std::numeric_limits<double>::epsilon() * scale;
                auto far = [&](double e) {
                    for (int k = 0; k < options.excludeCount; ++k)
                        if (!(detail::TailExcluded(piece.p, options.exclude[k]) > e))
                            return false;
                    return true;
                };
                if (!far(eps)) return false;
                // Measured as a converged piece is (the checks are not kept where they
                // disagree: they are few, and this is rare).
                const double measured =
                    trusted(n, scale) ? eps : std::max(eps, 2 * measure(n));
                if (!far(measured)) return false;
                piece.eps = measured;
                piece.converged = true;
                stats.excluded += 1;
                return true;
            };
            sampleLevel(n);
            bool raised = false;
            for (;;) {
                InterpolateChebyshevLobatto(values, n, w.lo, w.hi, piece.p);
                double scale = options.scaleFloor;
                for (int i = 0; i <= n; ++i) scale = std::max(scale, std::abs(values[i]));
                if (raised && stopsFar(n, scale)) break;
                const double tail = std::abs(piece.p.c[n]) + std::abs(piece.p.c[n - 1]);
                const double floor =
                    64 * (n + 1) * std::numeric_limits<double>::epsilon() * scale;
                const bool converged = tail <= options.tolerance * scale;
                if (converged || n >= options.maxDegree) {
                    const double discrepancy = trusted(n, scale) ? 0.0 : measure(n);
                    piece.eps = 2 * std::max({tail, discrepancy, floor});
                    piece.converged = converged;
                    break;
                }
                if (2 * n <= options.maxDegree) {
                    // The n new nodes of level 2n sit between this level's.
                    for (int i = 0; i < n; ++i)
                        ts[i] = mid + half * node(2 * i + 1, 2 * n);
                    detail::SampleMany(f, ts, n, fresh);
                    stats.evaluations += n;
                    for (int i = n; i >= 0; --i) values[2 * i] = values[i];
                    for (int i = 0; i < n; ++i) values[2 * i + 1] = fresh[i];
                    n *= 2;
                    raised = options.excludeCount > 0 && n >= 6;
                    if (raised) previous.c.swap(piece.p.c);
                } else {
                    n = options.maxDegree;
                    sampleLevel(n);
                    raised = false;
                }
            }
            if (!piece.converged && w.depth < options.maxSplits && top + 2 <= 64) {
                stack[top++] = {mid, w.hi, w.depth + 1};
                stack[top++] = {w.lo, mid, w.depth + 1};
                continue;
            }
        } else {
            // A pinned degree (order studies): LGL nodes, every gap checked, since the
            // degree need not have converged and its tail is then no error estimate.
            const int n = options.startDegree;
            piece.p = sample(n);
            double scale = options.scaleFloor;
            for (double v : scratch) scale = std::max(scale, std::abs(v));
            const double tail = std::abs(piece.p.c[n]) + std::abs(piece.p.c[n - 1]);
            const double floor =
                64 * (n + 1) * std::numeric_limits<double>::epsilon() * scale;
            const LglRule& rule = LglNodes(n);
            double checkT[kMaxLegendreDegree + 1], checkF[kMaxLegendreDegree + 1];
            int checks = 0;
            for (int i = 0; i < n; i += std::max(1, n / 4))
                checkT[checks++] = mid + half * 0.5 * (rule.nodes[i] + rule.nodes[i + 1]);
            const double discrepancy = detail::MeasuredMiss(f, piece.p, checkT, checks,
                                                            checkF, stats.evaluations);
            piece.eps = 2 * std::max(discrepancy, floor);
            piece.converged = tail <= options.tolerance * scale;
        }
        stats.maxDegree = std::max(stats.maxDegree, piece.p.Degree());
        stats.degreeSum += piece.p.Degree();
        stats.pieces += 1;
        stats.unconverged += !piece.converged;
        pieces.push_back(std::move(piece));
    }
}

namespace detail {

/// The single root of a series whose derivative keeps one sign on [lo, hi], given
/// opposite signs at the ends.
inline double PolishSeriesRoot(const LegendreSeries& q, double lo, double hi, double vlo,
                               double vhi, double minWidth) {
    auto tol = [&](double x, double y) { return std::abs(y - x) <= minWidth; };
    std::uintmax_t iterations = 200;
    auto r = boost::math::tools::toms748_solve([&](double t) { return q(t); }, lo, hi, vlo, vhi,
                                               tol, iterations);
    return 0.5 * (r.first + r.second);
}

/// f - C with the last few values remembered, so that the ends of a bracket returned by
/// the solver (points it has already sampled) cost no new sample.
template <typename F>
struct RecentValues {
    F& f;
    double C;
    double t[8] = {}, v[8] = {};
    int count = 0;
    double operator()(double x) {
        for (int i = 0; i < std::min(count, 8); ++i)
            if (t[i] == x) return v[i];
        const double value = f(x) - C;
        t[count % 8] = x;
        v[count % 8] = value;
        ++count;
        return value;
    }
};
template <typename F>
RecentValues(F&, double) -> RecentValues<F>;

/// For a series p monotone on [lo, hi] with |p - C| > eps at both ends and opposite signs:
/// [a, b] inside it, about the root of p - C, with |p - C| > eps at a and b (or a, b at
/// the window's ends), and r the root of p - C. Then every t in the window where
/// |p - C| <= eps lies in (a, b).
/// False if no such bracket narrower than the window was found.
inline bool TightBracket(const LegendreSeries& p, double C, double eps, double lo, double hi,
                         double minWidth, double& a, double& b, double& r) {
    const double vlo = p(lo) - C, vhi = p(hi) - C;
    if (!(std::abs(vlo) > eps && std::abs(vhi) > eps) || (vlo < 0) == (vhi < 0)) return false;
    {  // r: the root of p - C
        auto tol = [&](double x, double y) { return std::abs(y - x) <= minWidth; };
        std::uintmax_t iterations = 200;
        auto q = [&](double t) { return p(t) - C; };
        const auto br = boost::math::tools::toms748_solve(q, lo, hi, vlo, vhi, tol, iterations);
        r = 0.5 * (br.first + br.second);
    }
    const double h = std::max(minWidth, 1e-6 * (hi - lo));
    const double slope = std::abs(p(std::min(hi, r + h)) - p(std::max(lo, r - h))) /
                         (std::min(hi, r + h) - std::max(lo, r - h));
    double delta = std::max(2 * minWidth, slope > 0 ? 2 * eps / slope : hi - lo);
    for (int k = 0; k < 24; ++k, delta *= 4) {
        a = std::max(lo, r - delta);
        b = std::min(hi, r + delta);
        if (a == lo && b == hi) return false;
        if ((a == lo || std::abs(p(a) - C) > eps) && (b == hi || std::abs(p(b) - C) > eps))
            return true;
    }
    return false;
}

/// A window of IsolateRoots: the series on it and what is known of it.
struct IsolateWindow {
    LegendreSeries q;
    double vlo = 0, vhi = 0;  // q(lo) - C, q(hi) - C
    bool monotone = false;    // proven: q' keeps one sign on the interval
    int depth = 0;
};

/// IsolateRoots' storage, kept per thread from call to call: the series of its windows
/// keep their capacity, so a call allocates nothing once the thread has run a few.
struct IsolateStorage {
    std::vector<IsolateWindow> windows;  ///< a stack: the first `size` are in use
    std::size_t size = 0;
    IsolateWindow current;
    LegendreSeries derivative, second;
    bool busy = false;  ///< a call on this thread is running (a visit may call again)

    IsolateWindow& Push(double vlo, double vhi, bool monotone, int depth) {
        if (size == windows.size()) windows.emplace_back();
        IsolateWindow& w = windows[size++];
        w.vlo = vlo;
        w.vhi = vhi;
        w.monotone = monotone;
        w.depth = depth;
        return w;
    }
    /// Moves the top window into `current` (the series' storage swapped, not copied).
    void Pop() {
        IsolateWindow& w = windows[--size];
        std::swap(current.q.c, w.q.c);
        current.q.a = w.q.a;
        current.q.b = w.q.b;
        current.vlo = w.vlo;
        current.vhi = w.vhi;
        current.monotone = w.monotone;
        current.depth = w.depth;
    }
};

template <typename Visit>
void IsolateRoots(const LegendreSeries& p, double C, double eps, double minWidth,
                  std::vector<double>& scratch, Visit&& visit) {
    static thread_local IsolateStorage shared;
    IsolateStorage local;
    IsolateStorage& store = shared.busy ? local : shared;
    struct Release {
        IsolateStorage& store;
        ~Release() {
            store.busy = false;
            store.size = 0;
        }
    } release{store};
    store.busy = true;
    store.size = 0;
    {
        IsolateWindow& first = store.Push(p(p.a) - C, p(p.b) - C, false, 0);
        first.q.a = p.a;
        first.q.b = p.b;
        first.q.c.assign(p.c.begin(), p.c.end());
    }
    // Windows examined before the rest is given up as one unresolved window: a bound on
    // the work whatever the series (the flat test below handles the known cause).
    constexpr int kMaxWindows = 20000;
    int windows = 0;
    double flatEnd = std::numeric_limits<double>::quiet_NaN();
    IsolateWindow& w = store.current;
    LegendreSeries& d = store.derivative;
    while (store.size > 0) {
        store.Pop();
        const double lo = w.q.a, hi = w.q.b;
        if (++windows > kMaxWindows) {
            double end = hi;
            for (std::size_t k = 0; k < store.size; ++k)
                end = std::max(end, store.windows[k].q.b);
            visit(lo, end, 4, 0.5 * (lo + end));
            return;
        }
        // |q - C| >= |c0 - C| - tail: exclude when that exceeds the projection error.
        if (!w.monotone && TailExcluded(w.q, C) > eps) continue;
        // |q - C| <= |c0 - C| + tail: within twice the error of C over the whole window,
        // the field touches the level along an interval, where no root can be told from
        // another: one contact at the start of each run of such windows. (Twice: windows
        // where q - C is near the error itself would otherwise be split to the root
        // tolerance wherever q is flat, as at a contact of high multiplicity.)
        if (std::abs(w.q.c[0] - C) + w.q.Tail() <= 2 * eps) {
            const bool continues = lo == flatEnd;
            flatEnd = hi;
            if (!continues && visit(lo, hi, 2, lo)) return;
            continue;
        }
        bool monotone = w.monotone;
        if (!monotone) {
            w.q.Derivative(d);
            monotone = TailExcluded(d, 0.0) > 0;
        }
        if (monotone) {
            // The range of q is [min(vlo, vhi), max(vlo, vhi)].
            if (std::min(w.vlo, w.vhi) > eps || std::max(w.vlo, w.vhi) < -eps) continue;
            if (std::abs(w.vlo) > eps && std::abs(w.vhi) > eps) {
                if (visit(lo, hi, 1, lo)) return;  // proven sign change
                continue;
            }
            // An end within eps of C: the root is at that end, within the error.
            const double t = std::abs(w.vlo) <= eps ? lo : hi;
            if (visit(lo, hi, 3, t)) return;
            continue;
        }
        // q' changes sign. With a proven single root of q' (q'' keeps one sign), q is
        // unimodal: split at its extremum t*, where a tangency would be.
        const double dlo = d(lo), dhi = d(hi);
        if ((dlo < 0) != (dhi < 0) && dlo != 0 && dhi != 0 &&
            (d.Derivative(store.second), TailExcluded(store.second, 0.0) > 0)) {
            const double ts = PolishSeriesRoot(d, lo, hi, dlo, dhi, minWidth);
            const double vs = w.q(ts) - C;
            if (std::abs(vs) <= eps && (w.vlo < 0) == (w.vhi < 0) && std::abs(w.vlo) > eps &&
                std::abs(w.vhi) > eps) {
                if (visit(lo, hi, 2, ts)) return;  // tangency within the error
                continue;
            }
            if (ts > lo && ts < hi) {
                Restrict(w.q, ts, hi, scratch,
                         store.Push(vs, w.vhi, true, w.depth + 1).q);
                Restrict(w.q, lo, ts, scratch,
                         store.Push(w.vlo, vs, true, w.depth + 1).q);
                continue;
            }
        }
        if (hi - lo <= minWidth || w.depth >= 60) {
            if (visit(lo, hi, 4, 0.5 * (lo + hi))) return;
            continue;
        }
        const double mid = 0.5 * (lo + hi);
        const double vmid = w.q(mid) - C;
        Restrict(w.q, mid, hi, scratch, store.Push(vmid, w.vhi, false, w.depth + 1).q);
        Restrict(w.q, lo, mid, scratch, store.Push(w.vlo, vmid, false, w.depth + 1).q);
    }
}

}  // namespace detail

template <typename F, typename OnRoot>
int FindRoots(F&& f, const std::vector<ProjectedPiece>& pieces, double C,
              const RootOptions& options, std::vector<double>& scratch, OnRoot&& onRoot) {
    RootResult result;
    bool stop = false;
    if (pieces.empty()) return 0;
    const double length = pieces.back().p.b - pieces.front().p.a;
    const double minWidth = std::max(options.rootTolerance * length,
                                     4 * std::numeric_limits<double>::epsilon() *
                                         std::max(std::abs(pieces.front().p.a),
                                                  std::abs(pieces.back().p.b)));
    for (const ProjectedPiece& piece : pieces) {
        const double accept = options.tangentTolerance + 2 * piece.eps;
        detail::IsolateRoots(
            piece.p, C, piece.eps, minWidth, scratch,
            [&](double lo, double hi, int kind, double tStar) {
                if (kind == 1 && options.polish) {
                    // A proven sign change of p - C with p monotone: the roots of f - C in
                    // the window all lie where |p - C| <= eps, a short interval about the
                    // root of p. Bracket that interval and polish inside it, which needs
                    // far fewer samples of the true field than the whole window.
                    double a, b, r;
                    if (detail::TightBracket(piece.p, C, piece.eps, lo, hi, minWidth, a, b, r)) {
                        detail::RecentValues g{f, C};
                        const double target = options.residualTarget;
                        // The projection's root: |f - C| <= eps there if eps holds.
                        const double gr = g(r);
                        if (target > 0 && std::abs(gr) <= target) {
                            result = {RootKind::Simple, r, std::abs(gr), result.failures};
                            return stop = onRoot(result);
                        }
                        // Newton on the true field with the projection's slope (p' is
                        // within about n^2 eps / length of f'), then secant steps:
                        // accepted once the step left is below a quarter of the root
                        // tolerance, inside [a, b], where every root of f - C in the
                        // window lies.
                        double pr, slope;
                        piece.p.Eval(r, pr, slope);
                        if (std::abs(gr) <= piece.eps && slope != 0 &&
                            std::isfinite(gr)) {
                            double t0 = r, g0 = gr, s0 = slope;
                            for (int step = 0; step < 3; ++step) {
                                const double t1 = t0 - g0 / s0;
                                if (!(t1 >= a && t1 <= b)) break;
                                const double g1 = g(t1);
                                if (g1 == 0 ||
                                    std::abs(g1) <= 0.25 * std::abs(slope) * minWidth) {
                                    result = {RootKind::Simple, t1, std::abs(g1),
                                              result.failures};
                                    return stop = onRoot(result);
                                }
                                if (t1 == t0 || g1 == g0) break;
                                s0 = (g1 - g0) / (t1 - t0);
                                t0 = t1;
                                g0 = g1;
                                if (!(s0 != 0) || !std::isfinite(s0)) break;
                            }
                        }
                        const double ga = g(a), gb = g(b);
                        const double pa = piece.p(a) - C;
                        // The true field must have the projection's signs there (else the
                        // measured eps was wrong: take the whole window below).
                        if ((ga < 0) == (pa < 0) && (gb < 0) != (pa < 0) && ga != 0 &&
                            gb != 0) {
                            auto tol = [&](double x, double y) {
                                return std::abs(y - x) <= minWidth ||
                                       (target > 0 && std::min(std::abs(g(x)),
                                                               std::abs(g(y))) <= target);
                            };
                            std::uintmax_t iterations = 200;
                            auto bracket = boost::math::tools::toms748_solve(
                                std::ref(g), a, b, ga, gb, tol, iterations);
                            const double ra = std::abs(g(bracket.first));
                            const double rb = std::abs(g(bracket.second));
                            const double t = ra <= rb ? bracket.first : bracket.second;
                            result = {RootKind::Simple, t, std::min(ra, rb), result.failures};
                            return stop = onRoot(result);
                        }
                    }
                }
                const double glo = f(lo) - C, ghi = f(hi) - C;
                if ((glo < 0) != (ghi < 0) || glo == 0 || ghi == 0) {
                    if (glo == 0 || ghi == 0) {
                        const double t = glo == 0 ? lo : hi;
                        result = {RootKind::Simple, t, 0.0, result.failures};
                        return stop = onRoot(result);
                    }
                    if (!options.polish) {
                        const double plo = piece.p(lo) - C, phi = piece.p(hi) - C;
                        double t = lo;
                        if ((plo < 0) != (phi < 0) && plo != 0 && phi != 0) {
                            auto q = [&](double x) { return piece.p(x) - C; };
                            auto tol = [&](double x, double y) {
                                return std::abs(y - x) <= minWidth;
                            };
                            std::uintmax_t iterations = 200;
                            auto r = boost::math::tools::toms748_solve(q, lo, hi, plo, phi,
                                                                       tol, iterations);
                            t = 0.5 * (r.first + r.second);
                        } else {
                            t = std::abs(plo) <= std::abs(phi) ? lo : hi;
                        }
                        result = {RootKind::Simple, t, std::abs(f(t) - C), result.failures};
                        return stop = onRoot(result);
                    }
                    auto g = [&](double t) { return f(t) - C; };
                    auto tol = [&](double x, double y) { return std::abs(y - x) <= minWidth; };
                    std::uintmax_t iterations = 200;
                    auto bracket = boost::math::tools::toms748_solve(g, lo, hi, glo, ghi, tol,
                                                                     iterations);
                    // Report the bracket end with the smaller true residual.
                    const double ga = std::abs(g(bracket.first));
                    const double gb = std::abs(g(bracket.second));
                    const double t = ga <= gb ? bracket.first : bracket.second;
                    result = {RootKind::Simple, t, std::min(ga, gb), result.failures};
                    return stop = onRoot(result);
                }
                // No sign change of the true field across the window: a tangency (kind 2),
                // a root at the window's end within the error (3), or unresolved (4).
                const double gs = std::abs(f(tStar) - C);
                if (gs <= accept) {
                    result = {kind == 3 ? RootKind::Simple : RootKind::Tangent, tStar, gs,
                              result.failures};
                    return stop = onRoot(result);
                }
                if (kind == 4) ++result.failures;
                return false;
            });
        if (stop) break;
    }
    return result.failures;
}

template <typename F>
RootResult FirstRoot(F&& f, const std::vector<ProjectedPiece>& pieces, double C,
                     const RootOptions& options, std::vector<double>& scratch) {
    RootResult first;
    const int failures = FindRoots(f, pieces, C, options, scratch, [&](const RootResult& r) {
        first = r;
        return true;
    });
    first.failures = failures;
    return first;
}

}  // namespace hpray
