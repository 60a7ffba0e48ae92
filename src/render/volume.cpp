// The optical model of volume rendering (see volume.h).
#include "render/volume.h"

#include <cerf.h>

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <array>
#include <boost/math/quadrature/gauss.hpp>
#include <boost/math/quadrature/gauss_kronrod.hpp>
#include <cmath>
#include <cstring>
#include <limits>

#include "render/legendre.h"
#include "util/check.h"
#include "util/dense_inverse.h"
#include "util/lanes.h"

namespace hpray {

void PiecewiseLinearTf::ComputeAffineOn(int k, double* offset, double* slope) const {
    const int n = Size();
    if (k < 0 || k >= n - 1) {
        const double* v = values_.data() + (k < 0 ? 0 : std::size_t(n - 1) * channels_);
        for (int c = 0; c < channels_; ++c) {
            offset[c] = v[c];
            slope[c] = 0;
        }
        return;
    }
    const double s0 = scalars_[k], s1 = scalars_[k + 1];
    const double* v0 = values_.data() + std::size_t(k) * channels_;
    const double* v1 = v0 + channels_;
    for (int c = 0; c < channels_; ++c) {
        slope[c] = (v1[c] - v0[c]) / (s1 - s0);
        // Anchored at the end nearer zero, so the offset carries no large cancellation.
        offset[c] =
            std::abs(s0) <= std::abs(s1) ? v0[c] - slope[c] * s0 : v1[c] - slope[c] * s1;
    }
}

PiecewiseLinearTf::PiecewiseLinearTf(std::vector<double> scalars,
                                     std::vector<double> values, int channels)
    : scalars_(std::move(scalars)), values_(std::move(values)), channels_(channels) {
    HPRAY_CHECK(channels_ >= 1);
    HPRAY_CHECK(!scalars_.empty());
    HPRAY_CHECK(values_.size() == scalars_.size() * std::size_t(channels_));
    for (std::size_t k = 1; k < scalars_.size(); ++k)
        HPRAY_CHECK(scalars_[k - 1] < scalars_[k]);
    short_.Set(scalars_);
    size_ = static_cast<int>(scalars_.size());
    // Piece k sits at index k + 1: the clamped pieces -1 and Size() - 1 have slope 0.
    steepest_.assign(scalars_.size() + 1, 0.0);
    affineOffset_.assign((scalars_.size() + 1) * channels_, 0.0);
    affineSlope_.assign((scalars_.size() + 1) * channels_, 0.0);
    for (int k = -1; k < Size(); ++k) {
        double* o = affineOffset_.data() + std::size_t(k + 1) * channels_;
        double* sl = affineSlope_.data() + std::size_t(k + 1) * channels_;
        ComputeAffineOn(k, o, sl);
        double m = 0;
        for (int c = 0; c < channels_; ++c) m = std::max(m, std::abs(sl[c]));
        steepest_[k + 1] = m;
    }
    // The lane lookups' tables (see LaneIndex), which give the clamped pieces' slope as
    // +0, the value of their entries here.
    HPRAY_CHECK(steepest_.front() == 0 && !std::signbit(steepest_.front()) &&
                steepest_.back() == 0 && !std::signbit(steepest_.back()));
    if (short_.valid && channels_ <= 3) {
        for (int k = 0; k < Size(); ++k) {
            laneScalars_[k] = scalars_[k];
            for (int c = 0; c < channels_; ++c)
                laneValues_[c][k] = values_[std::size_t(k) * channels_ + c];
            laneSteepest_[k] = steepest_[k];
        }
    }
}

void PiecewiseLinearTf::RangeOver(double lo, double hi, double* minOut,
                                  double* maxOut) const {
    double v[3];
    HPRAY_CHECK(channels_ <= 3);
    Eval(lo, minOut);
    for (int c = 0; c < channels_; ++c) maxOut[c] = minOut[c];
    auto include = [&](const double* x) {
        for (int c = 0; c < channels_; ++c) {
            minOut[c] = std::min(minOut[c], x[c]);
            maxOut[c] = std::max(maxOut[c], x[c]);
        }
    };
    Eval(hi, v);
    include(v);
    for (int k = 0; k < Size(); ++k)
        if (scalars_[k] > lo && scalars_[k] < hi)
            include(values_.data() + std::size_t(k) * channels_);
}

double PiecewiseLinearTf::MaxValue() const {
    return *std::max_element(values_.begin(), values_.end());
}

double PiecewiseLinearTf::MaxSlope() const {
    double slope = 0;
    for (int k = 0; k + 1 < Size(); ++k)
        for (int c = 0; c < channels_; ++c) {
            const double dv = values_[std::size_t(k + 1) * channels_ + c] -
                              values_[std::size_t(k) * channels_ + c];
            slope = std::max(slope, std::abs(dv) / (scalars_[k + 1] - scalars_[k]));
        }
    return slope;
}

namespace {

constexpr int kMaxTaylorTerms = 64;
/// Series in the slope: at most this many terms, so moments up to E_{2 + 2
/// kMaxSlopeTerms}.
constexpr int kMaxSlopeTerms = 32;
constexpr int kMaxExpMoment = 2 + 2 * kMaxSlopeTerms;

/// Regime "small depth" (alpha + |beta| <= 1): the Taylor series T(x) = sum c_n x^n of
/// exp(-alpha x - beta x^2), c_0 = 1, (n + 1) c_{n+1} = -alpha c_n - 2 beta c_{n-1}, so
/// I_m = sum c_n / (n + m + 1). |c_n| <= 2^n / n!: 30 terms reach 1e-23, and the
/// alternating sum loses at most a factor e^2 to cancellation.
/// 1 / k for k = 0..kMaxTaylorTerms + 2 (index 0 unused): the series below multiply by
/// these instead of dividing (each product is within an ulp of the quotient).
const std::array<double, kMaxTaylorTerms + 3> kReciprocal = [] {
    std::array<double, kMaxTaylorTerms + 3> r{};
    for (int k = 1; k < kMaxTaylorTerms + 3; ++k) r[k] = 1.0 / k;
    return r;
}();

void TaylorMoments(double alpha, double beta, double m[3]) {
    double cPrev = 0, c = 1;
    m[0] = m[1] = m[2] = 0;
    for (int n = 0; n < kMaxTaylorTerms; ++n) {
        m[0] += c * kReciprocal[n + 1];
        m[1] += c * kReciprocal[n + 2];
        m[2] += c * kReciprocal[n + 3];
        // c_{n+1} = a_n c_n + b_n c_{n-1}: the factors and b_n c_{n-1} do not wait for
        // c_n, so each term costs one fused multiply-add of latency.
        const double a = -alpha * kReciprocal[n + 1];
        const double b = -2 * beta * kReciprocal[n + 1];
        const double next = std::fma(a, c, b * cPrev);
        cPrev = c;
        c = next;
        // The rest adds below 1e-17 (the terms decay faster than 2^n / n!), a tenth of
        // an ulp of the smallest moment (I2 >= e^-1 / 3).
        if (std::abs(c) + std::abs(cPrev) <= 1e-17) break;
    }
}

/// E_n(alpha) = integral_0^1 x^n exp(-alpha x) dx for n = 0..count-1 (count <=
/// kMaxExpMoment + 1), alpha >= 0. Upward recurrence E_n = (n E_{n-1} - e^-alpha) / alpha
/// where it is stable (alpha >= n); otherwise the positive series
/// E_N = e^-alpha sum_j alpha^j / ((N+1)...(N+j+1)) at N >= 2 alpha (ratio <= 1/2), then
/// the downward recurrence E_{n-1} = (alpha E_n + e^-alpha) / n (positive terms).
void ExpMoments(double alpha, int count, double* e) {
    const double ea = std::exp(-alpha);
    if (alpha >= count) {
        e[0] = -std::expm1(-alpha) / alpha;
        for (int n = 1; n < count; ++n) e[n] = (n * e[n - 1] - ea) / alpha;
        return;
    }
    const int top = std::max(count - 1, static_cast<int>(std::ceil(2 * alpha)));
    double term = 1.0 / (top + 1), sum = 0;
    for (int j = 0; j < 400; ++j) {
        sum += term;
        term *= alpha / (top + j + 2);
        if (term <= 1e-19 * sum) break;
    }
    double en = ea * sum;
    for (int n = top; n > 0; --n) {
        if (n < count) e[n] = en;
        en = (alpha * en + ea) / n;
    }
    e[0] = en;
}

/// Regime "small slope": exp(-alpha x - beta x^2) = e^(-alpha x) sum_k (-beta x^2)^k /
/// k!, so I_m = sum_k (-beta)^k / k! E_{m+2k}(alpha). Used for |beta| <= 1 (term ratio <=
/// |beta| / k) and for |beta| <= alpha^2 / 200 with beta <= alpha / 2: the term ratio is
/// then about 4 k beta / alpha^2 <= k / 50 while 2k < alpha, and the sum of |terms|,
/// integral x^m exp(-alpha x + |beta| x^2), stays within a small factor of the result
/// (for beta < 0 all terms are positive). 32 terms reach 1e-18 relative.
void SlopeSeriesMoments(double alpha, double beta, double m[3]) {
    double e[kMaxExpMoment + 1];
    ExpMoments(alpha, kMaxExpMoment + 1, e);
    double coef = 1;
    m[0] = m[1] = m[2] = 0;
    for (int k = 0; k <= kMaxSlopeTerms; ++k) {
        const double t0 = coef * e[2 * k];
        m[0] += t0;
        m[1] += coef * e[2 * k + 1];
        m[2] += coef * e[2 * k + 2];
        if (std::abs(t0) <= 1e-19 * std::abs(m[0])) break;
        coef *= -beta / (k + 1);
    }
}

/// Depths below this take OpacityOfSmallDepth; the others exp.
constexpr double kSmallDepth = 0.5;

/// 1 - e^-d for 0 <= d < kSmallDepth: d times the sum of (-d)^k / (k + 1)! to degree 16
/// (the next term is below 2e-20 of the sum), by Horner's rule with fused multiply-adds;
/// the terms alternate and fall by at least 4x, so the sum (>= 0.78) carries about an
/// ulp. Written once for a double and for vectors (OpacityOfSmallDepthLanes): the same
/// operations, so each lane's value is the scalar one bitwise.
inline double OpacityOfSmallDepth(double d) {
    const double x = -d;
    double p = kInverseFactorial[17];
    for (int k = 15; k >= 0; --k) p = std::fma(p, x, kInverseFactorial[k + 1]);
    return d * p;
}

/// The start of IntegrateLinearPiece: the clamped inputs, alpha, beta and depth.
struct PieceStart {
    double alpha, beta, depth;
};
[[gnu::always_inline]] inline PieceStart LinearPieceStart(double tau0, double tau1,
                                                          double length) {
    tau0 = std::max(0.0, tau0);
    tau1 = std::max(0.0, tau1);
    length = std::max(0.0, length);
    // D(x) = alpha x + beta x^2; alpha + 2 beta = length tau1 >= 0.
    return {length * tau0, 0.5 * length * (tau1 - tau0), 0.5 * length * (tau0 + tau1)};
}
/// The piece's exponential from its start, given its opacity when the depth is small
/// (OpacityOfSmallDepth, or the same computed in lanes). True when the Taylor regime
/// applies.
bool FinishLinearPieceStart(const PieceStart& start, double smallOpacity,
                            LinearPieceIntegrals& q) {
    // One exponential: for small depth the opacity and T = 1 - opacity (T >= 0.6, so
    // within 2 ulps), else T by exp and the opacity 1 - T (>= 0.39, likewise).
    if (start.depth < kSmallDepth) {
        q.opacity = smallOpacity;
        q.transmittance = 1 - q.opacity;
    } else {
        q.transmittance = std::exp(-start.depth);
        q.opacity = 1 - q.transmittance;
    }
    return start.alpha + std::abs(start.beta) <= 1;
}
bool BeginLinearPiece(double tau0, double tau1, double length, LinearPieceIntegrals& q,
                      PieceStart& start) {
    start = LinearPieceStart(tau0, tau1, length);
    return FinishLinearPieceStart(
        start, start.depth < kSmallDepth ? OpacityOfSmallDepth(start.depth) : 0.0, q);
}

/// The end of IntegrateLinearPiece from the moments m.
[[gnu::always_inline]] inline void FinishLinearPiece(const PieceStart& start,
                                                     const double m[3],
                                                     LinearPieceIntegrals& q) {
    q.mean = std::clamp(m[0], 0.0, 1.0);
    q.firstMoment = std::clamp(m[1], 0.0, q.mean);
    // P = integral x (alpha + 2 beta x) T dx; by parts P = I0 - T(1), which cancels only
    // for small depth, where the moment form is used.
    const double far = std::isnan(m[2]) ? q.mean - q.transmittance
                                        : start.alpha * m[1] + 2 * start.beta * m[2];
    q.farWeight = std::clamp(far, 0.0, q.opacity);
}

/// The moments of a piece outside the Taylor regime (BeginLinearPiece false), from its
/// start and exponential.
void MomentsBeyondTaylor(const PieceStart& start, const LinearPieceIntegrals& q,
                         double m[3]) {
    const double alpha = start.alpha, beta = start.beta;
    if (std::abs(beta) <= 1 ||
        (beta <= 0.5 * alpha && std::abs(beta) <= 0.005 * alpha * alpha)) {
        SlopeSeriesMoments(alpha, beta, m);
        return;
    }
    // Complete the square. Here |beta| > 1 and either beta > alpha / 2 or |beta| >
    // alpha^2 / 200, so I1 = (1 - T(1) - alpha I0) / (2 beta) below carries an absolute
    // error of at most (1 + alpha / |beta|) <= 16 ulps of I0.
    const double s = std::sqrt(std::abs(beta));
    const double u0 = alpha / (2 * s);
    double i0;
    if (beta > 0) {
        // I0 = sqrt(pi) / (2 s) (erfcx(u0) - erfcx(u0 + s) T(1)).
        i0 = 0.88622692545275801365 / s * (erfcx(u0) - erfcx(u0 + s) * q.transmittance);
    } else {
        // u1 = u0 - s >= 0 since alpha >= 2 |beta|; I0 = (F(u0) - F(u1) T(1)) / s.
        const double u1 = std::max(0.0, u0 - s);
        i0 = (dawson(u0) - dawson(u1) * q.transmittance) / s;
    }
    m[0] = i0;
    m[1] = (q.opacity - alpha * i0) / (2 * beta);
    m[2] = std::numeric_limits<double>::quiet_NaN();
}

#if defined(HPRAY_LANES)
/// TaylorMoments of N pieces at once (lanes.h), bitwise TaylorMoments per lane: every
/// lane runs the same operations, and a lane whose series has ended takes no more terms.
template <int N>
[[gnu::always_inline]] inline void TaylorMomentsLanes(const double* alpha,
                                                      const double* beta, double m[][3]) {
    using lanes::D;
    using lanes::Splat;
    const D<N> negAlpha = Splat<N>(0.0) - lanes::Load<N>(alpha);
    const D<N> negTwoBeta = Splat<N>(-2) * lanes::Load<N>(beta);
    const D<N> small = Splat<N>(1e-17);
    D<N> cPrev = Splat<N>(0), c = Splat<N>(1);
    D<N> m0 = Splat<N>(0), m1 = m0, m2 = m0;
    lanes::I<N> live = lanes::SplatI<N>(-1);
    for (int n = 0; n < kMaxTaylorTerms; ++n) {
        const D<N> r1 = Splat<N>(kReciprocal[n + 1]);
        const D<N> r2 = Splat<N>(kReciprocal[n + 2]);
        const D<N> r3 = Splat<N>(kReciprocal[n + 3]);
        m0 = lanes::Select(live, m0 + c * r1, m0);
        m1 = lanes::Select(live, m1 + c * r2, m1);
        m2 = lanes::Select(live, m2 + c * r3, m2);
        const D<N> a = negAlpha * r1;
        const D<N> b = negTwoBeta * r1;
        const D<N> next = lanes::Fma(a, c, b * cPrev);
        cPrev = c;
        c = next;
        const D<N> rest = lanes::Abs<N>(c) + lanes::Abs<N>(cPrev);
        live = ~(rest <= small) & live;
        if (lanes::Bits(live) == 0) break;
    }
    for (int l = 0; l < N; ++l) {
        m[l][0] = m0[l];
        m[l][1] = m1[l];
        m[l][2] = m2[l];
    }
}

/// OpacityOfSmallDepth of N depths at once, each lane the scalar function's operations.
template <int N>
[[gnu::always_inline]] inline void OpacityOfSmallDepthLanes(const double* d,
                                                            double* out) {
    using lanes::D;
    using lanes::Splat;
    const D<N> dv = lanes::Load<N>(d);
    const D<N> x = -dv;
    D<N> p = Splat<N>(kInverseFactorial[17]);
    for (int k = 15; k >= 0; --k)
        p = lanes::Fma(p, x, Splat<N>(kInverseFactorial[k + 1]));
    const D<N> r = dv * p;
    std::memcpy(out, &r, sizeof r);
}

void TaylorMoments4(const double alpha[4], const double beta[4], double m[4][3]) {
    TaylorMomentsLanes<4>(alpha, beta, m);
}
HPRAY_TARGET_AVX512 void TaylorMoments8(const double alpha[8], const double beta[8],
                                        double m[8][3]) {
    TaylorMomentsLanes<8>(alpha, beta, m);
}
#else
void TaylorMoments4(const double alpha[4], const double beta[4], double m[4][3]) {
    for (int l = 0; l < 4; ++l) TaylorMoments(alpha[l], beta[l], m[l]);
}
void TaylorMoments8(const double alpha[8], const double beta[8], double m[8][3]) {
    for (int l = 0; l < 8; ++l) TaylorMoments(alpha[l], beta[l], m[l]);
}
#endif

}  // namespace

/// IntegrateLinearPieces on the inputs of piece i that in(i, tau0, tau1, length) gives.
template <typename Inputs>
[[gnu::always_inline]] inline void IntegrateLinearPiecesOf(int n, Inputs in,
                                                           LinearPieceIntegrals* out,
                                                           bool wideLanes) {
    // Pieces in the Taylor regime wait for a batch of four, or of eight where the
    // processor has AVX-512.
    const int batch = wideLanes && CpuHasAvx512() ? 8 : 4;
    int lane[8], lanes = 0;
    alignas(64) double alpha[8], beta[8];
    double m[8][3];
    PieceStart start[8];
    auto runLanes = [&] {
        for (int l = lanes; l < 8; ++l) alpha[l] = beta[l] = 0;
        if (lanes > 4)
            TaylorMoments8(alpha, beta, m);
        else
            TaylorMoments4(alpha, beta, m);
        for (int l = 0; l < lanes; ++l) FinishLinearPiece(start[l], m[l], out[lane[l]]);
        lanes = 0;
    };
    // The pieces in chunks: their starts, then the opacities of those of small depth
    // in vector lanes (OpacityOfSmallDepth lane by lane), then each piece in order.
    constexpr int kChunk = 16;
    for (int i0 = 0; i0 < n; i0 += kChunk) {
        const int count = std::min(kChunk, n - i0);
        PieceStart starts[kChunk];
        alignas(32) double depth[kChunk], opacity[kChunk];
        for (int k = 0; k < count; ++k) {
            double tau0, tau1, length;
            in(i0 + k, tau0, tau1, length);
            starts[k] = LinearPieceStart(tau0, tau1, length);
            depth[k] = starts[k].depth < kSmallDepth ? starts[k].depth : 0.0;
        }
#if defined(HPRAY_LANES)
        for (int k = count; k < (count + 3) / 4 * 4; ++k) depth[k] = 0;
        for (int k = 0; k < count; k += 4)
            OpacityOfSmallDepthLanes<4>(depth + k, opacity + k);
#else
        for (int k = 0; k < count; ++k) opacity[k] = OpacityOfSmallDepth(depth[k]);
#endif
        for (int k = 0; k < count; ++k) {
            const int i = i0 + k;
            LinearPieceIntegrals& q = out[i];
            q = LinearPieceIntegrals{};
            const PieceStart& ps = starts[k];
            if (FinishLinearPieceStart(ps, opacity[k], q)) {
                lane[lanes] = i;
                start[lanes] = ps;
                alpha[lanes] = ps.alpha;
                beta[lanes] = ps.beta;
                if (++lanes == batch) runLanes();
            } else {
                double mm[3];
                MomentsBeyondTaylor(ps, q, mm);
                FinishLinearPiece(ps, mm, q);
            }
        }
    }
    if (lanes == 1) {
        double mm[3];
        TaylorMoments(start[0].alpha, start[0].beta, mm);
        FinishLinearPiece(start[0], mm, out[lane[0]]);
    } else if (lanes > 1) {
        runLanes();
    }
}

void IntegrateLinearPieces(int n, const double* tau0, const double* tau1,
                           const double* length, LinearPieceIntegrals* out,
                           bool wideLanes) {
    IntegrateLinearPiecesOf(
        n,
        [&](int i, double& a, double& b, double& l) {
            a = tau0[i];
            b = tau1[i];
            l = length[i];
        },
        out, wideLanes);
}

void IntegrateLinearPieces(int n, const unsigned char* base, std::size_t stride,
                           std::size_t tau0At, std::size_t tau1At, std::size_t lengthAt,
                           LinearPieceIntegrals* out, bool wideLanes) {
    IntegrateLinearPiecesOf(
        n,
        [&](int i, double& a, double& b, double& l) {
            const unsigned char* piece = base + std::size_t(i) * stride;
            std::memcpy(&a, piece + tau0At, sizeof a);
            std::memcpy(&b, piece + tau1At, sizeof b);
            std::memcpy(&l, piece + lengthAt, sizeof l);
        },
        out, wideLanes);
}

LinearPieceIntegrals IntegrateLinearPiece(double tau0, double tau1, double length) {
    LinearPieceIntegrals q;
    PieceStart start;
    double m[3];
    if (BeginLinearPiece(tau0, tau1, length, q, start)) {
        TaylorMoments(start.alpha, start.beta, m);
    } else {
        MomentsBeyondTaylor(start, q, m);
    }
    FinishLinearPiece(start, m, q);
    return q;
}

const KronrodRule& GetKronrodRule() {
    static const KronrodRule rule = [] {
        KronrodRule r;
        constexpr int n = KronrodRule::kNodes, half = n / 2;
        using GK = boost::math::quadrature::gauss_kronrod<double, 15>;
        using G = boost::math::quadrature::gauss<double, 7>;
        const auto& x = GK::abscissa();  // 0, then positive nodes ascending
        const auto& wk = GK::weights();
        const auto& wg = G::weights();  // for the even-indexed Kronrod abscissae
        for (int i = 0; i <= half; ++i) {
            r.nodes[half + i] = x[i];
            r.nodes[half - i] = -x[i];
            r.kronrodWeights[half + i] = r.kronrodWeights[half - i] = wk[i];
            const double g = i % 2 == 0 ? wg[i / 2] : 0.0;
            r.gaussWeights[half + i] = r.gaussWeights[half - i] = g;
        }
        // Cumulative integration of the interpolant: with V[j][k] = P_k(x_j) and
        // Q[i][k] = integral_{-1}^{x_i} P_k, cumulative = Q V^-1 (long double).
        using LD = long double;
        LD V[n][n], Q[n][n], inv[n][n];
        for (int j = 0; j < n; ++j) {
            LD p[n + 1];
            const LD xj = r.nodes[j];
            p[0] = 1;
            p[1] = xj;
            for (int k = 1; k < n; ++k)
                p[k + 1] = ((2 * k + 1) * xj * p[k] - k * p[k - 1]) / (k + 1);
            for (int k = 0; k < n; ++k) V[j][k] = p[k];
            Q[j][0] = xj + 1;
            for (int k = 1; k < n; ++k) Q[j][k] = (p[k + 1] - p[k - 1]) / (2 * k + 1);
        }
        // Gauss-Jordan with partial pivoting.
        LD a[n][2 * n];
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < 2 * n; ++j)
                a[i][j] = j < n ? V[i][j] : (j - n == i ? 1 : 0);
        for (int c = 0; c < n; ++c) {
            int pivot = c;
            for (int i = c + 1; i < n; ++i)
                if (std::abs(a[i][c]) > std::abs(a[pivot][c])) pivot = i;
            for (int j = 0; j < 2 * n; ++j) std::swap(a[c][j], a[pivot][j]);
            const LD d = a[c][c];
            HPRAY_CHECK(d != 0);
            for (int j = 0; j < 2 * n; ++j) a[c][j] /= d;
            for (int i = 0; i < n; ++i) {
                if (i == c) continue;
                const LD f = a[i][c];
                for (int j = 0; j < 2 * n; ++j) a[i][j] -= f * a[c][j];
            }
        }
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) inv[i][j] = a[i][n + j];
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) {
                LD s = 0;
                for (int k = 0; k < n; ++k) s += Q[i][k] * inv[k][j];
                r.cumulative[i][j] = static_cast<double>(s);
            }
        return r;
    }();
    return rule;
}

namespace {

using LD = long double;

/// Solves a x = b (n x n, row-major) through a's inverse.
std::vector<LD> SolveDense(int n, std::vector<LD> a, const std::vector<LD>& b) {
    const std::vector<LD> inv = InvertDense(n, std::move(a));
    std::vector<LD> x(n, 0);
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) x[i] += inv[std::size_t(i) * n + j] * b[j];
    return x;
}

/// Patterson's extension of the symmetric rule with the m nodes `x` (m odd, holding 0):
/// the m + 1 roots of the polynomial pi of degree m + 1 with integral_{-1}^1 w pi P_k = 0
/// for k <= m, w = prod (x - x_i), appended to `x`. pi is even, P_{m+1} plus even
/// Legendre polynomials of lower degree; the conditions for odd k determine it. The
/// integrals are exact by 30-point Gauss-Legendre (degree 59 >= 3m + 1 for m <= 15).
void PattersonExtension(std::vector<LD>& x) {
    const int m = static_cast<int>(x.size()), deg = m + 1, half = deg / 2;
    HPRAY_CHECK(m % 2 == 1 && 3 * m + 1 <= 59);
    using G = boost::math::quadrature::gauss<LD, 30>;
    std::vector<LD> gx, gw;
    for (std::size_t i = 0; i < G::abscissa().size(); ++i) {
        const LD a = G::abscissa()[i], w = G::weights()[i];
        gx.push_back(a);
        gw.push_back(w);
        if (a != 0) {
            gx.push_back(-a);
            gw.push_back(w);
        }
    }
    auto omega = [&](LD t) {
        LD w = 1;
        for (LD xi : x) w *= t - xi;
        return w;
    };
    // Unknowns c_j for the even degrees 2j < deg; condition rows for odd k = 2r + 1 <= m.
    std::vector<LD> a(std::size_t(half) * half, 0), b(half, 0);
    std::vector<LD> p(deg + 1);
    for (std::size_t g = 0; g < gx.size(); ++g) {
        LegendreValuesLong(gx[g], deg, p.data());
        const LD wo = gw[g] * omega(gx[g]);
        for (int r = 0; r < half; ++r) {
            const LD pk = p[2 * r + 1] * wo;
            for (int j = 0; j < half; ++j) a[std::size_t(r) * half + j] += pk * p[2 * j];
            b[r] -= pk * p[deg];
        }
    }
    const std::vector<LD> c = SolveDense(half, a, b);
    auto pi = [&](LD t) {
        LegendreValuesLong(t, deg, p.data());
        LD v = p[deg];
        for (int j = 0; j < half; ++j) v += c[j] * p[2 * j];
        return v;
    };
    // Its positive roots: sign changes on a fine grid, then bisection to the last bit.
    constexpr int kGrid = 1 << 12;
    int found = 0;
    LD lo = 0, vlo = pi(lo);
    for (int i = 1; i <= kGrid; ++i) {
        const LD hi = LD(i) / kGrid, vhi = pi(hi);
        if ((vlo < 0) != (vhi < 0)) {
            LD l = lo, h = hi, fl = vlo;
            for (int it = 0; it < 200 && l < h; ++it) {
                const LD mid = (l + h) / 2;
                if (mid <= l || mid >= h) break;
                const LD fm = pi(mid);
                if ((fm < 0) == (fl < 0)) {
                    l = mid;
                    fl = fm;
                } else {
                    h = mid;
                }
            }
            const LD root = (l + h) / 2;
            x.push_back(root);
            x.push_back(-root);
            ++found;
        }
        lo = hi;
        vlo = vhi;
    }
    HPRAY_CHECK(found == half);
}

/// The weights of the interpolatory rule on the nodes x: sum_i w_i P_k(x_i) = 2 [k = 0]
/// for k < size.
std::vector<LD> InterpolatoryWeights(const std::vector<LD>& x) {
    const int n = static_cast<int>(x.size());
    std::vector<LD> a(std::size_t(n) * n), b(n, 0), p(n);
    for (int i = 0; i < n; ++i) {
        LegendreValuesLong(x[i], n - 1, p.data());
        for (int k = 0; k < n; ++k) a[std::size_t(k) * n + i] = p[k];
    }
    b[0] = 2;
    return SolveDense(n, a, b);
}

NestedQuadratureRules MakeNestedQuadratureRules() {
    using R = NestedQuadratureRules;
    R r;
    // The midpoint, Gauss 3 and Kronrod 7 from Boost's tables (the Gauss 3 nodes are
    // among the Kronrod nodes), then Patterson's extensions.
    using GK7 = boost::math::quadrature::gauss_kronrod<LD, 7>;
    using G3 = boost::math::quadrature::gauss<LD, 3>;
    const auto& kx = GK7::abscissa();  // 0, then the positive nodes ascending
    const auto& kw = GK7::weights();
    const auto& gx = G3::abscissa();
    const auto& gw = G3::weights();
    HPRAY_CHECK(kx.size() == 4 && gx.size() == 2 && std::abs(kx[2] - gx[1]) < 1e-18L);
    std::vector<LD> x = {0, kx[2], -kx[2], kx[1], -kx[1], kx[3], -kx[3]};
    std::vector<std::vector<LD>> w(R::kRules);
    w[0] = {2};
    w[1] = {gw[0], gw[1], gw[1]};
    w[2] = {kw[0], kw[2], kw[2], kw[1], kw[1], kw[3], kw[3]};
    for (int rule = 3; rule < R::kRules; ++rule) {
        PattersonExtension(x);
        HPRAY_CHECK(int(x.size()) == R::Size(rule));
        w[rule] = InterpolatoryWeights(x);
    }
    for (int i = 0; i < R::kMaxNodes; ++i) r.nodes[i] = double(x[i]);
    for (int rule = 0; rule < R::kRules; ++rule)
        for (int i = 0; i < R::Size(rule); ++i) {
            HPRAY_CHECK(w[rule][i] > 0);
            r.weights[rule][i] = double(w[rule][i]);
        }
    return r;
}

}  // namespace

const NestedQuadratureRules& GetNestedQuadratureRules() {
    static const NestedQuadratureRules rules = MakeNestedQuadratureRules();
    return rules;
}

}  // namespace hpray
