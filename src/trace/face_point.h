// The face point of a walk's crossing of a triangular face (FacePoint, trace/
// brick_traverser.h): where the ray crosses the face, as weights of its corners, with a
// bound of how far that point may lie off the ray.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

#if defined(__AVX2__)
#include <immintrin.h>
#endif

#include "trace/brick_traverser.h"
#include "trace/ray_frame.h"

namespace hpray::trace {

// The face point of a crossing x of triangle (a, b, c) (sheared corners of the face's
// canonical representation, whose point ids are `ids`); dirKz = |ray direction| along the
// frame's z axis (|a_kz| = |z| dirKz for a corner's offset a from the ray origin).
[[gnu::always_inline]] inline void MakeFacePoint(
    const std::int32_t* ids, const ShearedPoint& a, const ShearedPoint& b,
    const ShearedPoint& c, const TriangleCrossing& x, double dirKz, FacePoint& fp) {
    constexpr double kU = 0.5 * std::numeric_limits<double>::epsilon();
    constexpr double kEps = std::numeric_limits<double>::epsilon();
    const ShearedPoint* p[3] = {&a, &b, &c};
    const double* w = x.bary;
    double err = 0;
    for (int k = 0; k < 3; ++k) {
        // The offset's rounding (|a_d| each, |a_kx| <= |x| + |a_kz| as |sx| <= 1), the
        // shear's fused multiply-add and its result's rounding.
        err = std::max(
            err, std::abs(p[k]->x) + std::abs(p[k]->y) + 2 * std::abs(p[k]->z) * dirKz);
    }
    const double cornerError = 4 * kU * err;
    // The point's distance from the ray: the first two sums (the third is t up to its
    // rounding) plus their rounding and the corners' errors.
    double dx = 0, dy = 0, ax = 0, ay = 0, az = 0;
#if defined(__AVX2__)
    // dx, dy, ax, ay in the lanes of one vector: each lane the scalar sum's operations
    // in the same order (a product, then a sum; nothing fused), so bitwise the same.
    const __m256d sign = _mm256_set1_pd(-0.0);
    __m256d acc = _mm256_setzero_pd();
    for (int m = 0; m < 3; ++m) {
        const __m128d xy = _mm_loadu_pd(&p[m]->x);
        const __m256d terms =
            _mm256_insertf128_pd(_mm256_castpd128_pd256(xy),
                                 _mm_andnot_pd(_mm256_castpd256_pd128(sign), xy), 1);
        acc = _mm256_add_pd(acc, _mm256_mul_pd(_mm256_set1_pd(w[m]), terms));
        az += w[m] * std::abs(p[m]->z);
    }
    alignas(32) double sums[4];
    _mm256_store_pd(sums, acc);
    dx = sums[0];
    dy = sums[1];
    ax = sums[2];
    ay = sums[3];
#else
    for (int m = 0; m < 3; ++m) {
        dx += w[m] * p[m]->x;
        dy += w[m] * p[m]->y;
        ax += w[m] * std::abs(p[m]->x);
        ay += w[m] * std::abs(p[m]->y);
        az += w[m] * std::abs(p[m]->z);
    }
#endif
    const double off0 = std::abs(dx) + 4 * kEps * ax + cornerError;
    const double off1 = std::abs(dy) + 4 * kEps * ay + cornerError;
    const double off2 = 4 * kEps * az;
#if defined(__AVX2__)
    // Stored in pieces of 16 bytes (at the struct's offsets 0, 16, ..., 64), the chunks
    // in which the walk copies a face point it has just made (FacePoint::SetFrom): a load
    // of 16 bytes from two stores of 8 would wait for both to reach the cache instead of
    // taking their data on the way.
    static_assert(offsetof(FacePoint, v) == 0 && offsetof(FacePoint, w) == 16 &&
                  offsetof(FacePoint, t) == 40 && offsetof(FacePoint, off) == 48 &&
                  offsetof(FacePoint, cornerError) == 72 && sizeof(FacePoint) == 80);
    unsigned char* base = reinterpret_cast<unsigned char*>(&fp);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(base),
                     _mm_setr_epi32(ids[0], ids[1], ids[2], 0));
    _mm_storeu_pd(reinterpret_cast<double*>(base + 16), _mm_setr_pd(w[0], w[1]));
    _mm_storeu_pd(reinterpret_cast<double*>(base + 32), _mm_setr_pd(w[2], x.t));
    _mm_storeu_pd(reinterpret_cast<double*>(base + 48), _mm_setr_pd(off0, off1));
    _mm_storeu_pd(reinterpret_cast<double*>(base + 64), _mm_setr_pd(off2, cornerError));
#else
    for (int k = 0; k < 3; ++k) {
        fp.v[k] = ids[k];
        fp.w[k] = w[k];
    }
    fp.t = x.t;
    fp.off[0] = off0;
    fp.off[1] = off1;
    fp.off[2] = off2;
    fp.cornerError = cornerError;
#endif
}

}  // namespace hpray::trace
