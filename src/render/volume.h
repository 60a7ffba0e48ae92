// The optical model of volume rendering (docs/contracts.md, Volume): piecewise-linear
// transfer functions, the closed-form integrals of a ray piece whose extinction is linear
// in t, and the Gauss-Kronrod rule with its cumulative (spectral) integration matrix for
// pieces where it is not.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "util/check.h"

#if defined(__AVX2__)
#include <immintrin.h>
#endif

namespace hpray {

/// At most kMax ascending values, padded with NaN (which no comparison counts): how many
/// are <= s, or < s, by a fixed number of comparisons (two vectors of four where the
/// build has them) instead of a loop whose branches go either way from call to call.
struct ShortAscending {
    static constexpr int kMax = 8;
    bool valid = false;  ///< the list had at most kMax values
    alignas(32) std::array<double, kMax> v{};
    /// From an ascending list (valid only when it has at most kMax values).
    void Set(const std::vector<double>& ascending) {
        valid = ascending.size() <= std::size_t(kMax);
        v.fill(std::numeric_limits<double>::quiet_NaN());
        if (valid) std::copy(ascending.begin(), ascending.end(), v.begin());
    }
    int CountAtMost(double s) const { return Count<true>(s); }
    int CountBelow(double s) const { return Count<false>(s); }
#if defined(__AVX2__)
    /// CountAtMost of four values at once, as 64-bit lanes.
    __m256i CountAtMost4(__m256d s) const { return Count4<_CMP_LE_OQ>(s); }
#endif

  private:
    template <bool kOrEqual>
    int Count(double s) const {
#if defined(__AVX2__)
        static_assert(kMax == 8);
        constexpr int kCompare = kOrEqual ? _CMP_LE_OQ : _CMP_LT_OQ;
        const __m256d x = _mm256_set1_pd(s);
        const __m256d lo = _mm256_cmp_pd(_mm256_loadu_pd(v.data()), x, kCompare);
        const __m256d hi = _mm256_cmp_pd(_mm256_loadu_pd(v.data() + 4), x, kCompare);
        return __builtin_popcount(unsigned(_mm256_movemask_pd(lo)) |
                                  unsigned(_mm256_movemask_pd(hi)) << 4);
#else
        int k = 0;
        for (int i = 0; i < kMax; ++i) k += kOrEqual ? v[i] <= s : v[i] < s;
        return k;
#endif
    }
#if defined(__AVX2__)
    template <int kCompare>
    __m256i Count4(__m256d s) const {
        // A true comparison is all ones, -1 as an integer: subtracting it counts one.
        __m256i count = _mm256_setzero_si256();
        for (int i = 0; i < kMax; ++i)
            count = _mm256_sub_epi64(count, _mm256_castpd_si256(_mm256_cmp_pd(
                                                _mm256_set1_pd(v[i]), s, kCompare)));
        return count;
    }
#endif
};

/// A piecewise-linear function of one scalar with `channels` outputs (1: extinction,
/// 3: colour), clamped to its first and last control values outside its control points.
class PiecewiseLinearTf {
  public:
    PiecewiseLinearTf() = default;
    /// `scalars` strictly increasing (>= 1 point); `values` holds channels values per
    /// point.
    PiecewiseLinearTf(std::vector<double> scalars, std::vector<double> values,
                      int channels);

    int Channels() const { return channels_; }
    int Size() const { return size_; }
    const std::vector<double>& Scalars() const { return scalars_; }
    /// Scalars() for fixed-length counts (valid for at most ShortAscending::kMax points).
    const ShortAscending& ShortScalars() const { return short_; }

    /// The linear piece holding s: -1 left of the first control point, Size() - 1 at or
    /// right of the last, else k with scalars[k] <= s < scalars[k + 1]. NaN maps to -1.
    int IntervalOf(double s) const;
    /// The affine function of piece k (constant on the clamped pieces -1 and Size() - 1)
    /// at s, which may lie outside piece k (the piece's function extended): `out` gets
    /// Channels() values.
    void EvalOn(int k, double s, double* out) const;
    void Eval(double s, double* out) const { EvalOn(IntervalOf(s), s, out); }
    /// EvalOn of a function of 3 channels (colours) into registers: bitwise EvalOn.
    void EvalOn3(int k, double s, double& r, double& g, double& b) const;
    /// EvalOn of a function of 1 channel: bitwise EvalOn.
    double EvalOn1(int k, double s) const;
#if defined(__AVX2__)
    /// Four lanes at once, each bitwise the scalar function: IntervalOf (ShortScalars()
    /// valid only) as 64-bit lanes; EvalOn3 (3 channels only) and EvalOn1 (1 channel
    /// only) of the lanes' pieces k at two values sA and sB each; SteepestOn.
    __m256i IntervalOf4(__m256d s) const {
        return _mm256_sub_epi64(short_.CountAtMost4(s), _mm256_set1_epi64x(1));
    }
    void EvalOn3x4(__m256i k, __m256d sA, __m256d sB, __m256d outA[3],
                   __m256d outB[3]) const {
        EvalOnX4<3>(k, sA, sB, outA, outB);
    }
    void EvalOn1x4(__m256i k, __m256d sA, __m256d sB, __m256d& outA,
                   __m256d& outB) const {
        EvalOnX4<1>(k, sA, sB, &outA, &outB);
    }
    __m256d SteepestOn4(__m256i k) const {
        // steepest_[k + 1]: the table's entry for inner pieces, 0 on the clamped pieces
        // (their entries, 0 too; see the constructor).
        const __m256i clamped =
            _mm256_or_si256(_mm256_cmpgt_epi64(_mm256_setzero_si256(), k),
                            _mm256_cmpgt_epi64(k, _mm256_set1_epi64x(Size() - 2)));
        const LaneIndex at(
            _mm256_add_epi64(_mm256_andnot_si256(clamped, k), _mm256_set1_epi64x(1)));
        return _mm256_andnot_pd(_mm256_castsi256_pd(clamped),
                                at.Of(laneSteepest_.data()));
    }
#endif
    /// Piece k as an affine function, value = offset + slope * s (slope 0 on the clamped
    /// pieces): `offset`, `slope` get Channels() values.
    void AffineOn(int k, double* offset, double* slope) const;
    /// AffineOn for a function of 3 channels (colour) and of 1 (extinction), written out:
    /// the general loop of unknown length compiles to two calls of memmove.
    void AffineOn3(int k, double offset[3], double slope[3]) const;
    void AffineOn1(int k, double& offset, double& slope) const;
    /// max over channels of |slope| of piece k (AffineOn's), tabulated.
    double SteepestOn(int k) const { return steepest_[k + 1]; }
    /// max of SteepestOn over the pieces that hold some s in [lo, hi].
    double SteepestOver(double lo, double hi) const {
        double m = 0;
        for (int k = IntervalOf(lo), e = IntervalOf(hi); k <= e; ++k)
            m = std::max(m, SteepestOn(k));
        return m;
    }

    /// Over all s in [lo, hi]: the minimum and maximum of each channel (exact: at the
    /// ends or at control points inside). `minOut`, `maxOut` get Channels() values.
    void RangeOver(double lo, double hi, double* minOut, double* maxOut) const;
    /// The largest value of any channel over all s.
    double MaxValue() const;
    /// The largest |d value / d s| of any channel (0 for a single control point).
    double MaxSlope() const;

  private:
#if defined(__AVX2__)
    template <int C>
    void EvalOnX4(__m256i k, __m256d sA, __m256d sB, __m256d* outA, __m256d* outB) const;
    /// Entries 0..7 of a table of 8 doubles for four 64-bit lane indices, by two
    /// in-register permutes and a blend instead of a gather (whose latency the four-lane
    /// lookups waited for).
    struct LaneIndex {
        explicit LaneIndex(__m256i k) {
            // The 32-bit halves 2k, 2k + 1 of each entry (the permute reads the low 3
            // bits: entries 4..7 come from the second half of the table).
            const __m256i twice = _mm256_slli_epi64(k, 1);
            idx = _mm256_or_si256(
                twice,
                _mm256_slli_epi64(_mm256_add_epi64(twice, _mm256_set1_epi64x(1)), 32));
            high = _mm256_castsi256_pd(_mm256_cmpgt_epi64(k, _mm256_set1_epi64x(3)));
        }
        __m256d Of(const double* table) const {
            const __m256i lo = _mm256_load_si256(reinterpret_cast<const __m256i*>(table));
            const __m256i hi =
                _mm256_load_si256(reinterpret_cast<const __m256i*>(table + 4));
            return _mm256_blendv_pd(
                _mm256_castsi256_pd(_mm256_permutevar8x32_epi32(lo, idx)),
                _mm256_castsi256_pd(_mm256_permutevar8x32_epi32(hi, idx)), high);
        }
        __m256i idx;
        __m256d high;
    };
#endif
    /// For the lane lookups (ShortScalars() valid: at most 8 control points): the
    /// control points, each channel's values and SteepestOn(k - 1) at k, padded to 8.
    alignas(32) std::array<double, 8> laneScalars_{};
    alignas(32) std::array<std::array<double, 8>, 3> laneValues_{};
    alignas(32) std::array<double, 8> laneSteepest_{};
    std::vector<double> scalars_;
    std::vector<double> values_;
    int channels_ = 1;
    std::vector<double> steepest_;  ///< SteepestOn(k) at k + 1
    /// AffineOn(k)'s offsets and slopes, Channels() each, at (k + 1) * Channels():
    /// computed once (a division per channel and piece) instead of on every call.
    std::vector<double> affineOffset_, affineSlope_;
    /// Where piece k's entries start in affineOffset_ and affineSlope_ (k clamped to the
    /// pieces, -1 the one below the first control point).
    std::size_t AffineAt(int k) const {
        return std::size_t(std::clamp(k, -1, Size() - 1) + 1) * channels_;
    }
    /// AffineOn computed from the control points (the tables' source).
    void ComputeAffineOn(int k, double* offset, double* slope) const;
    ShortAscending short_;          ///< the control points, for IntervalOf
    int size_ = 0;                  ///< scalars_.size(), read per ray piece
};

// Called per ray piece: inline.
inline int PiecewiseLinearTf::IntervalOf(double s) const {
    // Short functions: the number of control points <= s, without branches (a search's
    // branches go either way from piece to piece along a ray). The same result: -1 below
    // the first point and for NaN, Size() - 1 from the last on.
    if (short_.valid) return short_.CountAtMost(s) - 1;
    if (scalars_.size() <= 16) {
        int k = -1;
        for (const double x : scalars_) k += x <= s;
        return k;
    }
    if (!(s >= scalars_.front())) return -1;
    if (s >= scalars_.back()) return Size() - 1;
    // First control point > s, minus one.
    const auto it = std::upper_bound(scalars_.begin(), scalars_.end(), s);
    return static_cast<int>(it - scalars_.begin()) - 1;
}

inline void PiecewiseLinearTf::EvalOn(int k, double s, double* out) const {
    const int n = Size();
    if (k < 0 || k >= n - 1) {
        const double* v = values_.data() + (k < 0 ? 0 : std::size_t(n - 1) * channels_);
        for (int c = 0; c < channels_; ++c) out[c] = v[c];
        return;
    }
    // (1 - w) v_k + w v_{k+1} reproduces both control values exactly at w = 0 and w = 1.
    const double w = (s - scalars_[k]) / (scalars_[k + 1] - scalars_[k]);
    const double* v0 = values_.data() + std::size_t(k) * channels_;
    const double* v1 = v0 + channels_;
    for (int c = 0; c < channels_; ++c) out[c] = (1 - w) * v0[c] + w * v1[c];
}

inline void PiecewiseLinearTf::EvalOn3(int k, double s, double& r, double& g,
                                       double& b) const {
    const int n = Size();
    if (k < 0 || k >= n - 1) {
        const double* v = values_.data() + (k < 0 ? 0 : std::size_t(n - 1) * 3);
        r = v[0];
        g = v[1];
        b = v[2];
        return;
    }
    const double w = (s - scalars_[k]) / (scalars_[k + 1] - scalars_[k]);
    const double* v0 = values_.data() + std::size_t(k) * 3;
    r = (1 - w) * v0[0] + w * v0[3];
    g = (1 - w) * v0[1] + w * v0[4];
    b = (1 - w) * v0[2] + w * v0[5];
}

#if defined(__AVX2__)
template <int C>
inline void PiecewiseLinearTf::EvalOnX4(__m256i k, __m256d sA, __m256d sB, __m256d* outA,
                                        __m256d* outB) const {
    const int n = Size();
    const __m256i below = _mm256_cmpgt_epi64(_mm256_setzero_si256(), k);     // k < 0
    const __m256i above = _mm256_cmpgt_epi64(k, _mm256_set1_epi64x(n - 2));  // k >= n - 1
    // The clamped pieces' constants: the first or the last control values.
    const double* last = values_.data() + std::size_t(n - 1) * C;
    __m256d fixed[C];
    for (int c = 0; c < C; ++c)
        fixed[c] = _mm256_blendv_pd(_mm256_set1_pd(values_[c]), _mm256_set1_pd(last[c]),
                                    _mm256_castsi256_pd(above));
    if (n < 2) {
        for (int c = 0; c < C; ++c) outA[c] = outB[c] = fixed[c];
        return;
    }
    // Inner pieces: as EvalOn, (1 - w) v_k + w v_{k+1}, w = (s - s_k) / (s_{k+1} - s_k)
    // (lanes of clamped pieces read piece 0 and take the constants instead).
    const __m256i clampedLanes = _mm256_or_si256(below, above);
    const __m256i inner = _mm256_andnot_si256(clampedLanes, k);
    const __m256d clamped = _mm256_castsi256_pd(clampedLanes);
    // The tables' entries inner and inner + 1 (lane lookups; see LaneIndex).
    const LaneIndex at0(inner), at1(_mm256_add_epi64(inner, _mm256_set1_epi64x(1)));
    const __m256d s0 = at0.Of(laneScalars_.data());
    const __m256d s1 = at1.Of(laneScalars_.data());
    const __m256d width = _mm256_sub_pd(s1, s0);
    const __m256d one = _mm256_set1_pd(1.0);
    const __m256d wA = _mm256_div_pd(_mm256_sub_pd(sA, s0), width);
    const __m256d wB = _mm256_div_pd(_mm256_sub_pd(sB, s0), width);
    const __m256d oneMinusWA = _mm256_sub_pd(one, wA),
                  oneMinusWB = _mm256_sub_pd(one, wB);
    for (int c = 0; c < C; ++c) {
        const __m256d v0 = at0.Of(laneValues_[c].data());
        const __m256d v1 = at1.Of(laneValues_[c].data());
        outA[c] = _mm256_blendv_pd(
            _mm256_add_pd(_mm256_mul_pd(oneMinusWA, v0), _mm256_mul_pd(wA, v1)), fixed[c],
            clamped);
        outB[c] = _mm256_blendv_pd(
            _mm256_add_pd(_mm256_mul_pd(oneMinusWB, v0), _mm256_mul_pd(wB, v1)), fixed[c],
            clamped);
    }
}
#endif

inline double PiecewiseLinearTf::EvalOn1(int k, double s) const {
    const int n = Size();
    if (k < 0 || k >= n - 1) return values_[k < 0 ? 0 : std::size_t(n - 1)];
    const double w = (s - scalars_[k]) / (scalars_[k + 1] - scalars_[k]);
    return (1 - w) * values_[std::size_t(k)] + w * values_[std::size_t(k) + 1];
}

inline void PiecewiseLinearTf::AffineOn(int k, double* offset, double* slope) const {
    const std::size_t at = AffineAt(k);
    for (int c = 0; c < channels_; ++c) {
        offset[c] = affineOffset_[at + c];
        slope[c] = affineSlope_[at + c];
    }
}

inline void PiecewiseLinearTf::AffineOn3(int k, double offset[3], double slope[3]) const {
    HPRAY_DCHECK(channels_ == 3);
    const std::size_t at = AffineAt(k);
    const double* o = affineOffset_.data() + at;
    const double* d = affineSlope_.data() + at;
    offset[0] = o[0], offset[1] = o[1], offset[2] = o[2];
    slope[0] = d[0], slope[1] = d[1], slope[2] = d[2];
}

inline void PiecewiseLinearTf::AffineOn1(int k, double& offset, double& slope) const {
    HPRAY_DCHECK(channels_ == 1);
    const std::size_t at = AffineAt(k);
    offset = affineOffset_[at];
    slope = affineSlope_[at];
}

/// Integrals of one ray piece of world length `length` over which the extinction is
/// linear, tau(x) = tau0 (1 - x) + tau1 x for x = (t - tStart) / length in [0, 1]. With
/// the optical depth D(x) = length * (tau0 x + (tau1 - tau0) x^2 / 2) and T(x) =
/// exp(-D(x)):
struct LinearPieceIntegrals {
    double transmittance = 1;  ///< T(1) = exp(-D(1))
    double opacity = 0;        ///< 1 - T(1), relatively accurate when small
    double mean = 1;           ///< I0 = integral_0^1 T(x) dx
    double firstMoment = 0.5;  ///< I1 = integral_0^1 x T(x) dx
    /// P = integral_0^1 x (dD/dx) T(x) dx, so that the Williams-Max emission of a linear
    /// chromaticity k(x) = k0 (1 - x) + k1 x is k0 (opacity - P) + k1 P.
    double farWeight = 0;
};

/// 1 / k! for k = 0..17: the Taylor coefficients of the exponentials of the closed forms
/// and the quadratures.
inline constexpr double kInverseFactorial[18] = {1.0,
                                                 1.0,
                                                 1.0 / 2,
                                                 1.0 / 6,
                                                 1.0 / 24,
                                                 1.0 / 120,
                                                 1.0 / 720,
                                                 1.0 / 5040,
                                                 1.0 / 40320,
                                                 1.0 / 362880,
                                                 1.0 / 3628800,
                                                 1.0 / 39916800,
                                                 1.0 / 479001600,
                                                 1.0 / 6227020800.0,
                                                 1.0 / 87178291200.0,
                                                 1.0 / 1307674368000.0,
                                                 1.0 / 20922789888000.0,
                                                 1.0 / 355687428096000.0};

/// The closed form of LinearPieceIntegrals, accurate to a few ulps relative in every
/// regime: a Taylor series for small depth (including length -> 0 and zero extinction),
/// a series in the extinction slope around the exponential for small slope (d -> 0) and
/// for large depth, and erfcx (increasing extinction) or Dawson's integral (decreasing)
/// otherwise; no overflow or underflow for any finite input. tau0, tau1 >= 0.
LinearPieceIntegrals IntegrateLinearPiece(double tau0, double tau1, double length);

/// IntegrateLinearPiece of n pieces, bitwise the same per piece: the Taylor series of
/// the small-depth regime, a recurrence whose latency bounds a piece alone, runs for
/// four pieces at once.
void IntegrateLinearPieces(int n, const double* tau0, const double* tau1,
                           const double* length, LinearPieceIntegrals* out,
                           bool wideLanes = true);
/// The same with piece i's inputs in an array of structures: the doubles at byte offsets
/// tau0At, tau1At and lengthAt of the stride bytes from base + i * stride.
void IntegrateLinearPieces(int n, const unsigned char* base, std::size_t stride,
                           std::size_t tau0At, std::size_t tau1At, std::size_t lengthAt,
                           LinearPieceIntegrals* out, bool wideLanes = true);

/// Williams-Max emission of a linear piece: integral kappa tau T for chromaticity going
/// linearly from kappa0 to kappa1 (per channel).
inline double WilliamsMaxEmission(const LinearPieceIntegrals& q, double kappa0,
                                  double kappa1) {
    return kappa0 * (q.opacity - q.farWeight) + kappa1 * q.farWeight;
}
/// Wilhelms-Van Gelder emission of a linear piece: integral g T dt for glow going
/// linearly from g0 to g1 (per world unit) over `length`.
inline double GlowEmission(const LinearPieceIntegrals& q, double g0, double g1,
                           double length) {
    return length * (g0 * (q.mean - q.firstMoment) + g1 * q.firstMoment);
}

/// The 15-point Gauss-Kronrod rule on [-1, 1] (nodes ascending) with its embedded 7-point
/// Gauss rule, and the matrix of cumulative integrals of the degree-14 interpolant:
/// cumulative[i][j] = integral_{-1}^{nodes[i]} l_j(s) ds for the Lagrange basis l_j of
/// the nodes. Built once (thread-safe).
struct KronrodRule {
    static constexpr int kNodes = 15;
    std::array<double, kNodes> nodes{};
    std::array<double, kNodes> kronrodWeights{};
    std::array<double, kNodes> gaussWeights{};  ///< 0 at the Kronrod-only nodes
    std::array<std::array<double, kNodes>, kNodes> cumulative{};
};
const KronrodRule& GetKronrodRule();

/// A ladder of nested quadrature rules on [-1, 1] for the integrals of volume pieces:
/// rule r has Size(r) = 2^(r+1) - 1 nodes, the first Size(r) of `nodes`, and extends rule
/// r - 1 (its nodes are those of r - 1 and Size(r - 1) + 1 more): the midpoint (Gauss 1),
/// Gauss 3, its Kronrod extension of 7 nodes, and Patterson's extensions of 15 and 31
/// nodes (exact for polynomials of degree 1, 5, 11, 23 and 47). Rung L of the ladder
/// integrates by rule L and estimates its error by rule L + 1, so climbing a rung
/// evaluates only the new nodes. Built once (thread-safe), in long double.
struct NestedQuadratureRules {
    static constexpr int kRules = 5;
    static constexpr int kMaxNodes = 31;
    static constexpr int Size(int r) { return (2 << r) - 1; }
    /// Degree of polynomials rule r integrates exactly.
    static constexpr int Degree(int r) {
        constexpr int kDegree[kRules] = {1, 5, 11, 23, 47};
        return kDegree[r];
    }
    std::array<double, kMaxNodes> nodes{};
    /// weights[r][i] for i < Size(r); 0 beyond.
    std::array<std::array<double, kMaxNodes>, kRules> weights{};
};
const NestedQuadratureRules& GetNestedQuadratureRules();

}  // namespace hpray
