// Guaranteed field ranges and geometry boxes from Bernstein coefficients (see bounds.h).
#include "elements/bounds.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <tuple>
#include <utility>
#include <vector>

#include "util/check.h"

#if defined(__AVX2__)
#include <immintrin.h>
#endif

namespace hpray {
namespace {

using LD = long double;
constexpr double kUnit = std::numeric_limits<double>::epsilon() / 2;

LD Binomial(int n, int k) {
    LD r = 1;
    for (int i = 1; i <= k; ++i) r = r * (n - k + i) / i;
    return r;
}

LD Factorial(int n) {
    LD r = 1;
    for (int i = 2; i <= n; ++i) r *= i;
    return r;
}

LD PowInt(LD x, int k) {
    LD r = 1;
    for (int i = 0; i < k; ++i) r *= x;
    return r;
}

// Inverse of the n x n row-major matrix `a` by Gauss-Jordan with partial pivoting in
// extended precision; checks the residual so that the stored transform is exact to
// double rounding.
std::vector<LD> InvertExtended(const std::vector<LD>& matrix, int n) {
    std::vector<LD> a = matrix, inv(static_cast<std::size_t>(n) * n, 0.0L);
    for (int i = 0; i < n; ++i) inv[static_cast<std::size_t>(i) * n + i] = 1.0L;
    for (int col = 0; col < n; ++col) {
        int piv = col;
        for (int r = col + 1; r < n; ++r)
            if (std::abs(a[static_cast<std::size_t>(r) * n + col]) >
                std::abs(a[static_cast<std::size_t>(piv) * n + col]))
                piv = r;
        HPRAY_CHECK(a[static_cast<std::size_t>(piv) * n + col] != 0.0L);
        if (piv != col)
            for (int c = 0; c < n; ++c) {
                std::swap(a[static_cast<std::size_t>(piv) * n + c],
                          a[static_cast<std::size_t>(col) * n + c]);
                std::swap(inv[static_cast<std::size_t>(piv) * n + c],
                          inv[static_cast<std::size_t>(col) * n + c]);
            }
        const LD d = a[static_cast<std::size_t>(col) * n + col];
        for (int c = 0; c < n; ++c) {
            a[static_cast<std::size_t>(col) * n + c] /= d;
            inv[static_cast<std::size_t>(col) * n + c] /= d;
        }
        for (int r = 0; r < n; ++r) {
            if (r == col) continue;
            const LD f = a[static_cast<std::size_t>(r) * n + col];
            if (f == 0.0L) continue;
            for (int c = 0; c < n; ++c) {
                a[static_cast<std::size_t>(r) * n + c] -= f * a[static_cast<std::size_t>(col) * n + c];
                inv[static_cast<std::size_t>(r) * n + c] -=
                    f * inv[static_cast<std::size_t>(col) * n + c];
            }
        }
    }
    // Residual of matrix * inv - I, relative to the size of the inverse.
    LD worst = 0.0L, scale = 0.0L;
    for (LD v : inv) scale = std::max(scale, std::abs(v));
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
            LD s = (i == j) ? -1.0L : 0.0L;
            for (int k = 0; k < n; ++k)
                s += matrix[static_cast<std::size_t>(i) * n + k] *
                     inv[static_cast<std::size_t>(k) * n + j];
            worst = std::max(worst, std::abs(s));
        }
    HPRAY_CHECK_MSG(worst <= 1e-16L * std::max(scale, 1.0L),
                    "Bernstein transform residual " << static_cast<double>(worst));
    return inv;
}

struct Matrix {
    int rows = 0, cols = 0;
    std::vector<double> v, abs;  // row-major, and the entry-wise absolute values
};

Matrix ToMatrix(const std::vector<LD>& m, int rows, int cols) {
    Matrix out;
    out.rows = rows;
    out.cols = cols;
    for (LD x : m) {
        out.v.push_back(static_cast<double>(x));
        out.abs.push_back(std::abs(static_cast<double>(x)));
    }
    return out;
}

// Nodal -> Bernstein transform of one (shape, order), Lagrange family.
struct BernsteinTable {
    int p = 1;
    CellShape shape = CellShape::Hex;
    std::vector<LD> line;  // 1-D transform in extended precision (pyramid set-up)
    Matrix m1;             // 1-D: bern_k = sum_i m1[k][i] f(i/p)
    Matrix simplex;        // triangle (wedge) or tet: bern = simplex * nodal
    std::vector<Matrix> aBern;  // pyramid level k: (p+1) x (q+1), Bernstein of l^(q)_i(a)
    std::vector<std::vector<double>> cBern, cBernAbs;  // level k: Bernstein in c
    double gamma = 0.0;         // relative error bound of the computed coefficients
};

std::vector<LD> LineTransform(int p) {
    std::vector<LD> b(static_cast<std::size_t>(p + 1) * (p + 1));
    for (int i = 0; i <= p; ++i) {
        const LD x = static_cast<LD>(i) / p;
        for (int k = 0; k <= p; ++k)
            b[static_cast<std::size_t>(i) * (p + 1) + k] =
                Binomial(p, k) * PowInt(x, k) * PowInt(1.0L - x, p - k);
    }
    return InvertExtended(b, p + 1);
}

// Simplex Bernstein collocation at the equispaced lattice, lattice order of mesh/cell.h
// (k outer, then j, then i; dims = 2 for the triangle).
std::vector<LD> SimplexTransform(int p, int dims) {
    std::vector<std::array<int, 3>> idx;
    for (int k = 0; k <= (dims == 3 ? p : 0); ++k)
        for (int j = 0; j + k <= p; ++j)
            for (int i = 0; i + j + k <= p; ++i) idx.push_back({i, j, k});
    const int n = static_cast<int>(idx.size());
    std::vector<LD> b(static_cast<std::size_t>(n) * n);
    const LD pf = Factorial(p);
    for (int r = 0; r < n; ++r) {
        const LD x = static_cast<LD>(idx[r][0]) / p, y = static_cast<LD>(idx[r][1]) / p,
                 z = static_cast<LD>(idx[r][2]) / p, w = 1.0L - x - y - z;
        for (int c = 0; c < n; ++c) {
            const auto& e = idx[c];
            const int l = p - e[0] - e[1] - e[2];
            b[static_cast<std::size_t>(r) * n + c] =
                pf / (Factorial(e[0]) * Factorial(e[1]) * Factorial(e[2]) * Factorial(l)) *
                PowInt(x, e[0]) * PowInt(y, e[1]) * PowInt(z, e[2]) * PowInt(w, l);
        }
    }
    return InvertExtended(b, n);
}

// Degree-p Bernstein coefficients of a polynomial of degree <= p given by its values at
// j/p, in extended precision.
std::vector<LD> BernsteinOfValues(const std::vector<LD>& line, const std::vector<LD>& vals) {
    const int n = static_cast<int>(vals.size());
    std::vector<LD> out(n, 0.0L);
    for (int k = 0; k < n; ++k)
        for (int i = 0; i < n; ++i) out[k] += line[static_cast<std::size_t>(k) * n + i] * vals[i];
    return out;
}

LD Silvester(int p, int m, LD x) {
    LD s = 1.0L;
    for (int q = 0; q < m; ++q) s *= (p * x - q) / (q + 1);
    return s;
}

std::unique_ptr<BernsteinTable> BuildTable(CellShape shape, int p) {
    auto t = std::make_unique<BernsteinTable>();
    t->p = p;
    t->shape = shape;
    t->line = LineTransform(p);
    t->m1 = ToMatrix(t->line, p + 1, p + 1);
    const int n = NodeCount(shape, p);
    double length = 0;  // longest chain of floating-point sums a coefficient goes through
    switch (shape) {
        case CellShape::Hex: length = 3 * (p + 1); break;
        case CellShape::Tet:
            t->simplex = ToMatrix(SimplexTransform(p, 3), n, n);
            length = n;
            break;
        case CellShape::Wedge: {
            const int n2 = (p + 1) * (p + 2) / 2;
            t->simplex = ToMatrix(SimplexTransform(p, 2), n2, n2);
            length = n2 + (p + 1);
            break;
        }
        case CellShape::Pyramid: {
            for (int k = 0; k <= p; ++k) {
                const int q = p - k;
                std::vector<LD> a(static_cast<std::size_t>(p + 1) * (q + 1));
                for (int i = 0; i <= q; ++i) {
                    std::vector<LD> vals(p + 1);
                    for (int j = 0; j <= p; ++j) {
                        const LD x = static_cast<LD>(j) / p;
                        // l^(q)_i(x) = S^q_i(x) S^q_{q-i}(1 - x); q = 0: the constant 1.
                        vals[j] = q == 0 ? 1.0L : Silvester(q, i, x) * Silvester(q, q - i, 1 - x);
                    }
                    const auto bern = BernsteinOfValues(t->line, vals);
                    for (int r = 0; r <= p; ++r) a[static_cast<std::size_t>(r) * (q + 1) + i] = bern[r];
                }
                t->aBern.push_back(ToMatrix(a, p + 1, q + 1));
                std::vector<LD> vals(p + 1);
                for (int j = 0; j <= p; ++j) {
                    const LD c = static_cast<LD>(j) / p;
                    const LD w = q == 0 ? 1.0L : PowInt((1.0L - c) * p / q, q);
                    vals[j] = w * Silvester(p, k, c);
                }
                const auto bern = BernsteinOfValues(t->line, vals);
                std::vector<double> cb, cba;
                for (LD v : bern) {
                    cb.push_back(static_cast<double>(v));
                    cba.push_back(std::abs(static_cast<double>(v)));
                }
                t->cBern.push_back(cb);
                t->cBernAbs.push_back(cba);
            }
            length = n + 3 * (p + 1);
            break;
        }
    }
    // n u per length-n sum, the stored transforms' rounding, and a factor 4 of slack.
    t->gamma = 4.0 * (length + 16.0) * kUnit;
    return t;
}

const BernsteinTable& GetTable(CellShape shape, int order) {
    // Tables live as long as the process; each thread remembers those it has seen.
    const int slot = static_cast<int>(shape) * (kMaxOrder + 1) + order;
    thread_local std::array<const BernsteinTable*, kNumCellShapes * (kMaxOrder + 1)> seen{};
    const bool cacheable = order >= 0 && order <= kMaxOrder;
    if (cacheable && seen[slot]) return *seen[slot];
    static std::mutex mutex;
    static std::map<std::pair<int, int>, std::unique_ptr<BernsteinTable>> cache;
    std::lock_guard<std::mutex> lock(mutex);
    auto key = std::make_pair(static_cast<int>(shape), order);
    auto it = cache.find(key);
    if (it == cache.end()) it = cache.emplace(key, BuildTable(shape, order)).first;
    if (cacheable) seen[slot] = it->second.get();
    return *it->second;
}

// y = M x and ay = |M| ax along one axis of a 3-D array of extent n1 per axis.
void ApplyAxis(const Matrix& m, int n1, int axis, std::vector<double>& x,
               std::vector<double>& ax) {
    const int stride = axis == 0 ? 1 : (axis == 1 ? n1 : n1 * n1);
    const int outerStride = axis == 2 ? n1 : n1 * n1;  // the remaining two axes
    const int innerStride = axis == 0 ? n1 : 1;
    double in[kMaxOrder + 1], ain[kMaxOrder + 1];
    for (int o = 0; o < n1; ++o)
        for (int i = 0; i < n1; ++i) {
            const int base = o * outerStride + i * innerStride;
            for (int l = 0; l < n1; ++l) {
                in[l] = x[base + l * stride];
                ain[l] = ax[base + l * stride];
            }
            for (int r = 0; r < n1; ++r) {
                double s = 0.0, as = 0.0;
                for (int l = 0; l < n1; ++l) {
                    s += m.v[r * n1 + l] * in[l];
                    as += m.abs[r * n1 + l] * ain[l];
                }
                x[base + r * stride] = s;
                ax[base + r * stride] = as;
            }
        }
}

// Row r of a simplex's Lagrange-to-Bernstein transform applied to f (s) and its absolute
// value to af (as), summed in column order.
inline void SimplexRow(const BernsteinTable& t, int n, int r, const double* f,
                       const double* af, double& s, double& as) {
    s = 0.0;
    as = 0.0;
    const double* row = t.simplex.v.data() + static_cast<std::size_t>(r) * n;
    const double* arow = t.simplex.abs.data() + static_cast<std::size_t>(r) * n;
    for (int c = 0; c < n; ++c) {
        s += row[c] * f[c];
        as += arow[c] * af[c];
    }
}

// Bernstein coefficients (and |T| |f|) of order-p Lagrange nodal values of a shape.
// `af` bounds |f| entry-wise (it may be larger, to carry the input's own error bound).
void Bernstein(const BernsteinTable& t, const BasisTable& basis, const std::vector<double>& f,
               const std::vector<double>& af, std::vector<double>& out,
               std::vector<double>& outAbs) {
    const int p = t.p, n1 = p + 1;
    const int n = static_cast<int>(f.size());
    switch (t.shape) {
        case CellShape::Hex:
            out = f;
            outAbs = af;
            for (int axis = 0; axis < 3; ++axis) ApplyAxis(t.m1, n1, axis, out, outAbs);
            return;
        case CellShape::Tet:
            out.assign(n, 0.0);
            outAbs.assign(n, 0.0);
            for (int r = 0; r < n; ++r)
                SimplexRow(t, n, r, f.data(), af.data(), out[r], outAbs[r]);
            return;
        case CellShape::Wedge: {
            const int n2 = t.simplex.rows;
            std::vector<double> tmp(n), atmp(n);
            for (int k = 0; k < n1; ++k)
                for (int r = 0; r < n2; ++r) {
                    double s = 0.0, as = 0.0;
                    for (int c = 0; c < n2; ++c) {
                        s += t.simplex.v[r * n2 + c] * f[k * n2 + c];
                        as += t.simplex.abs[r * n2 + c] * af[k * n2 + c];
                    }
                    tmp[k * n2 + r] = s;
                    atmp[k * n2 + r] = as;
                }
            out.assign(n, 0.0);
            outAbs.assign(n, 0.0);
            for (int r = 0; r < n2; ++r)
                for (int k = 0; k < n1; ++k) {
                    double s = 0.0, as = 0.0;
                    for (int l = 0; l < n1; ++l) {
                        s += t.m1.v[k * n1 + l] * tmp[l * n2 + r];
                        as += t.m1.abs[k * n1 + l] * atmp[l * n2 + r];
                    }
                    out[k * n2 + r] = s;
                    outAbs[k * n2 + r] = as;
                }
            return;
        }
        case CellShape::Pyramid: {
            // alpha = C f (coefficients of the level functions psi), block-triangular C.
            std::vector<double> alpha(n), aAlpha(n);
            int l = 0;
            for (int k = 0; k <= p; ++k)
                for (; l < basis.levelEnd[k]; ++l) {
                    const double* row = basis.psiToNodal.data() + static_cast<std::size_t>(l) * n;
                    double s = 0.0, as = 0.0;
                    for (int m = 0; m < basis.levelEnd[k]; ++m) {
                        s += row[m] * f[m];
                        as += std::abs(row[m]) * af[m];
                    }
                    alpha[l] = s;
                    aAlpha[l] = as;
                }
            out.assign(n1 * n1 * n1, 0.0);
            outAbs.assign(n1 * n1 * n1, 0.0);
            std::vector<double> t1, at1, t2(n1 * n1), at2(n1 * n1);
            int start = 0;
            for (int k = 0; k <= p; ++k) {
                const int q = p - k, nq = q + 1;
                const Matrix& a = t.aBern[k];
                // t1[j][r] = sum_i a[r][i] alpha[k][j][i]
                t1.assign(nq * n1, 0.0);
                at1.assign(nq * n1, 0.0);
                for (int j = 0; j < nq; ++j)
                    for (int r = 0; r < n1; ++r) {
                        double s = 0.0, as = 0.0;
                        for (int i = 0; i < nq; ++i) {
                            s += a.v[r * nq + i] * alpha[start + j * nq + i];
                            as += a.abs[r * nq + i] * aAlpha[start + j * nq + i];
                        }
                        t1[j * n1 + r] = s;
                        at1[j * n1 + r] = as;
                    }
                // t2[b][r] = sum_j a[b][j] t1[j][r]
                for (int b = 0; b < n1; ++b)
                    for (int r = 0; r < n1; ++r) {
                        double s = 0.0, as = 0.0;
                        for (int j = 0; j < nq; ++j) {
                            s += a.v[b * nq + j] * t1[j * n1 + r];
                            as += a.abs[b * nq + j] * at1[j * n1 + r];
                        }
                        t2[b * n1 + r] = s;
                        at2[b * n1 + r] = as;
                    }
                for (int c = 0; c < n1; ++c) {
                    const double w = t.cBern[k][c], aw = t.cBernAbs[k][c];
                    if (w == 0.0) continue;
                    for (int i = 0; i < n1 * n1; ++i) {
                        out[c * n1 * n1 + i] += w * t2[i];
                        outAbs[c * n1 * n1 + i] += aw * at2[i];
                    }
                }
                start += nq * nq;
            }
            return;
        }
    }
}

// std::nextafter(x, +-inf), inlined (called four times per bound, for every cell): the
// same result for every x, NaN and infinities included.
inline double NextUp(double x) {
    if (std::isnan(x) || x == std::numeric_limits<double>::infinity()) return x;
    if (x == 0) return std::numeric_limits<double>::denorm_min();
    std::uint64_t b;
    std::memcpy(&b, &x, sizeof b);
    b = x > 0 ? b + 1 : b - 1;
    std::memcpy(&x, &b, sizeof b);
    return x;
}
inline double NextDown(double x) { return -NextUp(-x); }

// Lagrange tetrahedra of up to this many nodes (order 4) are bounded from stack arrays.
constexpr int kSmallTetNodes = 35;

// Bounds of a Lagrange tetrahedron with at most kSmallTetNodes nodes: the same operations
// in the same order as the general path below (so bitwise the same interval), without its
// scratch vectors.
template <int kFixed>
Interval SmallTetBoundsN(const BasisTable& basis, const double* coeffsIn, int stride) {
    const int n = kFixed > 0 ? kFixed : basis.nodeCount;
    double nodalLo = std::numeric_limits<double>::infinity(), nodalHi = -nodalLo;
    for (int m = 0; m < n; ++m) {
        nodalLo = std::min(nodalLo, coeffsIn[m * stride]);
        nodalHi = std::max(nodalHi, coeffsIn[m * stride]);
    }
    const double shift = 0.5 * nodalLo + 0.5 * nodalHi;
    double f[kSmallTetNodes], af[kSmallTetNodes];
    for (int m = 0; m < n; ++m) {
        f[m] = coeffsIn[m * stride] - shift;
        af[m] = std::abs(f[m]);
    }
    const BernsteinTable& t = GetTable(basis.shape, basis.order);
    const double gamma = t.gamma + 0.0 + 2.0 * kUnit;
    const double inf = std::numeric_limits<double>::infinity();
    Interval out{inf, -inf};
    for (int r = 0; r < n; ++r) {
        double s, as;
        SimplexRow(t, n, r, f, af, s, as);
        const double margin = gamma * as;
        out.lo = std::min(out.lo, s - margin);
        out.hi = std::max(out.hi, s + margin);
    }
    out.lo = NextDown(NextDown(out.lo + shift));
    out.hi = NextUp(NextUp(out.hi + shift));
    return out;
}

// The linear tetrahedron (a fixed size: loops unrolled) or any other small one.
Interval SmallTetBounds(const BasisTable& basis, const double* coeffsIn, int stride) {
    return basis.nodeCount == 4 ? SmallTetBoundsN<4>(basis, coeffsIn, stride)
                                : SmallTetBoundsN<0>(basis, coeffsIn, stride);
}

Interval Bounds(const BasisTable& basis, const double* coeffsIn, int stride) {
    if (basis.shape == CellShape::Tet && basis.family != CellFamily::Serendipity &&
        basis.nodeCount <= kSmallTetNodes)
        return SmallTetBounds(basis, coeffsIn, stride);
    // Constants are reproduced exactly by both bases, so transform f - shift and add the
    // shift back: the rounding margin then scales with the variation of the data, not
    // with its offset (fields like 1e6 + O(1)).
    double nodalLo = std::numeric_limits<double>::infinity(), nodalHi = -nodalLo;
    for (int m = 0; m < basis.nodeCount; ++m) {
        nodalLo = std::min(nodalLo, coeffsIn[m * stride]);
        nodalHi = std::max(nodalHi, coeffsIn[m * stride]);
    }
    const double shift = 0.5 * nodalLo + 0.5 * nodalHi;
    // Scratch of this thread: called for every cell at load, three times for its box
    // and once per field, so no allocation per call.
    thread_local std::vector<double> shifted, f, af, b, ab;
    shifted.resize(basis.nodeCount);
    for (int m = 0; m < basis.nodeCount; ++m) shifted[m] = coeffsIn[m * stride] - shift;
    // The subtraction rounds: |error| <= u |f - shift| per entry, carried below.
    const double* coeffs = shifted.data();
    stride = 1;
    const BasisTable* full = &basis;
    double gammaInput = 0.0;
    if (basis.family == CellFamily::Serendipity) {
        // Exact expansion to the order-2 Lagrange space that contains the serendipity
        // space; the dyadic corrections are exact, only the sums round: |error| <=
        // gammaInput * sum |c f|, which the absolute path carries.
        full = basis.full;
        f.assign(full->nodeCount, 0.0);
        af.assign(full->nodeCount, 0.0);
        for (int m = 0; m < basis.nodeCount; ++m) {
            f[basis.fullIndex[m]] = coeffs[m * stride];
            af[basis.fullIndex[m]] = std::abs(coeffs[m * stride]);
        }
        for (std::size_t r = 0; r < basis.dropped.size(); ++r) {
            double s = 0.0, as = 0.0;
            for (int m = 0; m < basis.nodeCount; ++m) {
                const double c = basis.correction[r * basis.nodeCount + m];
                s += c * coeffs[m * stride];
                as += std::abs(c * coeffs[m * stride]);
            }
            f[basis.dropped[r]] = s;
            af[basis.dropped[r]] = as;
        }
        gammaInput = 2.0 * (basis.nodeCount + 2) * kUnit;
    } else {
        f.resize(basis.nodeCount);
        af.resize(basis.nodeCount);
        for (int m = 0; m < basis.nodeCount; ++m) {
            f[m] = coeffs[m * stride];
            af[m] = std::abs(f[m]);
        }
    }
    const BernsteinTable& t = GetTable(full->shape, full->order);
    Bernstein(t, *full, f, af, b, ab);
    const double gamma = t.gamma + gammaInput + 2.0 * kUnit;
    const double inf = std::numeric_limits<double>::infinity();
    Interval out{inf, -inf};
    for (std::size_t k = 0; k < b.size(); ++k) {
        const double margin = gamma * ab[k];
        out.lo = std::min(out.lo, b[k] - margin);
        out.hi = std::max(out.hi, b[k] + margin);
    }
    // Adding the shift rounds once more (half an ulp): step outward twice.
    out.lo = NextDown(NextDown(out.lo + shift));
    out.hi = NextUp(NextUp(out.hi + shift));
    return out;
}

}  // namespace

namespace {
// out = a b for n x n row-major matrices, computed in extended precision and rounded to
// double; returns the largest absolute row sum of out.
double RoundedProduct(const std::vector<LD>& a, const std::vector<LD>& b, int n,
                      double* out) {
    double worst = 0;
    for (int r = 0; r < n; ++r) {
        double sum = 0;
        for (int c = 0; c < n; ++c) {
            LD v = 0;
            for (int k = 0; k < n; ++k)
                v += a[static_cast<std::size_t>(r) * n + k] *
                     b[static_cast<std::size_t>(k) * n + c];
            out[static_cast<std::size_t>(r) * n + c] = static_cast<double>(v);
            sum += std::abs(out[static_cast<std::size_t>(r) * n + c]);
        }
        worst = std::max(worst, sum);
    }
    return worst;
}
}  // namespace

namespace {
// The table of key (a, b), built by `build` the first time any thread asks and kept for
// the life of the process; each thread remembers those it has seen (at `slot` < Slots),
// so later lookups take no lock.
template <typename T, int Slots, typename Build>
const T& CachedTable(int a, int b, int slot, Build&& build) {
    thread_local std::array<const T*, Slots> seen{};
    const T*& mine = seen[slot];
    if (mine) return *mine;
    static std::mutex mutex;
    static std::map<std::pair<int, int>, std::unique_ptr<T>> cache;
    std::lock_guard<std::mutex> lock(mutex);
    std::unique_ptr<T>& entry = cache[{a, b}];
    if (!entry) entry = build();
    return *(mine = entry.get());
}
}  // namespace

namespace {
// HexSubBounds' 1-D matrices for order p and n pieces: row (k (p + 1) + a) gives
// Bernstein coefficient a, on [k / n, (k + 1) / n], of the interpolant of the p + 1
// equispaced nodal values on [0, 1] (the line transform applied to the Lagrange basis at
// the piece's own equispaced nodes, in extended precision), and the largest absolute row
// sum.
struct SubdivisionTable {
    std::vector<double> m;
    double rowSum = 0;
};

std::unique_ptr<SubdivisionTable> BuildSubdivisionTable(int p, int n) {
    auto t = std::make_unique<SubdivisionTable>();
    const int q = p + 1;
    const std::vector<LD> line = LineTransform(p);  // bern_a = sum_i line[a][i] f(i / p)
    t->m.resize(static_cast<std::size_t>(n) * q * q);
    for (int k = 0; k < n; ++k) {
        // e[i][j] = l_j(y_i), y_i = (k + i / p) / n: the piece's nodal values from the
        // cell's.
        std::vector<LD> e(static_cast<std::size_t>(q) * q);
        for (int i = 0; i < q; ++i) {
            const LD y = (static_cast<LD>(k) + static_cast<LD>(i) / p) / n;
            for (int j = 0; j < q; ++j) {
                LD l = 1;
                for (int m = 0; m < q; ++m)
                    if (m != j)
                        l *= (y - static_cast<LD>(m) / p) /
                             (static_cast<LD>(j) / p - static_cast<LD>(m) / p);
                e[static_cast<std::size_t>(i) * q + j] = l;
            }
        }
        t->rowSum = std::max(
            t->rowSum,
            RoundedProduct(line, e, q, &t->m[static_cast<std::size_t>(k) * q * q]));
    }
    return t;
}

const SubdivisionTable& GetSubdivisionTable(int p, int n) {
    return CachedTable<SubdivisionTable, (kMaxOrder + 1) * (kMaxSubdivision + 1)>(
        p, n, p * (kMaxSubdivision + 1) + n, [&] { return BuildSubdivisionTable(p, n); });
}
}  // namespace

namespace {
// HexSubBounds for Q = p + 1 nodes per direction, known at compile time so that the sums
// over the nodes unroll and the passes over whole rows vectorise.
template <int Q>
void HexSubBoundsFixed(const SubdivisionTable& t, int n, const double* coeffs, int comps,
                       Interval* out) {
    constexpr double inf = std::numeric_limits<double>::infinity();
    const int w = n * Q;
    const double* m = t.m.data();  // (n Q) x Q
    thread_local std::vector<double> a, b;
    a.resize(static_cast<std::size_t>(w) * Q * Q);
    b.resize(static_cast<std::size_t>(w) * w * Q);
    // Three sums of Q terms, the tables' own rounding, and a factor 4 of slack: every
    // computed coefficient is within gamma (|M| x |M| x |M|) |u| <= gamma R^3 max |u| of
    // the exact one.
    const double gamma = 4.0 * (3.0 * Q + 16.0) * kUnit;
    const double r3 = t.rowSum * t.rowSum * t.rowSum;
    for (int comp = 0; comp < comps; ++comp) {
        double maxAbs = 0, u[Q * Q * Q];
        bool finite = true;
        for (int v = 0; v < Q * Q * Q; ++v) {
            u[v] = coeffs[static_cast<std::size_t>(v) * comps + comp];
            finite = finite && std::isfinite(u[v]);
            maxAbs = std::max(maxAbs, std::abs(u[v]));
        }
        if (!finite) {
            for (int box = 0; box < n * n * n; ++box)
                out[static_cast<std::size_t>(box) * comps + comp] = {-inf, inf};
            continue;
        }
        // Along r: a[X + w (j + Q l)], then s: b[X + w (Y + w l)], then t.
        for (int jl = 0; jl < Q * Q; ++jl) {
            const double* row = u + Q * jl;
            double* dst = &a[static_cast<std::size_t>(w) * jl];
            for (int x = 0; x < w; ++x) {
                double sum = 0;
                for (int i = 0; i < Q; ++i) sum = std::fma(m[x * Q + i], row[i], sum);
                dst[x] = sum;
            }
        }
        for (int l = 0; l < Q; ++l)
            for (int y = 0; y < w; ++y) {
                double f[Q];
                for (int j = 0; j < Q; ++j) f[j] = m[y * Q + j];
                double* dst = &b[static_cast<std::size_t>(w) * (y + w * l)];
                const double* src = &a[static_cast<std::size_t>(w) * Q * l];
                for (int x = 0; x < w; ++x) {
                    double sum = 0;
                    for (int j = 0; j < Q; ++j) sum = std::fma(f[j], src[w * j + x], sum);
                    dst[x] = sum;
                }
            }
        // Along t, each row of coefficients straight into its boxes' ranges (no third
        // array), kept per lane and reduced once per slab of boxes.
        const int plane = w * w;
        double lo[kMaxSubdivision * kMaxSubdivision],
            hi[kMaxSubdivision * kMaxSubdivision];
        const double widen = gamma * r3 * maxAbs;
        for (int k2 = 0; k2 < n; ++k2) {
            double laneLo[kMaxSubdivision][kMaxSubdivision * Q],
                laneHi[kMaxSubdivision][kMaxSubdivision * Q];
            for (int k1 = 0; k1 < n; ++k1)
                for (int x = 0; x < w; ++x) laneLo[k1][x] = inf, laneHi[k1][x] = -inf;
            for (int z = k2 * Q; z < k2 * Q + Q; ++z) {
                double f[Q];
                for (int l = 0; l < Q; ++l) f[l] = m[z * Q + l];
                for (int y = 0; y < w; ++y) {
                    const double* src = &b[static_cast<std::size_t>(w) * y];
                    double row[kMaxSubdivision * Q];
                    for (int x = 0; x < w; ++x) row[x] = 0;
                    for (int l = 0; l < Q; ++l)
                        for (int x = 0; x < w; ++x)
                            row[x] = std::fma(f[l], src[plane * l + x], row[x]);
                    double* rl = laneLo[y / Q];
                    double* rh = laneHi[y / Q];
                    for (int x = 0; x < w; ++x) {
                        rl[x] = std::min(rl[x], row[x]);
                        rh[x] = std::max(rh[x], row[x]);
                    }
                }
            }
            for (int k1 = 0; k1 < n; ++k1)
                for (int k0 = 0; k0 < n; ++k0) {
                    double bl = inf, bh = -inf;
                    for (int x = k0 * Q; x < k0 * Q + Q; ++x) {
                        bl = std::min(bl, laneLo[k1][x]);
                        bh = std::max(bh, laneHi[k1][x]);
                    }
                    lo[k0 + n * k1] = bl;
                    hi[k0 + n * k1] = bh;
                }
            for (int k1 = 0; k1 < n; ++k1)
                for (int k0 = 0; k0 < n; ++k0) {
                    const double l0 = lo[k0 + n * k1], h0 = hi[k0 + n * k1];
                    Interval& o =
                        out[static_cast<std::size_t>(k0 + n * (k1 + n * k2)) * comps +
                            comp];
                    // Outward by the margin, and by a few ulps more for the rounding of
                    // that.
                    o.lo = l0 - (widen + 4 * kUnit * std::abs(l0));
                    o.hi = h0 + (widen + 4 * kUnit * std::abs(h0));
                    if (!(std::isfinite(o.lo) && std::isfinite(o.hi))) {
                        o.lo = -inf;
                        o.hi = inf;
                    }
                }
        }
    }
}

using SubBoundsKernel = void (*)(const SubdivisionTable&, int, const double*, int,
                                 Interval*);
template <int... Qs>
constexpr std::array<SubBoundsKernel, kMaxOrder + 2> SubBoundsKernels(
    std::integer_sequence<int, Qs...>) {
    return {nullptr, nullptr, &HexSubBoundsFixed<Qs + 2>...};
}
constexpr auto kSubBoundsKernels =
    SubBoundsKernels(std::make_integer_sequence<int, kMaxOrder>{});
}  // namespace

void HexSubBounds(int p, int n, const double* coeffs, int comps, Interval* out) {
    HPRAY_CHECK(p >= 1 && p <= kMaxOrder && n >= 1 && n <= kMaxSubdivision);
    kSubBoundsKernels[p + 1](GetSubdivisionTable(p, n), n, coeffs, comps, out);
}

namespace {
// TetSubBounds' tables for one order and depth: the corners of the 8^levels
// sub-tetrahedra (uniform refinement of each child into its 4 corner tetrahedra and the 4
// of its inner octahedron, cut along one diagonal), and for each sub-tetrahedron s the
// matrix M_s (n x n, row-major) that takes a Lagrange tetrahedron's nodal values,
// internal order, to the Bernstein coefficients of its interpolant restricted to s: the
// simplex transform applied to the Lagrange basis at s's own lattice points, in extended
// precision.
struct TetSubdivisionTable {
    int count = 0, n = 0;
    std::vector<double> m;
    double rowSum = 0;
};

using Corner = std::array<LD, 3>;
using SubTet = std::array<Corner, 4>;

std::vector<SubTet> RefineTets(const std::vector<SubTet>& in) {
    std::vector<SubTet> out;
    for (const SubTet& t : in) {
        auto mid = [&](int a, int b) {
            Corner c;
            for (int d = 0; d < 3; ++d) c[d] = (t[a][d] + t[b][d]) / 2;
            return c;
        };
        const Corner x01 = mid(0, 1), x02 = mid(0, 2), x03 = mid(0, 3), x12 = mid(1, 2),
                     x13 = mid(1, 3), x23 = mid(2, 3);
        out.push_back({t[0], x01, x02, x03});
        out.push_back({x01, t[1], x12, x13});
        out.push_back({x02, x12, t[2], x23});
        out.push_back({x03, x13, x23, t[3]});
        // The octahedron x01 x02 x03 x12 x13 x23, cut along the diagonal x02 - x13.
        out.push_back({x01, x02, x03, x13});
        out.push_back({x01, x02, x12, x13});
        out.push_back({x02, x03, x13, x23});
        out.push_back({x02, x12, x13, x23});
    }
    return out;
}

std::unique_ptr<TetSubdivisionTable> BuildTetSubdivisionTable(const BasisTable& basis,
                                                              int levels) {
    const int p = basis.order;
    auto t = std::make_unique<TetSubdivisionTable>();
    const int n = basis.nodeCount;
    const std::vector<LD> simplex = SimplexTransform(p, 3);  // lattice order -> Bernstein
    std::vector<SubTet> tets = {
        SubTet{Corner{0, 0, 0}, Corner{1, 0, 0}, Corner{0, 1, 0}, Corner{0, 0, 1}}};
    for (int l = 0; l < levels; ++l) tets = RefineTets(tets);
    t->count = static_cast<int>(tets.size());
    t->n = n;
    t->m.resize(static_cast<std::size_t>(t->count) * n * n);
    // Silvester's form of the equispaced Lagrange basis: node (i, j, k) of order p with
    // barycentric indices a = (p - i - j - k, i, j, k) is prod_m prod_{q < a_m}
    // (p lambda_m - q) / (q + 1).
    auto basisAt = [&](const Corner& y, std::vector<LD>& phi) {
        const LD lambda[4] = {1 - y[0] - y[1] - y[2], y[0], y[1], y[2]};
        for (int m = 0; m < n; ++m) {
            const auto& ijk = basis.lattice[m];
            const int a[4] = {p - ijk[0] - ijk[1] - ijk[2], ijk[0], ijk[1], ijk[2]};
            LD v = 1;
            for (int b = 0; b < 4; ++b)
                for (int q = 0; q < a[b]; ++q) v *= (p * lambda[b] - q) / (q + 1);
            phi[m] = v;
        }
    };
    std::vector<LD> e(static_cast<std::size_t>(n) * n), phi(n);
    for (int s = 0; s < t->count; ++s) {
        const SubTet& st = tets[s];
        // Rows: the sub-tetrahedron's lattice points in lattice order (k, then j, then
        // i).
        int r = 0;
        for (int k = 0; k <= p; ++k)
            for (int j = 0; j + k <= p; ++j)
                for (int i = 0; i + j + k <= p; ++i, ++r) {
                    Corner y;
                    for (int d = 0; d < 3; ++d)
                        y[d] = st[0][d] + (st[1][d] - st[0][d]) * i / p +
                               (st[2][d] - st[0][d]) * j / p +
                               (st[3][d] - st[0][d]) * k / p;
                    basisAt(y, phi);
                    for (int m = 0; m < n; ++m)
                        e[static_cast<std::size_t>(r) * n + m] = phi[m];
                }
        t->rowSum = std::max(
            t->rowSum,
            RoundedProduct(simplex, e, n, &t->m[static_cast<std::size_t>(s) * n * n]));
    }
    return t;
}

const TetSubdivisionTable& GetTetSubdivisionTable(const BasisTable& basis, int levels) {
    const int p = basis.order;
    return CachedTable<TetSubdivisionTable, (kMaxOrder + 1) * 3>(
        p, levels, p * 3 + levels,
        [&] { return BuildTetSubdivisionTable(basis, levels); });
}
}  // namespace

int TetSubCount(int levels) { return levels == 0 ? 1 : 8 * TetSubCount(levels - 1); }

void TetSubBounds(const BasisTable& basis, int levels, const double* coeffs, int comps,
                  Interval* out) {
    HPRAY_CHECK(basis.kind == BasisKind::TetLagrange && levels >= 0 && levels <= 2);
    constexpr double inf = std::numeric_limits<double>::infinity();
    const TetSubdivisionTable& t = GetTetSubdivisionTable(basis, levels);
    const int n = t.n;
    // One sum of n terms, the table's own rounding, and a factor 4 of slack: each
    // computed coefficient is within gamma |M| |u| <= gamma R max |u| of the exact one.
    const double gamma = 4.0 * (n + 16.0) * kUnit;
    // Four components at a time, one per vector lane (node coordinates and a field
    // together), and four rows at a time: independent sums that keep the units busy.
    for (int c0 = 0; c0 < comps; c0 += 4) {
        const int cn = std::min(4, comps - c0);
        // (Only the n rows used are written: zeroing the whole array cost more than the
        // products for small cells.)
        alignas(32) double u[kMaxBasisNodes][4];
        double maxAbs[4] = {0, 0, 0, 0};
        bool finite[4] = {true, true, true, true};
        for (int m = 0; m < n; ++m)
            for (int c = 0; c < 4; ++c) {
                const double v =
                    c < cn ? coeffs[static_cast<std::size_t>(m) * comps + c0 + c] : 0.0;
                u[m][c] = v;
                finite[c] = finite[c] && std::isfinite(v);
                maxAbs[c] = std::max(maxAbs[c], std::abs(v));
            }
        for (int s = 0; s < t.count; ++s) {
            const double* m = t.m.data() + static_cast<std::size_t>(s) * n * n;
            double lo[4] = {inf, inf, inf, inf}, hi[4] = {-inf, -inf, -inf, -inf};
            int a = 0;
#if defined(__AVX2__) && defined(__FMA__)
            __m256d vlo = _mm256_set1_pd(inf), vhi = _mm256_set1_pd(-inf);
            for (; a + 4 <= n; a += 4) {
                const double* m0 = m + a * n;
                __m256d s0 = _mm256_setzero_pd(), s1 = s0, s2 = s0, s3 = s0;
                for (int q = 0; q < n; ++q) {
                    const __m256d uq = _mm256_load_pd(u[q]);
                    s0 = _mm256_fmadd_pd(_mm256_set1_pd(m0[q]), uq, s0);
                    s1 = _mm256_fmadd_pd(_mm256_set1_pd(m0[n + q]), uq, s1);
                    s2 = _mm256_fmadd_pd(_mm256_set1_pd(m0[2 * n + q]), uq, s2);
                    s3 = _mm256_fmadd_pd(_mm256_set1_pd(m0[3 * n + q]), uq, s3);
                }
                vlo = _mm256_min_pd(
                    vlo, _mm256_min_pd(_mm256_min_pd(s0, s1), _mm256_min_pd(s2, s3)));
                vhi = _mm256_max_pd(
                    vhi, _mm256_max_pd(_mm256_max_pd(s0, s1), _mm256_max_pd(s2, s3)));
            }
            _mm256_storeu_pd(lo, vlo);
            _mm256_storeu_pd(hi, vhi);
#else
            for (; a + 4 <= n; a += 4) {
                double sum[4][4] = {};
                for (int q = 0; q < n; ++q)
                    for (int r = 0; r < 4; ++r)
                        for (int c = 0; c < 4; ++c)
                            sum[r][c] = std::fma(m[(a + r) * n + q], u[q][c], sum[r][c]);
                for (int r = 0; r < 4; ++r)
                    for (int c = 0; c < 4; ++c) {
                        lo[c] = std::min(lo[c], sum[r][c]);
                        hi[c] = std::max(hi[c], sum[r][c]);
                    }
            }
#endif
            for (; a < n; ++a) {
                double sum[4] = {};
                for (int q = 0; q < n; ++q)
                    for (int c = 0; c < 4; ++c)
                        sum[c] = std::fma(m[a * n + q], u[q][c], sum[c]);
                for (int c = 0; c < 4; ++c) {
                    lo[c] = std::min(lo[c], sum[c]);
                    hi[c] = std::max(hi[c], sum[c]);
                }
            }
            for (int c = 0; c < cn; ++c) {
                Interval& o = out[static_cast<std::size_t>(s) * comps + c0 + c];
                if (!finite[c]) {
                    o = {-inf, inf};
                    continue;
                }
                const double widen = gamma * t.rowSum * maxAbs[c];
                o.lo = lo[c] - (widen + 4 * kUnit * std::abs(lo[c]));
                o.hi = hi[c] + (widen + 4 * kUnit * std::abs(hi[c]));
            }
        }
    }
}

Interval FieldBounds(const BasisTable& basis, const double* coeffs, int stride) {
    return Bounds(basis, coeffs, stride);
}

Box GeometryBox(const BasisTable& basis, const double* nodeXyz) {
    Box box;
    for (int d = 0; d < 3; ++d) {
        const Interval i = Bounds(basis, nodeXyz + d, 3);
        box.lo[d] = i.lo;
        box.hi[d] = i.hi;
    }
    return box;
}

Box GeometryBoxEnclosure(const BasisTable& basis, const double* nodeXyz) {
    const double inf = std::numeric_limits<double>::infinity();
    Box box{{-inf, -inf, -inf}, {inf, inf, inf}};
    if (basis.shape != CellShape::Tet || basis.family == CellFamily::Serendipity ||
        basis.nodeCount > kSmallTetNodes)
        return box;
    // R: the largest sum of |T| over a row of the Lagrange-to-Bernstein transform (1 for
    // the linear tetrahedron), remembered per basis on each thread.
    thread_local const BasisTable* seen = nullptr;
    thread_local double rowSum = 0;
    if (seen != &basis) {
        const BernsteinTable& t = GetTable(basis.shape, basis.order);
        const int n = basis.nodeCount;
        double worst = 0;
        for (int r = 0; r < n; ++r) {
            double sum = 0;
            for (int c = 0; c < n; ++c) sum += t.simplex.abs[std::size_t(r) * n + c];
            worst = std::max(worst, sum);
        }
        seen = &basis;
        rowSum = worst;
    }
    // Bounds (SmallTetBounds): with the shift s in [lo, hi], every |f - s| <= hi - lo,
    // every Bernstein coefficient and its margin (gamma < 1e-10) stay within (1 + gamma)
    // R (hi - lo) of 0 up to a few ulps, and adding s back and stepping outward twice
    // costs a few ulps of |lo| + |hi| + that more: 2.1 R (hi - lo) plus 1e-12 of the
    // magnitudes covers it all with a wide margin (also the rounding of lo - w itself).
    for (int d = 0; d < 3; ++d) {
        double lo = nodeXyz[d], hi = nodeXyz[d];
        for (int m = 1; m < basis.nodeCount; ++m) {
            lo = std::min(lo, nodeXyz[3 * m + d]);
            hi = std::max(hi, nodeXyz[3 * m + d]);
        }
        const double w =
            2.1 * rowSum * (hi - lo) + 1e-12 * (std::abs(lo) + std::abs(hi)) + 1e-300;
        box.lo[d] = lo - w;
        box.hi[d] = hi + w;
    }
    return box;
}

}  // namespace hpray
