// Bernstein nets of curved faces and their exact ray crossings (see curved_face.h).
#include "trace/curved_face.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <utility>
#include <vector>

#if defined(__AVX2__)
#include <immintrin.h>
#endif

#include "util/check.h"
#include "util/dense_inverse.h"

namespace hpray::trace {
namespace {

constexpr int kMaxOrder = 10;
constexpr int kMaxNet = (kMaxOrder + 1) * (kMaxOrder + 1);
// Bisection depth of an edge count; sub-patch sides stay far below it, which keeps the
// counts of a side and of its halves exactly additive.
constexpr int kMaxCurveDepth = 60;
// Subdivision depth of a face: about 2^-20 of its parameter range per direction.
constexpr int kMaxPatchDepth = 40;

inline int TriIndex(int p, int i, int j) { return j * (p + 1) - j * (j - 1) / 2 + i; }
inline int QuadIndex(int p, int i, int j) { return j * (p + 1) + i; }

// Inverse of a Bernstein collocation matrix (well conditioned), rounded to double.
std::vector<double> Invert(int n, const std::vector<long double>& m) {
    const std::vector<long double> inv = InvertDense(n, m);
    return std::vector<double>(inv.begin(), inv.end());
}

long double PowL(long double x, int k) {
    long double r = 1;
    for (int i = 0; i < k; ++i) r *= x;
    return r;
}

// Binomial coefficients, exact in double (kMaxOrder is far below where they stop being).
constexpr double Binomial(int n, int k) {
    double r = 1;
    for (int i = 1; i <= k; ++i) r = r * (n - k + i) / i;
    return r;
}

struct Tables {
    std::vector<double> edgeInv[kMaxOrder + 1];  // Bernstein from nodal values, 1-D
    std::vector<double> triInv[kMaxOrder + 1];   // Bernstein from nodal values, triangle

    Tables() {
        for (int p = 1; p <= kMaxOrder; ++p) {
            std::vector<long double> m(std::size_t(p + 1) * (p + 1));
            for (int k = 0; k <= p; ++k) {
                const long double s = (long double)k / p;
                for (int i = 0; i <= p; ++i)
                    m[std::size_t(k) * (p + 1) + i] =
                        Binomial(p, i) * PowL(s, i) * PowL(1 - s, p - i);
            }
            edgeInv[p] = Invert(p + 1, m);
            const int n = NetSize(true, p);
            std::vector<long double> t(std::size_t(n) * n);
            for (int jn = 0; jn <= p; ++jn)
                for (int in = 0; in <= p - jn; ++in) {
                    const long double u = (long double)in / p, v = (long double)jn / p;
                    const long double w = 1 - u - v;
                    const int row = TriIndex(p, in, jn);
                    for (int j = 0; j <= p; ++j)
                        for (int i = 0; i <= p - j; ++i)
                            t[std::size_t(row) * n + TriIndex(p, i, j)] =
                                Binomial(p, i) * Binomial(p - i, j) * PowL(u, i) *
                                PowL(v, j) * PowL(w, p - i - j);
                }
            triInv[p] = Invert(n, t);
        }
    }
};

const Tables& GetTables() {
    static const Tables tables;
    return tables;
}

// ---------------------------------------------------------------------------------------
// Edge counts

struct P2 {
    double x, y;
};

// Signed crossing of the straight segment a -> b with the perturbed half-line (exact).
int SegmentCount(const P2& a, const P2& b) {
    const bool ua = a.y > 0, ub = b.y > 0;
    if (ua == ub) return 0;
    const int up = ub ? 1 : -1;
    const int s = EdgeSign(ShearedPoint{a.x, a.y, 0}, ShearedPoint{b.x, b.y, 0});
    return s == up ? up : 0;
}

// De Casteljau at 1/2. Every new point is (a + b) * 0.5, which is symmetric in a and b,
// so halving the reversed polygon gives bitwise the reversed halves.
void Halve(const P2* c, int n, P2* left, P2* right) {
    P2 w[kMaxOrder + 1];
    std::copy(c, c + n + 1, w);
    left[0] = w[0];
    right[n] = w[n];
    for (int r = 1; r <= n; ++r) {
        for (int i = 0; i + r <= n; ++i) {
            w[i].x = (w[i].x + w[i + 1].x) * 0.5;
            w[i].y = (w[i].y + w[i + 1].y) * 0.5;
        }
        left[r] = w[0];
        right[n - r] = w[n - r];
    }
}

// Is the origin separated from every control point by a margin along direction (a, b)?
// The margin (1e-10 of the points' extent) is far above the rounding that halving adds,
// so halves of a separated curve are still counted exactly (see CurveCount).
bool Separated(const P2* c, int n, double a, double b) {
    double lo = INFINITY, hi = -INFINITY, scale = 0;
    for (int k = 0; k <= n; ++k) {
        const double s = a * c[k].x + b * c[k].y;
        lo = std::min(lo, s);
        hi = std::max(hi, s);
        scale = std::max(scale, std::fabs(a * c[k].x) + std::fabs(b * c[k].y));
    }
    const double margin = 1e-10 * scale;
    return lo > margin || hi < -margin;
}

// Signed number of crossings of the Bezier curve c[0..n] with the half-line from the
// perturbed origin towards +x (+1 upwards). Exactly antisymmetric under reversal of c and
// exactly additive over halving (CurveCount(c, d) = CurveCount(left, d + 1) +
// CurveCount(right, d + 1) for d < kMaxCurveDepth): every deciding test gives the exact
// count of the curve under the perturbation, and the halves of a decided curve are
// decided, by some test, with the same total. The axis tests are exact as they stand;
// when a line separates the origin from the control polygon by a wide margin the curve
// is homotopic to its chord away from the origin and counts as the chord.
int CurveCount(const P2* c, int n, int depth) {
    bool yPos = true, yNonPos = true, xPos = true, xNonPos = true;
    for (int k = 0; k <= n; ++k) {
        yPos = yPos && c[k].y > 0;
        yNonPos = yNonPos && !(c[k].y > 0);
        xPos = xPos && c[k].x > 0;
        xNonPos = xNonPos && !(c[k].x > 0);
    }
    if (yPos || yNonPos || xNonPos) return 0;
    if (xPos) return int(c[n].y > 0) - int(c[0].y > 0);
    if (n == 1 || depth >= kMaxCurveDepth) return SegmentCount(c[0], c[n]);
    // Separating lines: normal to the chord, and normal to the direction of its middle.
    const double ex = c[n].x - c[0].x, ey = c[n].y - c[0].y;
    if (Separated(c, n, -ey, ex) || Separated(c, n, c[0].x + c[n].x, c[0].y + c[n].y))
        return SegmentCount(c[0], c[n]);
    P2 left[kMaxOrder + 1], right[kMaxOrder + 1];
    Halve(c, n, left, right);
    return CurveCount(left, n, depth + 1) + CurveCount(right, n, depth + 1);
}

// ---------------------------------------------------------------------------------------
// Sub-patches

// A sub-patch of the face: its control net in the ray plane, its parameter region, and
// for each side the number of halvings since that side's curve was created (a face edge,
// or the cut between two siblings), so that side counts add up exactly to the whole
// curve's. Triangles: corners (A, B, C), net point (i, j) = blossom(A^(p-i-j) B^i C^j),
// sides A->B, B->C, C->A; refined by newest-vertex bisection of A->B. Quadrilaterals: the
// box [u0, u1] x [v0, v1], sides bottom, right, top, left counter-clockwise.
struct Patch {
    P2 b[kMaxNet];
    double corner[3][2];  // triangle: A, B, C; quad: (u0, v0), (u1, v1)
    std::uint8_t sideDepth[4];
    std::uint8_t depth;
    Patch() {}  // left uninitialised: only the first NetSize points are ever used
};

// Copies a patch's used part.
void CopyPatch(const Patch& from, int n, Patch& to) {
    std::copy(from.b, from.b + n, to.b);
    for (int a = 0; a < 3; ++a)
        to.corner[a][0] = from.corner[a][0], to.corner[a][1] = from.corner[a][1];
    for (int k = 0; k < 4; ++k) to.sideDepth[k] = from.sideDepth[k];
    to.depth = from.depth;
}

struct Scratch {
    std::vector<Patch> stack;
    std::vector<FaceCrossing> found;
    std::vector<ShearedPoint> net;  // the face's control net in the ray frame
};
thread_local Scratch tScratch;

void Side(const Patch& q, bool tri, int p, int s, P2* out) {
    for (int k = 0; k <= p; ++k) {
        int i, j;
        if (tri) {
            switch (s) {
                case 0:
                    i = k, j = 0;
                    break;
                case 1:
                    i = p - k, j = k;
                    break;
                default:
                    i = 0, j = p - k;
                    break;
            }
            out[k] = q.b[TriIndex(p, i, j)];
        } else {
            switch (s) {
                case 0:
                    i = k, j = 0;
                    break;
                case 1:
                    i = p, j = k;
                    break;
                case 2:
                    i = p - k, j = p;
                    break;
                default:
                    i = 0, j = p - k;
                    break;
            }
            out[k] = q.b[QuadIndex(p, i, j)];
        }
    }
}

int PatchCount(const Patch& q, bool tri, int p) {
    int w = 0;
    P2 c[kMaxOrder + 1];
    for (int s = 0; s < (tri ? 3 : 4); ++s) {
        Side(q, tri, p, s, c);
        w += CurveCount(c, p, q.sideDepth[s]);
    }
    return w;
}

// Does the control net's box exclude the perturbed origin? Then every side count is
// decided by the same test and the patch's count is exactly 0.
bool Excluded(const Patch& q, int n) {
    double x0 = q.b[0].x, x1 = x0, y0 = q.b[0].y, y1 = y0;
    for (int k = 1; k < n; ++k) {
        x0 = std::min(x0, q.b[k].x);
        x1 = std::max(x1, q.b[k].x);
        y0 = std::min(y0, q.b[k].y);
        y1 = std::max(y1, q.b[k].y);
    }
    return x0 > 0 || !(x1 > 0) || y0 > 0 || !(y1 > 0);
}

// Sufficient test for injectivity on the patch: every pair of control points of the two
// directional derivative nets has a cross product of one strict sign (then the mean
// derivatives along any segment of the parameter region are never parallel). Cross
// products within rounding of zero fail the test.
bool Injective(const Patch& q, bool tri, int p) {
    // Structure of arrays, so that the all-pairs loop below is branch-free and
    // vectorises.
    double d1x[kMaxNet], d1y[kMaxNet], d2x[kMaxNet + 4], d2y[kMaxNet + 4];
    int n = 0;
    for (int j = 0; j <= (tri ? p - 1 : p); ++j)
        for (int i = 0; i <= (tri ? p - 1 - j : p - 1); ++i) {
            const P2 a = q.b[tri ? TriIndex(p, i, j) : QuadIndex(p, i, j)];
            const P2 b = q.b[tri ? TriIndex(p, i + 1, j) : QuadIndex(p, i + 1, j)];
            d1x[n] = b.x - a.x;
            d1y[n++] = b.y - a.y;
        }
    int m = 0;
    for (int j = 0; j <= p - 1; ++j)
        for (int i = 0; i <= (tri ? p - 1 - j : p); ++i) {
            const P2 a = q.b[tri ? TriIndex(p, i, j) : QuadIndex(p, i, j)];
            const P2 b = q.b[tri ? TriIndex(p, i, j + 1) : QuadIndex(p, i, j + 1)];
            d2x[m] = b.x - a.x;
            d2y[m++] = b.y - a.y;
        }
    if (n == 0 || m == 0) return false;
    // Every cross product above its rounding margin, all of one sign (a pair within the
    // margin, or NaN, fails both).
    bool allPositive = true, allNegative = true;
#if defined(__AVX2__)
    // Four pairs at a time; the last vector is padded by repeating the last d2.
    const int m4 = (m + 3) / 4 * 4;
    for (int b = m; b < m4; ++b) d2x[b] = d2x[m - 1], d2y[b] = d2y[m - 1];
    const __m256d absMask = _mm256_castsi256_pd(_mm256_set1_epi64x(0x7fffffffffffffffLL));
    const __m256d rel = _mm256_set1_pd(1e-12);
    __m256d pos = _mm256_castsi256_pd(_mm256_set1_epi64x(-1)), neg = pos;
    for (int a = 0; a < n; ++a) {
        const __m256d ax = _mm256_set1_pd(d1x[a]), ay = _mm256_set1_pd(d1y[a]);
        for (int b = 0; b < m4; b += 4) {
            const __m256d px = _mm256_mul_pd(ax, _mm256_loadu_pd(d2y + b));
            const __m256d py = _mm256_mul_pd(ay, _mm256_loadu_pd(d2x + b));
            const __m256d c = _mm256_sub_pd(px, py);
            const __m256d margin = _mm256_mul_pd(
                rel,
                _mm256_add_pd(_mm256_and_pd(px, absMask), _mm256_and_pd(py, absMask)));
            pos = _mm256_and_pd(pos, _mm256_cmp_pd(c, margin, _CMP_GT_OQ));
            neg = _mm256_and_pd(
                neg,
                _mm256_cmp_pd(c, _mm256_sub_pd(_mm256_setzero_pd(), margin), _CMP_LT_OQ));
        }
        allPositive = _mm256_movemask_pd(pos) == 0xf;
        allNegative = _mm256_movemask_pd(neg) == 0xf;
        if (!allPositive && !allNegative) return false;
    }
#else
    for (int a = 0; a < n; ++a) {
        const double ax = d1x[a], ay = d1y[a];
        bool pos = true, neg = true;
        for (int b = 0; b < m; ++b) {
            const double px = ax * d2y[b], py = ay * d2x[b];
            const double c = px - py;
            const double margin = 1e-12 * (std::fabs(px) + std::fabs(py));
            pos &= c > margin;
            neg &= c < -margin;
        }
        allPositive &= pos;
        allNegative &= neg;
        if (!allPositive && !allNegative) return false;
    }
#endif
    return allPositive || allNegative;
}

void SplitQuad(const Patch& q, int p, bool alongU, Patch& lo, Patch& hi) {
    P2 row[kMaxOrder + 1], l[kMaxOrder + 1], r[kMaxOrder + 1];
    for (int a = 0; a <= p; ++a) {
        for (int k = 0; k <= p; ++k)
            row[k] = q.b[alongU ? QuadIndex(p, k, a) : QuadIndex(p, a, k)];
        Halve(row, p, l, r);
        for (int k = 0; k <= p; ++k) {
            lo.b[alongU ? QuadIndex(p, k, a) : QuadIndex(p, a, k)] = l[k];
            hi.b[alongU ? QuadIndex(p, k, a) : QuadIndex(p, a, k)] = r[k];
        }
    }
    const double u0 = q.corner[0][0], v0 = q.corner[0][1], u1 = q.corner[1][0],
                 v1 = q.corner[1][1];
    lo.depth = hi.depth = std::uint8_t(q.depth + 1);
    for (int s = 0; s < 4; ++s) lo.sideDepth[s] = hi.sideDepth[s] = q.sideDepth[s];
    if (alongU) {
        const double um = 0.5 * (u0 + u1);
        lo.corner[0][0] = u0, lo.corner[0][1] = v0, lo.corner[1][0] = um,
        lo.corner[1][1] = v1;
        hi.corner[0][0] = um, hi.corner[0][1] = v0, hi.corner[1][0] = u1,
        hi.corner[1][1] = v1;
        // bottom (0) and top (2) halved; lo's right (1) and hi's left (3) are the new
        // cut.
        lo.sideDepth[0] = hi.sideDepth[0] = std::uint8_t(q.sideDepth[0] + 1);
        lo.sideDepth[2] = hi.sideDepth[2] = std::uint8_t(q.sideDepth[2] + 1);
        lo.sideDepth[1] = 0;
        hi.sideDepth[3] = 0;
    } else {
        const double vm = 0.5 * (v0 + v1);
        lo.corner[0][0] = u0, lo.corner[0][1] = v0, lo.corner[1][0] = u1,
        lo.corner[1][1] = vm;
        hi.corner[0][0] = u0, hi.corner[0][1] = vm, hi.corner[1][0] = u1,
        hi.corner[1][1] = v1;
        lo.sideDepth[1] = hi.sideDepth[1] = std::uint8_t(q.sideDepth[1] + 1);
        lo.sideDepth[3] = hi.sideDepth[3] = std::uint8_t(q.sideDepth[3] + 1);
        lo.sideDepth[2] = 0;
        hi.sideDepth[0] = 0;
    }
}

// Newest-vertex bisection of (A, B, C) at the midpoint M of A->B into (C, A, M) and
// (B, C, M) (both keep the orientation; their refinement edges are opposite M). Rows of
// the net parallel to A->B are Bezier curves whose halves are the children's rows.
void SplitTriangle(const Patch& q, int p, Patch& t1, Patch& t2) {
    P2 row[kMaxOrder + 1], l[kMaxOrder + 1][kMaxOrder + 1],
        r[kMaxOrder + 1][kMaxOrder + 1];
    for (int j = 0; j <= p; ++j) {
        for (int i = 0; i <= p - j; ++i) row[i] = q.b[TriIndex(p, i, j)];
        Halve(row, p - j, l[j], r[j]);
    }
    // (A, M, C): l[j][i] = blossom(A^(p-i-j) M^i C^j); relabelled (C, A, M).
    // (M, B, C): r[j][i] = blossom(M^(p-i-j) B^i C^j); relabelled (B, C, M).
    for (int j = 0; j <= p; ++j)
        for (int i = 0; i <= p - j; ++i) {
            t1.b[TriIndex(p, i, j)] = l[p - i - j][j];
            t2.b[TriIndex(p, i, j)] = r[i][p - i - j];
        }
    const double* A = q.corner[0];
    const double* B = q.corner[1];
    const double* C = q.corner[2];
    const double M[2] = {0.5 * (A[0] + B[0]), 0.5 * (A[1] + B[1])};
    for (int d = 0; d < 2; ++d) {
        t1.corner[0][d] = C[d], t1.corner[1][d] = A[d], t1.corner[2][d] = M[d];
        t2.corner[0][d] = B[d], t2.corner[1][d] = C[d], t2.corner[2][d] = M[d];
    }
    t1.depth = t2.depth = std::uint8_t(q.depth + 1);
    const std::uint8_t half = std::uint8_t(q.sideDepth[0] + 1);
    t1.sideDepth[0] = q.sideDepth[2], t1.sideDepth[1] = half, t1.sideDepth[2] = 0;
    t2.sideDepth[0] = q.sideDepth[1], t2.sideDepth[1] = 0, t2.sideDepth[2] = half;
    t1.sideDepth[3] = t2.sideDepth[3] = 0;
}

// Is (u, v) in the patch's parameter region grown by `margin` (parameter units)?
bool InPatch(const Patch& q, bool tri, double u, double v, double margin) {
    if (!tri)
        return u >= q.corner[0][0] - margin && u <= q.corner[1][0] + margin &&
               v >= q.corner[0][1] - margin && v <= q.corner[1][1] + margin;
    const double* A = q.corner[0];
    const double* B = q.corner[1];
    const double* C = q.corner[2];
    const double e1[2] = {B[0] - A[0], B[1] - A[1]}, e2[2] = {C[0] - A[0], C[1] - A[1]};
    const double det = e1[0] * e2[1] - e1[1] * e2[0];
    const double x = u - A[0], y = v - A[1];
    const double l1 = (x * e2[1] - y * e2[0]) / det, l2 = (e1[0] * y - e1[1] * x) / det;
    const double len =
        std::sqrt(std::max(e1[0] * e1[0] + e1[1] * e1[1], e2[0] * e2[0] + e2[1] * e2[1]));
    const double m = margin / len;
    return l1 >= -m && l2 >= -m && 1 - l1 - l2 >= -m;
}

void Centre(const Patch& q, bool tri, double& u, double& v) {
    if (tri) {
        u = (q.corner[0][0] + q.corner[1][0] + q.corner[2][0]) / 3;
        v = (q.corner[0][1] + q.corner[1][1] + q.corner[2][1]) / 3;
    } else {
        u = 0.5 * (q.corner[0][0] + q.corner[1][0]);
        v = 0.5 * (q.corner[0][1] + q.corner[1][1]);
    }
}

// Newton's start in a patch: the point whose corner-interpolant (the flat triangle of the
// corners; for quadrilaterals the half, split on the diagonal, that holds the origin
// best) maps to the origin, clamped into the patch.
void StartPoint(const Patch& q, bool tri, int p, double& u, double& v) {
    auto solve = [](const P2& a, const P2& b, const P2& c, double& beta, double& gamma) {
        const double e1x = b.x - a.x, e1y = b.y - a.y, e2x = c.x - a.x, e2y = c.y - a.y;
        const double det = e1x * e2y - e1y * e2x;
        if (det == 0 || !std::isfinite(det)) return false;
        beta = (-a.x * e2y + a.y * e2x) / det;
        gamma = (-e1x * a.y + e1y * a.x) / det;
        return std::isfinite(beta) && std::isfinite(gamma);
    };
    auto clampBary = [](double& beta, double& gamma) {
        beta = std::max(0.0, beta);
        gamma = std::max(0.0, gamma);
        const double sum = beta + gamma;
        if (sum > 1) {
            beta /= sum;
            gamma /= sum;
        }
    };
    double beta, gamma;
    if (tri) {
        const P2 a = q.b[TriIndex(p, 0, 0)], b = q.b[TriIndex(p, p, 0)],
                 c = q.b[TriIndex(p, 0, p)];
        if (!solve(a, b, c, beta, gamma)) return Centre(q, tri, u, v);
        clampBary(beta, gamma);
        const double* A = q.corner[0];
        const double* B = q.corner[1];
        const double* C = q.corner[2];
        u = A[0] + beta * (B[0] - A[0]) + gamma * (C[0] - A[0]);
        v = A[1] + beta * (B[1] - A[1]) + gamma * (C[1] - A[1]);
        return;
    }
    const P2 c00 = q.b[QuadIndex(p, 0, 0)], c10 = q.b[QuadIndex(p, p, 0)];
    const P2 c11 = q.b[QuadIndex(p, p, p)], c01 = q.b[QuadIndex(p, 0, p)];
    double b1, g1, b2, g2;
    const bool ok1 = solve(c00, c10, c11, b1, g1), ok2 = solve(c00, c11, c01, b2, g2);
    if (!ok1 && !ok2) return Centre(q, tri, u, v);
    auto outside = [](double beta, double gamma) {
        return std::max({0.0, -beta, -gamma, beta + gamma - 1});
    };
    double s, t;  // position in the unit square
    if (ok1 && (!ok2 || outside(b1, g1) <= outside(b2, g2))) {
        clampBary(b1, g1);
        s = b1 + g1;  // (0,0) + b1 (1,0) + g1 (1,1)
        t = g1;
    } else {
        clampBary(b2, g2);
        s = b2;  // (0,0) + b2 (1,1) + g2 (0,1)
        t = b2 + g2;
    }
    u = q.corner[0][0] + s * (q.corner[1][0] - q.corner[0][0]);
    v = q.corner[0][1] + t * (q.corner[1][1] - q.corner[0][1]);
}

double Diameter(const Patch& q, bool tri) {
    if (!tri)
        return std::max(q.corner[1][0] - q.corner[0][0], q.corner[1][1] - q.corner[0][1]);
    double d = 0;
    for (int a = 0; a < 3; ++a) {
        const double* x = q.corner[a];
        const double* y = q.corner[(a + 1) % 3];
        d = std::max(d, std::hypot(x[0] - y[0], x[1] - y[1]));
    }
    return d;
}

// Newton on G(u, v) = 0 (the ray plane part of the face map) from (u, v).
bool Newton(bool tri, int p, const ShearedPoint* net, const CurvedFaceOptions& options,
            double& u, double& v, double& t) {
    double f[3], fu[3], fv[3];
    bool converged = false;
    // Once the residual is within the tolerance, polish on while the steps still shrink
    // fast (quadratic convergence): near tangency the Jacobian is nearly singular and a
    // residual at the tolerance still leaves t off by residual / sin(angle to the face).
    double lastStep = INFINITY;
    // The last step was predicted to land within rounding of the root: accepted if the
    // residual there is within the tolerance.
    bool predicted = false;
    for (int it = 0; it < options.maxNewtonIterations; ++it) {
        EvalNet(tri, p, net, u, v, f, fu, fv);
        const double det = fu[0] * fv[1] - fu[1] * fv[0];
        if (det == 0 || !std::isfinite(det)) return false;
        const double res = std::sqrt(f[0] * f[0] + f[1] * f[1]);
        if (predicted && res <= options.tolerance) {
            t = f[2];
            return std::isfinite(t);
        }
        predicted = false;
        const double du = (f[0] * fv[1] - f[1] * fv[0]) / det;
        const double dv = (fu[0] * f[1] - fu[1] * f[0]) / det;
        const double step = std::fabs(du) + std::fabs(dv);
        if (converged && !(step < 0.25 * lastStep)) {
            // At rounding: keep (u, v), where f was just evaluated.
            t = f[2];
            return std::isfinite(t);
        }
        u -= du;
        v -= dv;
        if (!(std::fabs(u) < 4 && std::fabs(v) < 4)) return false;
        if (res <= options.tolerance) {
            if (converged && step < 1e-15) break;
            converged = true;
        } else if (lastStep <= 1e-2 &&
                   step * step * step <= 1e-16 * lastStep * lastStep) {
            // Quadratic convergence measured on the last two steps: the error left after
            // this one is about K step^2 with K = step / lastStep^2, far below the
            // tolerance (near tangency K is large and this does not apply).
            predicted = true;
        }
        lastStep = step;
    }
    if (!converged) return false;
    EvalNet(tri, p, net, u, v, f, fu, fv);
    t = f[2];
    return std::isfinite(t);
}

// Distance in parameter space of (u, v) from boundary edge e of the face.
double EdgeDistance(bool tri, int e, double u, double v) {
    if (tri) {
        switch (e) {
            case 0:
                return std::fabs(v);
            case 1:
                return std::fabs(1 - u - v) / std::sqrt(2.0);
            default:
                return std::fabs(u);
        }
    }
    switch (e) {
        case 0:
            return std::fabs(v);
        case 1:
            return std::fabs(1 - u);
        case 2:
            return std::fabs(1 - v);
        default:
            return std::fabs(u);
    }
}

}  // namespace

int NetSize(bool triangle, int order) {
    return triangle ? (order + 1) * (order + 2) / 2 : (order + 1) * (order + 1);
}

int EdgeLatticeIndex(bool triangle, int p, int e, int k) {
    if (triangle) {
        switch (e) {
            case 0:
                return TriIndex(p, k, 0);
            case 1:
                return TriIndex(p, p - k, k);
            default:
                return TriIndex(p, 0, p - k);
        }
    }
    switch (e) {
        case 0:
            return QuadIndex(p, k, 0);
        case 1:
            return QuadIndex(p, p, k);
        case 2:
            return QuadIndex(p, p - k, p);
        default:
            return QuadIndex(p, 0, p - k);
    }
}

void EdgeBernstein(int p, const double* nodal, double* net) {
    HPRAY_CHECK(p >= 1 && p <= kMaxOrder);
    const std::vector<double>& inv = GetTables().edgeInv[p];
    for (int i = 0; i <= p; ++i)
        for (int d = 0; d < 3; ++d) {
            double s = 0;
            for (int k = 0; k <= p; ++k)
                s += inv[std::size_t(i) * (p + 1) + k] * nodal[3 * k + d];
            net[3 * i + d] = s;
        }
    for (int d = 0; d < 3; ++d) {
        net[d] = nodal[d];
        net[3 * p + d] = nodal[3 * p + d];
    }
}

void FaceBernstein(bool triangle, int p, const double* nodal, double* net) {
    HPRAY_CHECK(p >= 1 && p <= kMaxOrder);
    const Tables& tab = GetTables();
    const int n = NetSize(triangle, p);
    if (triangle) {
        const std::vector<double>& inv = tab.triInv[p];
        for (int m = 0; m < n; ++m)
            for (int d = 0; d < 3; ++d) {
                double s = 0;
                for (int k = 0; k < n; ++k)
                    s += inv[std::size_t(m) * n + k] * nodal[3 * k + d];
                net[3 * m + d] = s;
            }
    } else {
        const std::vector<double>& inv = tab.edgeInv[p];
        std::vector<double> tmp(3 * std::size_t(n));
        for (int j = 0; j <= p; ++j)  // along u
            for (int i = 0; i <= p; ++i)
                for (int d = 0; d < 3; ++d) {
                    double s = 0;
                    for (int k = 0; k <= p; ++k)
                        s += inv[std::size_t(i) * (p + 1) + k] *
                             nodal[3 * QuadIndex(p, k, j) + d];
                    tmp[3 * QuadIndex(p, i, j) + d] = s;
                }
        for (int j = 0; j <= p; ++j)  // along v
            for (int i = 0; i <= p; ++i)
                for (int d = 0; d < 3; ++d) {
                    double s = 0;
                    for (int k = 0; k <= p; ++k)
                        s += inv[std::size_t(j) * (p + 1) + k] *
                             tmp[3 * QuadIndex(p, i, k) + d];
                    net[3 * QuadIndex(p, i, j) + d] = s;
                }
    }
    for (int c = 0; c < (triangle ? 3 : 4); ++c) {
        const int idx = EdgeLatticeIndex(triangle, p, c, 0);
        for (int d = 0; d < 3; ++d) net[3 * idx + d] = nodal[3 * idx + d];
    }
}

namespace {

// Bernstein basis of degree P at s (b) and its derivative (db), by the recurrence
// B_i^d = (1 - s) B_i^(d-1) + s B_(i-1)^(d-1) up to degree P - 1, whose values give the
// derivative d/ds B_i^P = P (B_(i-1)^(P-1) - B_i^(P-1)).
template <int P>
inline void BernsteinWithDerivative(double s, double* b, double* db) {
    double low[P + 1];
    low[0] = 1;
    const double r = 1 - s;
    for (int d = 1; d < P; ++d) {
        low[d] = s * low[d - 1];
        for (int i = d - 1; i > 0; --i) low[i] = r * low[i] + s * low[i - 1];
        low[0] = r * low[0];
    }
    // low[0..P-1]: degree P - 1.
    b[0] = r * low[0];
    b[P] = s * low[P - 1];
    db[0] = -P * low[0];
    db[P] = P * low[P - 1];
    for (int i = 1; i < P; ++i) {
        b[i] = r * low[i] + s * low[i - 1];
        db[i] = P * (low[i - 1] - low[i]);
    }
}

#if defined(__AVX2__)
// The net evaluations below with a point's x, y, z in the first three lanes of a vector
// (the fourth zero; a masked load reads nothing past the point): each lane takes the
// scalar code's products and sums in the same order, nothing fused, so the results are
// bitwise the same.
static_assert(sizeof(ShearedPoint) == 3 * sizeof(double));
inline __m256d NetXyz(const ShearedPoint& q) {
    return _mm256_maskload_pd(&q.x, _mm256_setr_epi64x(-1, -1, -1, 0));
}
inline void StoreXyz(__m256d v, double out[3]) {
    alignas(32) double lanes[4];
    _mm256_store_pd(lanes, v);
    for (int c = 0; c < 3; ++c) out[c] = lanes[c];
}
#endif

template <int P>
void EvalQuadNet(const ShearedPoint* net, double u, double v, double value[3],
                 double dU[3], double dV[3]) {
    double bu[P + 1], du[P + 1], bv[P + 1], dv[P + 1];
    BernsteinWithDerivative<P>(u, bu, du);
    BernsteinWithDerivative<P>(v, bv, dv);
#if defined(__AVX2__)
    {
        __m256d f = _mm256_setzero_pd(), fu = f, fv = f;
        for (int j = 0; j <= P; ++j) {
            __m256d r = _mm256_setzero_pd(), dr = r;
            for (int i = 0; i <= P; ++i) {
                const __m256d q = NetXyz(net[j * (P + 1) + i]);
                r = _mm256_add_pd(r, _mm256_mul_pd(_mm256_set1_pd(bu[i]), q));
                dr = _mm256_add_pd(dr, _mm256_mul_pd(_mm256_set1_pd(du[i]), q));
            }
            const __m256d b = _mm256_set1_pd(bv[j]);
            f = _mm256_add_pd(f, _mm256_mul_pd(b, r));
            fu = _mm256_add_pd(fu, _mm256_mul_pd(b, dr));
            fv = _mm256_add_pd(fv, _mm256_mul_pd(_mm256_set1_pd(dv[j]), r));
        }
        StoreXyz(f, value);
        StoreXyz(fu, dU);
        StoreXyz(fv, dV);
        return;
    }
#endif
    double f[3] = {0, 0, 0}, fu[3] = {0, 0, 0}, fv[3] = {0, 0, 0};
    for (int j = 0; j <= P; ++j) {
        // Row j contracted along u, then weighted along v.
        double r[3] = {0, 0, 0}, dr[3] = {0, 0, 0};
        for (int i = 0; i <= P; ++i) {
            const ShearedPoint& q = net[j * (P + 1) + i];
            r[0] += bu[i] * q.x;
            r[1] += bu[i] * q.y;
            r[2] += bu[i] * q.z;
            dr[0] += du[i] * q.x;
            dr[1] += du[i] * q.y;
            dr[2] += du[i] * q.z;
        }
        for (int c = 0; c < 3; ++c) {
            f[c] += bv[j] * r[c];
            fu[c] += bv[j] * dr[c];
            fv[c] += dv[j] * r[c];
        }
    }
    for (int c = 0; c < 3; ++c) value[c] = f[c], dU[c] = fu[c], dV[c] = fv[c];
}

// The triangle net's weights as EvalTriangleNet multiplies them: value[i][j] =
// C(P, i) C(P - i, j) and slope[i][j] = P C(P - 1, i) C(P - 1 - i, j), products of
// integers, so exactly the values the products give at run time.
template <int P>
struct TriangleWeights {
    double value[P + 1][P + 1] = {};
    double slope[P + 1][P + 1] = {};
    constexpr TriangleWeights() {
        for (int j = 0; j <= P; ++j)
            for (int i = 0; i + j <= P; ++i)
                value[i][j] = Binomial(P, i) * Binomial(P - i, j);
        for (int j = 0; j < P; ++j)
            for (int i = 0; i + j < P; ++i)
                slope[i][j] = P * Binomial(P - 1, i) * Binomial(P - 1 - i, j);
    }
};

template <int P>
void EvalTriangleNet(const ShearedPoint* net, double u, double v, double value[3],
                     double dU[3], double dV[3]) {
    static constexpr TriangleWeights<P> kWeights{};
    const double w = 1 - u - v;
    double pu[P + 1], pv[P + 1], pw[P + 1];
    pu[0] = pv[0] = pw[0] = 1;
    for (int k = 1; k <= P; ++k) {
        pu[k] = pu[k - 1] * u;
        pv[k] = pv[k - 1] * v;
        pw[k] = pw[k - 1] * w;
    }
#if defined(__AVX2__)
    {
        __m256d f = _mm256_setzero_pd(), fu = f, fv = f;
#pragma GCC unroll 66
        for (int j = 0; j <= P; ++j)
#pragma GCC unroll 11
            for (int i = 0; i <= P - j; ++i) {
                const double b = kWeights.value[i][j] * pu[i] * pv[j] * pw[P - i - j];
                f = _mm256_add_pd(
                    f, _mm256_mul_pd(_mm256_set1_pd(b), NetXyz(net[TriIndex(P, i, j)])));
            }
        constexpr int Q = P - 1;
#pragma GCC unroll 55
        for (int j = 0; j <= Q; ++j)
#pragma GCC unroll 10
            for (int i = 0; i <= Q - j; ++i) {
                const __m256d b =
                    _mm256_set1_pd(kWeights.slope[i][j] * pu[i] * pv[j] * pw[Q - i - j]);
                const __m256d o = NetXyz(net[TriIndex(P, i, j)]);
                const __m256d a = NetXyz(net[TriIndex(P, i + 1, j)]);
                const __m256d c = NetXyz(net[TriIndex(P, i, j + 1)]);
                fu = _mm256_add_pd(fu, _mm256_mul_pd(b, _mm256_sub_pd(a, o)));
                fv = _mm256_add_pd(fv, _mm256_mul_pd(b, _mm256_sub_pd(c, o)));
            }
        StoreXyz(f, value);
        StoreXyz(fu, dU);
        StoreXyz(fv, dV);
        return;
    }
#endif
    double f[3] = {0, 0, 0}, fu[3] = {0, 0, 0}, fv[3] = {0, 0, 0};
#pragma GCC unroll 66
    for (int j = 0; j <= P; ++j)
#pragma GCC unroll 11
        for (int i = 0; i <= P - j; ++i) {
            const double b = kWeights.value[i][j] * pu[i] * pv[j] * pw[P - i - j];
            const ShearedPoint& q = net[TriIndex(P, i, j)];
            f[0] += b * q.x;
            f[1] += b * q.y;
            f[2] += b * q.z;
        }
    // Derivatives: P * sum over the degree P - 1 basis of the forward differences.
    constexpr int Q = P - 1;
#pragma GCC unroll 55
    for (int j = 0; j <= Q; ++j)
#pragma GCC unroll 10
        for (int i = 0; i <= Q - j; ++i) {
            const double b = kWeights.slope[i][j] * pu[i] * pv[j] * pw[Q - i - j];
            const ShearedPoint& o = net[TriIndex(P, i, j)];
            const ShearedPoint& a = net[TriIndex(P, i + 1, j)];
            const ShearedPoint& c = net[TriIndex(P, i, j + 1)];
            fu[0] += b * (a.x - o.x);
            fu[1] += b * (a.y - o.y);
            fu[2] += b * (a.z - o.z);
            fv[0] += b * (c.x - o.x);
            fv[1] += b * (c.y - o.y);
            fv[2] += b * (c.z - o.z);
        }
    for (int c = 0; c < 3; ++c) value[c] = f[c], dU[c] = fu[c], dV[c] = fv[c];
}

using NetEvaluator = void (*)(const ShearedPoint*, double, double, double*, double*,
                              double*);
template <int... Ps>
constexpr std::array<NetEvaluator, kMaxOrder + 1> QuadTable(
    std::integer_sequence<int, Ps...>) {
    return {nullptr, &EvalQuadNet<Ps + 1>...};
}
template <int... Ps>
constexpr std::array<NetEvaluator, kMaxOrder + 1> TriangleTable(
    std::integer_sequence<int, Ps...>) {
    return {nullptr, &EvalTriangleNet<Ps + 1>...};
}
constexpr auto kQuadNet = QuadTable(std::make_integer_sequence<int, kMaxOrder>{});
constexpr auto kTriangleNet = TriangleTable(std::make_integer_sequence<int, kMaxOrder>{});

}  // namespace

void EvalNet(bool triangle, int p, const ShearedPoint* net, double u, double v,
             double value[3], double dU[3], double dV[3]) {
    (triangle ? kTriangleNet : kQuadNet)[p](net, u, v, value, dU, dV);
}

int CrossCurvedFace(const CurvedFace& face, const RayFrame& frame,
                    const CurvedFaceOptions& options, std::vector<FaceCrossing>& out) {
    const bool tri = face.triangle;
    const int p = face.order;
    HPRAY_CHECK(p >= 1 && p <= kMaxOrder);
    const int n = NetSize(tri, p);
    Scratch& s = tScratch;
    if (s.net.size() < std::size_t(kMaxNet)) s.net.resize(kMaxNet);
    ShearedPoint* net = s.net.data();
    for (int k = 0; k < n; ++k) net[k] = frame.Transform(face.net + 3 * k);

    s.stack.reserve(2 * kMaxPatchDepth + 4);
    s.stack.clear();
    s.found.clear();
    // The whole face as the first patch; triangles start from their hypotenuse:
    // (A, B, C) = ((1, 0), (0, 1), (0, 0)), so that net point (i, j) = face point
    // (p - i - j, i), and patch sides 0, 1, 2 are face edges 1, 2, 0.
    s.stack.emplace_back();
    {
        Patch& root = s.stack.back();
        if (tri) {
            for (int j = 0; j <= p; ++j)
                for (int i = 0; i <= p - j; ++i) {
                    const ShearedPoint& q = net[TriIndex(p, p - i - j, i)];
                    root.b[TriIndex(p, i, j)] = {q.x, q.y};
                }
            const double corners[3][2] = {{1, 0}, {0, 1}, {0, 0}};
            for (int a = 0; a < 3; ++a)
                for (int d = 0; d < 2; ++d) root.corner[a][d] = corners[a][d];
        } else {
            for (int k = 0; k < n; ++k) root.b[k] = {net[k].x, net[k].y};
            root.corner[0][0] = root.corner[0][1] = 0;
            root.corner[1][0] = root.corner[1][1] = 1;
        }
        for (auto& d : root.sideDepth) d = 0;
        root.depth = 0;
        if (Excluded(root, n)) return 0;
    }
    int failures = 0;
    auto emit = [&](const Patch& q, int w, bool atLimit) {
        double u, v, t = 0;
        StartPoint(q, tri, p, u, v);
        const double u0 = u, v0 = v;
        const bool ok = Newton(tri, p, net, options, u, v, t);
        const double margin = 1e-6 * Diameter(q, tri) + 1e-13;
        if (ok && InPatch(q, tri, u, v, margin)) {
            for (int k = 0; k < std::abs(w); ++k)
                s.found.push_back({t, u, v, w > 0 ? 1 : -1});
            return true;
        }
        if (!atLimit) return false;
        // Depth limit: keep a converged root anyway, else the face point at the centre.
        if (!ok) {
            double f[3], fu[3], fv[3];
            EvalNet(tri, p, net, u0, v0, f, fu, fv);
            t = f[2];
            u = u0;
            v = v0;
            failures += std::abs(w);
        }
        for (int k = 0; k < std::abs(w); ++k)
            s.found.push_back({t, u, v, w > 0 ? 1 : -1});
        return true;
    };
    Patch q;
    while (!s.stack.empty()) {
        CopyPatch(s.stack.back(), n, q);
        s.stack.pop_back();
        if (q.depth > 0 && Excluded(q, n)) continue;
        const int w = PatchCount(q, tri, p);
        const bool atLimit = q.depth >= kMaxPatchDepth;
        if (Injective(q, tri, p) && std::abs(w) <= 1) {
            if (w == 0 || emit(q, w, atLimit)) continue;
        } else if (atLimit) {
            if (w != 0) emit(q, w, true);
            continue;
        }
        // Split: two children on the stack.
        s.stack.emplace_back();
        s.stack.emplace_back();
        Patch& a = s.stack[s.stack.size() - 2];
        Patch& b = s.stack[s.stack.size() - 1];
        if (tri) {
            SplitTriangle(q, p, a, b);
        } else {
            const bool alongU =
                q.corner[1][0] - q.corner[0][0] >= q.corner[1][1] - q.corner[0][1];
            SplitQuad(q, p, alongU, a, b);
        }
    }

    // Straight edges are counted by the exact segment predicate (as the planar or
    // bilinear face on their other side counts them), the sub-patches by their snapped
    // control points: where the two disagree, the ray passes within rounding of the edge;
    // add the crossing at the edge, or drop the one found next to it.
    const int nEdges = tri ? 3 : 4;
    for (int e = 0; e < nEdges; ++e) {
        if (!(face.straightEdges & (1u << e))) continue;
        P2 c[kMaxOrder + 1];
        for (int k = 0; k <= p; ++k) {
            const ShearedPoint& q = net[EdgeLatticeIndex(tri, p, e, k)];
            c[k] = {q.x, q.y};
        }
        int delta = SegmentCount(c[0], c[p]) - CurveCount(c, p, 0);
        while (delta != 0) {
            const int sgn = delta > 0 ? 1 : -1;
            delta -= sgn;
            int best = -1;
            double bestDist = 1e-6;
            for (int r = 0; r < int(s.found.size()); ++r) {
                if (s.found[r].side != -sgn) continue;
                const double dist = EdgeDistance(tri, e, s.found[r].u, s.found[r].v);
                if (dist <= bestDist) {
                    bestDist = dist;
                    best = r;
                }
            }
            if (best >= 0) {
                s.found.erase(s.found.begin() + best);
                continue;
            }
            // The crossing of the straight edge itself: where the projected edge passes
            // the origin, t linear along it.
            const ShearedPoint& a = net[EdgeLatticeIndex(tri, p, e, 0)];
            const ShearedPoint& b = net[EdgeLatticeIndex(tri, p, e, p)];
            const double ex = b.x - a.x, ey = b.y - a.y, len2 = ex * ex + ey * ey;
            double lambda = len2 > 0 ? -(a.x * ex + a.y * ey) / len2 : 0.5;
            lambda = std::min(1.0, std::max(0.0, lambda));
            const double t = a.z + lambda * (b.z - a.z);
            // Face parameters of the edge point (for later proximity tests only).
            double u, v;
            if (tri) {
                const double cu[3][2] = {{0, 0}, {1, 0}, {0, 1}};
                u = cu[e][0] + lambda * (cu[(e + 1) % 3][0] - cu[e][0]);
                v = cu[e][1] + lambda * (cu[(e + 1) % 3][1] - cu[e][1]);
            } else {
                const double cu[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
                u = cu[e][0] + lambda * (cu[(e + 1) % 4][0] - cu[e][0]);
                v = cu[e][1] + lambda * (cu[(e + 1) % 4][1] - cu[e][1]);
            }
            s.found.push_back({t, u, v, sgn});
        }
    }
    out.insert(out.end(), s.found.begin(), s.found.end());
    return failures;
}

}  // namespace hpray::trace
