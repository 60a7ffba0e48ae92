// Vectors of N doubles (and of N 64-bit integers) for kernels written once for several
// vector widths: N = 4 (AVX2, 256 bits) and N = 8 (AVX-512, 512 bits), as GCC's vector
// extensions (operators act lane by lane, comparisons give -1 / 0 lanes, `mask ? a : b`
// selects lane by lane). The project builds with -ffp-contract=off, so a * b + c stays a
// product and a sum in every width: a lane computes bitwise what the scalar expression
// computes, whatever N.
//
// An N = 8 kernel must be compiled for AVX-512: put it in a function with
// HPRAY_TARGET_AVX512 and call it only where CpuHasAvx512(); the helpers here are
// inlined into it (their callers' target). The kernels exist where the build has AVX2 and
// FMA (HPRAY_LANES defined); elsewhere their callers take the scalar paths.
#pragma once

#include <cstdint>
#include <cstring>

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif

// Vectors wider than the build's target ABI (64-byte vectors in a build without AVX-512)
// are only ever passed between inlined functions: GCC's note that their ABI differs does
// not apply.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wpsabi"
#endif

#define HPRAY_TARGET_AVX512 __attribute__((target("avx512f")))

namespace hpray {

/// Whether the processor runs AVX-512F (asked once; false under tools that emulate a
/// processor without it, such as valgrind).
bool CpuHasAvx512();

template <int N>
struct Lanes;
template <>
struct Lanes<4> {
    typedef double D __attribute__((vector_size(32)));
    typedef std::int64_t I __attribute__((vector_size(32)));
};
template <>
struct Lanes<8> {
    typedef double D __attribute__((vector_size(64)));
    typedef std::int64_t I __attribute__((vector_size(64)));
};

namespace lanes {

template <int N>
using D = typename Lanes<N>::D;
template <int N>
using I = typename Lanes<N>::I;

// Splat: x in every lane (a shuffle of lane 0: the compiler makes poor code of eight
// equal scalars). SplatI: the same with the bits of an integer.
template <int N>
[[gnu::always_inline]] inline D<N> Splat(double x) {
    const D<N> v = {x};
    if constexpr (N == 4)
        return __builtin_shufflevector(v, v, 0, 0, 0, 0);
    else
        return __builtin_shufflevector(v, v, 0, 0, 0, 0, 0, 0, 0, 0);
}
template <int N>
[[gnu::always_inline]] inline I<N> SplatI(std::int64_t x) {
    double bits;
    std::memcpy(&bits, &x, sizeof bits);
    return reinterpret_cast<I<N>>(Splat<N>(bits));
}
template <int N>
[[gnu::always_inline]] inline D<N> Load(const double* p) {
    D<N> v;
    std::memcpy(&v, p, sizeof v);
    return v;
}
/// |a| lane by lane (the sign bit cleared, as std::abs).
template <int N>
[[gnu::always_inline]] inline D<N> Abs(D<N> a) {
    return (D<N>)((I<N>)a & SplatI<N>(0x7fffffffffffffff));
}
[[gnu::always_inline]] inline I<4> Low(I<8> a) {
    return __builtin_shufflevector(a, a, 0, 1, 2, 3);
}
[[gnu::always_inline]] inline I<4> High(I<8> a) {
    return __builtin_shufflevector(a, a, 4, 5, 6, 7);
}

// Bits: bit j set where lane j of the mask is true (not 0). Select: a blend. Fma: a * b +
// c rounded once, lane by lane (std::fma's value). By AVX2 intrinsics, eight lanes as two
// halves: a function not itself compiled for AVX-512 (these helpers, the templates that
// call them) cannot call AVX-512 intrinsics, and inlined into an AVX-512 function these
// become its vector instructions.
#if defined(__AVX2__) && defined(__FMA__)
[[gnu::always_inline]] inline unsigned Bits(I<4> m) {
    return unsigned(_mm256_movemask_pd(reinterpret_cast<__m256d>(m)));
}
[[gnu::always_inline]] inline unsigned Bits(I<8> m) {
    return Bits(Low(m)) | Bits(High(m)) << 4;
}
/// Lane by lane where m (all ones or all zeros) is true a, else b.
[[gnu::always_inline]] inline D<4> Select(I<4> m, D<4> a, D<4> b) {
    return reinterpret_cast<D<4>>(_mm256_blendv_pd(reinterpret_cast<__m256d>(b),
                                                   reinterpret_cast<__m256d>(a),
                                                   reinterpret_cast<__m256d>(m)));
}
[[gnu::always_inline]] inline D<8> Select(I<8> m, D<8> a, D<8> b) { return m ? a : b; }
[[gnu::always_inline]] inline D<4> Fma(D<4> a, D<4> b, D<4> c) {
    return reinterpret_cast<D<4>>(_mm256_fmadd_pd(reinterpret_cast<__m256d>(a),
                                                  reinterpret_cast<__m256d>(b),
                                                  reinterpret_cast<__m256d>(c)));
}
[[gnu::always_inline]] inline D<8> Fma(D<8> a, D<8> b, D<8> c) {
    D<8> r;
    for (int j = 0; j < 8; ++j) r[j] = __builtin_fma(a[j], b[j], c[j]);
    return r;
}
#define HPRAY_LANES 1
#endif

}  // namespace lanes
}  // namespace hpray
