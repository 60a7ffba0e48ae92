// Nodal bases of every cell of the mesh model (see basis.h for the spaces and the proofs).
#include "elements/basis.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <mutex>
#include <tuple>

#include "elements/silvester.h"
#include "util/check.h"

namespace hpray {
namespace {

constexpr int kMaxPyramidNodes =
    (kMaxOrder + 1) * (kMaxOrder + 2) * (2 * kMaxOrder + 3) / 6;

// 1-D equispaced Lagrange polynomials of degree p on [0, 1]: l_i(x) = S_i(x) S_{p-i}(1-x).
template <typename Real>
inline void Lagrange1D(int p, Real x, Real* l, Real* dl) {
    Real a[kMaxOrder + 1], da[kMaxOrder + 1], b[kMaxOrder + 1], db[kMaxOrder + 1];
    Silvester<Real>(p, x, a, da);
    Silvester<Real>(p, Real(1) - x, b, db);
    for (int i = 0; i <= p; ++i) {
        l[i] = a[i] * b[p - i];
        dl[i] = da[i] * b[p - i] - a[i] * db[p - i];
    }
}

void EvalHex(int p, const double ref[3], double* values, double* dRef) {
    double l[3][kMaxOrder + 1], dl[3][kMaxOrder + 1];
    for (int d = 0; d < 3; ++d) Lagrange1D<double>(p, ref[d], l[d], dl[d]);
    int m = 0;
    for (int k = 0; k <= p; ++k)
        for (int j = 0; j <= p; ++j) {
            const double jk = l[1][j] * l[2][k];
            if (!dRef) {
                for (int i = 0; i <= p; ++i) values[m++] = l[0][i] * jk;
                continue;
            }
            const double djk = dl[1][j] * l[2][k];
            const double jdk = l[1][j] * dl[2][k];
            for (int i = 0; i <= p; ++i, ++m) {
                values[m] = l[0][i] * jk;
                dRef[3 * m] = dl[0][i] * jk;
                dRef[3 * m + 1] = l[0][i] * djk;
                dRef[3 * m + 2] = l[0][i] * jdk;
            }
        }
}

void EvalTet(int p, const double ref[3], double* values, double* dRef) {
    double a[kMaxOrder + 1], da[kMaxOrder + 1], b[kMaxOrder + 1], db[kMaxOrder + 1];
    double c[kMaxOrder + 1], dc[kMaxOrder + 1], e[kMaxOrder + 1], de[kMaxOrder + 1];
    Silvester<double>(p, ref[0], a, da);
    Silvester<double>(p, ref[1], b, db);
    Silvester<double>(p, ref[2], c, dc);
    Silvester<double>(p, 1.0 - ref[0] - ref[1] - ref[2], e, de);
    int m = 0;
    for (int k = 0; k <= p; ++k)
        for (int j = 0; j + k <= p; ++j)
            for (int i = 0; i + j + k <= p; ++i, ++m) {
                const int l = p - i - j - k;
                const double bc = b[j] * c[k];
                values[m] = a[i] * bc * e[l];
                if (!dRef) continue;
                const double ae = a[i] * e[l];
                const double ade = a[i] * de[l];
                dRef[3 * m] = (da[i] * e[l] - ade) * bc;
                dRef[3 * m + 1] = (db[j] * c[k] * ae) - ade * bc;
                dRef[3 * m + 2] = (b[j] * dc[k] * ae) - ade * bc;
            }
}

void EvalWedge(int p, const double ref[3], double* values, double* dRef) {
    double a[kMaxOrder + 1], da[kMaxOrder + 1], b[kMaxOrder + 1], db[kMaxOrder + 1];
    double e[kMaxOrder + 1], de[kMaxOrder + 1], l[kMaxOrder + 1], dl[kMaxOrder + 1];
    Silvester<double>(p, ref[0], a, da);
    Silvester<double>(p, ref[1], b, db);
    Silvester<double>(p, 1.0 - ref[0] - ref[1], e, de);
    Lagrange1D<double>(p, ref[2], l, dl);
    int m = 0;
    for (int k = 0; k <= p; ++k)
        for (int j = 0; j <= p; ++j)
            for (int i = 0; i + j <= p; ++i, ++m) {
                const int n = p - i - j;
                const double tri = a[i] * b[j] * e[n];
                values[m] = tri * l[k];
                if (!dRef) continue;
                const double ade = a[i] * b[j] * de[n];
                dRef[3 * m] = (da[i] * b[j] * e[n] - ade) * l[k];
                dRef[3 * m + 1] = (a[i] * db[j] * e[n] - ade) * l[k];
                dRef[3 * m + 2] = tri * dl[k];
            }
}

// Collapsed coordinates of the pyramid; on the apex line (t == 1) the axis limit.
inline void Collapse(const double ref[3], double& a, double& b, double& u) {
    u = 1.0 - ref[2];
    if (u != 0.0) {
        a = (ref[0] - 0.5 * ref[2]) / u;
        b = (ref[1] - 0.5 * ref[2]) / u;
    } else {
        a = b = 0.5;
    }
}

// The level functions psi of basis.h, in node order; derivatives in (r, s, t) as three
// separate arrays dPsi[d * stride + m] (null: values only).
void EvalPyramidPsi(int p, const double ref[3], double* psi, double* dPsi, int stride) {
    double a, b, u;
    Collapse(ref, a, b, u);
    double g[kMaxOrder + 1], dg[kMaxOrder + 1];
    Silvester<double>(p, ref[2], g, dg);
    int m = 0;
    for (int k = 0; k <= p; ++k) {
        const int q = p - k;
        if (q == 0) {  // apex
            psi[m] = g[k];
            if (dPsi) {
                dPsi[m] = dPsi[stride + m] = 0.0;
                dPsi[2 * stride + m] = dg[k];
            }
            ++m;
            continue;
        }
        double la[kMaxOrder + 1], dla[kMaxOrder + 1], lb[kMaxOrder + 1], dlb[kMaxOrder + 1];
        Lagrange1D<double>(q, a, la, dla);
        Lagrange1D<double>(q, b, lb, dlb);
        const double w = u * p / q;  // 1 on level k
        double wq1 = 1.0;
        for (int n = 1; n < q; ++n) wq1 *= w;
        const double wq = wq1 * w;
        const double f = wq1 * p / q;  // w^q / u without dividing by u
        const double fg = f * g[k];
        const double tLevel = -q * fg + wq * dg[k];
        for (int j = 0; j <= q; ++j)
            for (int i = 0; i <= q; ++i, ++m) {
                const double ll = la[i] * lb[j];
                psi[m] = ll * wq * g[k];
                if (!dPsi) continue;
                const double ra = dla[i] * lb[j] * fg;
                const double sb = la[i] * dlb[j] * fg;
                dPsi[m] = ra;
                dPsi[stride + m] = sb;
                dPsi[2 * stride + m] = ra * (a - 0.5) + sb * (b - 0.5) + ll * tLevel;
            }
    }
}

// The linear pyramid: EvalPyramidPsi at p = 1 with its factors of 1 and loops unrolled
// (the same operations, so bitwise the same values; no coupling between levels).
void EvalLinearPyramid(const double ref[3], double* values, double* dRef) {
    double a, b, u;
    Collapse(ref, a, b, u);
    const double la[2] = {1.0 - a, a}, lb[2] = {1.0 - b, b};
    for (int j = 0, m = 0; j < 2; ++j)
        for (int i = 0; i < 2; ++i, ++m) {
            const double ll = la[i] * lb[j];
            values[m] = ll * u;
            if (!dRef) continue;
            const double ra = (i == 0 ? -1.0 : 1.0) * lb[j];
            const double sb = la[i] * (j == 0 ? -1.0 : 1.0);
            dRef[3 * m] = ra;
            dRef[3 * m + 1] = sb;
            dRef[3 * m + 2] = ra * (a - 0.5) + sb * (b - 0.5) + ll * -1.0;
        }
    values[4] = ref[2];
    if (dRef) {
        dRef[12] = dRef[13] = 0.0;
        dRef[14] = 1.0;
    }
}

}  // namespace

void EvalPyramidAnyOrder(const BasisTable& basis, const double ref[3], double* values,
                         double* dRef) {
    const int n = basis.nodeCount, p = basis.order;
    // Rows: value, d/dr, d/ds, d/dt; solved in place from psi to the nodal functions.
    double work[4 * kMaxPyramidNodes];
    const int rows = dRef ? 4 : 1;
    EvalPyramidPsi(p, ref, work, dRef ? work + kMaxPyramidNodes : nullptr, kMaxPyramidNodes);
    // V^T N = psi: N_kl = psi_kl - sum_{kn > kl} scale (E (x) E)^T N_kn, from the top level
    // down (the apex row block is zero below its own level).
    double tmp[(kMaxOrder + 1) * (kMaxOrder + 1)];
    for (int kl = p - 1; kl >= 0; --kl) {
        const int ql = p - kl, nl = ql + 1;
        const int offL = kl == 0 ? 0 : basis.levelEnd[kl - 1];
        for (int kn = kl + 1; kn < p; ++kn) {
            const int qn = p - kn, nn = qn + 1;
            const int offN = basis.levelEnd[kn - 1];
            const int pair = kn * (p + 1) + kl;
            const double* e = basis.coupling.data() + basis.couplingOffset[pair];
            const double scale = basis.couplingScale[pair];
            for (int row = 0; row < rows; ++row) {
                double* w = work + row * kMaxPyramidNodes;
                const double* nN = w + offN;  // N at level kn, [jn][in]
                // tmp[in][jl] = sum_jn N[jn][in] E[jn][jl]
                for (int in = 0; in < nn; ++in)
                    for (int jl = 0; jl < nl; ++jl) tmp[in * nl + jl] = 0.0;
                for (int jn = 0; jn < nn; ++jn)
                    for (int in = 0; in < nn; ++in) {
                        const double v = nN[jn * nn + in];
                        const double* er = e + jn * nl;
                        double* tr = tmp + in * nl;
                        for (int jl = 0; jl < nl; ++jl) tr[jl] += v * er[jl];
                    }
                // N_kl[jl][il] -= scale sum_in E[in][il] tmp[in][jl]
                double* nL = w + offL;
                for (int jl = 0; jl < nl; ++jl)
                    for (int in = 0; in < nn; ++in) {
                        const double t = scale * tmp[in * nl + jl];
                        const double* er = e + in * nl;
                        double* lr = nL + jl * nl;
                        for (int il = 0; il < nl; ++il) lr[il] -= t * er[il];
                    }
            }
        }
    }
    std::copy(work, work + n, values);
    if (dRef)
        for (int m = 0; m < n; ++m)
            for (int d = 0; d < 3; ++d) dRef[3 * m + d] = work[(d + 1) * kMaxPyramidNodes + m];
}

namespace {

void EvalPyramid(const BasisTable& basis, const double ref[3], double* values,
                 double* dRef) {
    if (basis.order == 1) {
        EvalLinearPyramid(ref, values, dRef);
        return;
    }
    EvalPyramidAnyOrder(basis, ref, values, dRef);
}

void EvalLagrange(const BasisTable& basis, const double ref[3], double* values,
                  double* dRef) {
    switch (basis.kind) {
        case BasisKind::TetLagrange: EvalTet(basis.order, ref, values, dRef); return;
        case BasisKind::HexLagrange: EvalHex(basis.order, ref, values, dRef); return;
        case BasisKind::WedgeLagrange: EvalWedge(basis.order, ref, values, dRef); return;
        case BasisKind::PyramidLagrange: EvalPyramid(basis, ref, values, dRef); return;
        default: HPRAY_CHECK_MSG(false, "not a Lagrange basis");
    }
}

void EvalSerendipity(const BasisTable& basis, const double ref[3], double* values,
                     double* dRef) {
    constexpr int kMaxFull = 27;
    double fv[kMaxFull], fd[3 * kMaxFull];
    EvalLagrange(*basis.full, ref, fv, dRef ? fd : nullptr);
    const int n = basis.nodeCount;
    for (int m = 0; m < n; ++m) {
        const int f = basis.fullIndex[m];
        values[m] = fv[f];
        if (dRef)
            for (int d = 0; d < 3; ++d) dRef[3 * m + d] = fd[3 * f + d];
    }
    for (std::size_t r = 0; r < basis.dropped.size(); ++r) {
        const int f = basis.dropped[r];
        const double* c = basis.correction.data() + r * n;
        for (int m = 0; m < n; ++m) {
            if (c[m] == 0.0) continue;
            values[m] += c[m] * fv[f];
            if (dRef)
                for (int d = 0; d < 3; ++d) dRef[3 * m + d] += c[m] * fd[3 * f + d];
        }
    }
}

// psi_l(x_n) in extended precision, for building the pyramid's nodal transform.
long double PyramidPsiAtNode(int p, const LatticeIndex& fn, const LatticeIndex& node) {
    const int k = fn[2], q = p - k;
    const int kn = node[2], qn = p - kn;
    if (kn < k) return 0.0L;
    long double g[kMaxOrder + 1], dg[kMaxOrder + 1];
    Silvester<long double>(p, static_cast<long double>(kn) / p, g, dg);
    if (q == 0) return g[k];
    if (qn == 0) return 0.0L;  // apex: (1 - c)^q = 0
    const long double a = static_cast<long double>(node[0]) / qn;
    const long double b = static_cast<long double>(node[1]) / qn;
    long double la[kMaxOrder + 1], dla[kMaxOrder + 1], lb[kMaxOrder + 1],
        dlb[kMaxOrder + 1];
    Lagrange1D<long double>(q, a, la, dla);
    Lagrange1D<long double>(q, b, lb, dlb);
    const long double w = static_cast<long double>(qn) / q;  // u p / q with u = qn / p
    long double wq = 1.0L;
    for (int i = 0; i < q; ++i) wq *= w;
    return la[fn[0]] * lb[fn[1]] * wq * g[k];
}

void BuildPyramid(BasisTable& t) {
    const int p = t.order, n = t.nodeCount;
    t.levelEnd.assign(p + 1, 0);
    for (int m = 0; m < n; ++m) t.levelEnd[t.lattice[m][2]] = m + 1;
    // V[n][l] = psi_l(x_n) is unit block-lower-triangular (levels ascending); C = V^-1 by
    // block forward substitution: row n of C = e_n - sum_{l below level(n)} V[n][l] C[l].
    std::vector<long double> c(static_cast<std::size_t>(n) * n, 0.0L);
    for (int row = 0; row < n; ++row) {
        const int k = t.lattice[row][2];
        const int below = k == 0 ? 0 : t.levelEnd[k - 1];
        long double* cr = c.data() + static_cast<std::size_t>(row) * n;
        cr[row] = 1.0L;
        for (int l = 0; l < below; ++l) {
            const long double v = PyramidPsiAtNode(p, t.lattice[l], t.lattice[row]);
            if (v == 0.0L) continue;
            const long double* cl = c.data() + static_cast<std::size_t>(l) * n;
            for (int m = 0; m < below; ++m) cr[m] -= v * cl[m];
        }
    }
    // The Kronecker factors of V's blocks, for evaluation (see basis.h).
    t.couplingOffset.assign((p + 1) * (p + 1), -1);
    t.couplingScale.assign((p + 1) * (p + 1), 0.0);
    for (int kn = 1; kn < p; ++kn)
        for (int kl = 0; kl < kn; ++kl) {
            const int qn = p - kn, ql = p - kl, pair = kn * (p + 1) + kl;
            long double g[kMaxOrder + 1], dg[kMaxOrder + 1];
            Silvester<long double>(p, static_cast<long double>(kn) / p, g, dg);
            long double w = 1.0L;
            for (int i = 0; i < ql; ++i) w *= static_cast<long double>(qn) / ql;
            t.couplingScale[pair] = static_cast<double>(w * g[kl]);
            t.couplingOffset[pair] = static_cast<int>(t.coupling.size());
            for (int in = 0; in <= qn; ++in) {
                long double l[kMaxOrder + 1], dl[kMaxOrder + 1];
                Lagrange1D<long double>(ql, static_cast<long double>(in) / qn, l, dl);
                for (int il = 0; il <= ql; ++il) t.coupling.push_back(static_cast<double>(l[il]));
            }
        }
    // N = psi C: N_m = sum_l psi_l C[l][m]. C[l][m] != 0 only for level(m) <= level(l).
    t.psiToNodal.resize(c.size());
    for (std::size_t i = 0; i < c.size(); ++i) t.psiToNodal[i] = static_cast<double>(c[i]);
}

int FindFull(const BasisTable& full, const LatticeIndex& ijk) {
    return InternalNodeIndex(full.shape, 2, CellFamily::Lagrange, ijk);
}

int FindSer(const BasisTable& t, const LatticeIndex& ijk) {
    return InternalNodeIndex(t.shape, 2, CellFamily::Serendipity, ijk);
}

// Corrections N_m(x_r) of the serendipity nodes m at the dropped order-2 nodes r (derived
// from the closed forms of the 20-node hex, 15-node wedge and 13-node pyramid; the tests
// check that exactly the documented spaces are reproduced).
void BuildSerendipity(BasisTable& t) {
    const BasisTable& full = GetBasis(t.shape, 2, CellFamily::Lagrange);
    t.full = &full;
    const int n = t.nodeCount;
    for (const auto& ijk : t.lattice) t.fullIndex.push_back(FindFull(full, ijk));
    auto isCorner = [](const LatticeIndex& x) {
        return x[0] != 1 && x[1] != 1 && x[2] != 1;
    };
    auto ones = [](const LatticeIndex& x) { return (x[0] == 1) + (x[1] == 1) + (x[2] == 1); };
    for (int f = 0; f < full.nodeCount; ++f) {
        const LatticeIndex& r = full.lattice[f];
        if (FindSer(t, r) >= 0) continue;
        t.dropped.push_back(f);
        std::vector<double> corr(n, 0.0);
        for (int m = 0; m < n; ++m) {
            const LatticeIndex& x = t.lattice[m];
            switch (t.shape) {
                case CellShape::Hex:
                    if (ones(r) == 3) {  // body centre
                        corr[m] = isCorner(x) ? -0.25 : 0.25;
                    } else {  // face centre: the face is the coordinate that is not 1
                        const int d = r[0] != 1 ? 0 : (r[1] != 1 ? 1 : 2);
                        if (x[d] != r[d]) break;
                        corr[m] = isCorner(x) ? -0.25 : 0.5;
                    }
                    break;
                case CellShape::Wedge: {
                    // r = mid-height midpoint of the triangle edge between vertices va, vb.
                    LatticeIndex va{0, 0, 0}, vb{0, 0, 0};
                    if (r[1] == 0) {
                        vb = {2, 0, 0};
                    } else if (r[0] == 0) {
                        vb = {0, 2, 0};
                    } else {
                        va = {2, 0, 0};
                        vb = {0, 2, 0};
                    }
                    const bool atA = x[0] == va[0] && x[1] == va[1];
                    const bool atB = x[0] == vb[0] && x[1] == vb[1];
                    const bool atMid = x[0] == r[0] && x[1] == r[1];
                    if ((atA || atB) && x[2] != 1) corr[m] = -0.25;
                    else if (atA || atB || atMid) corr[m] = 0.5;
                    break;
                }
                case CellShape::Pyramid:  // r = base centre
                    if (x[2] != 0) break;
                    corr[m] = isCorner(x) ? -0.25 : 0.5;
                    break;
                case CellShape::Tet: HPRAY_CHECK_MSG(false, "no serendipity tet");
            }
        }
        t.correction.insert(t.correction.end(), corr.begin(), corr.end());
    }
}

std::unique_ptr<BasisTable> BuildBasis(CellShape shape, int order, CellFamily family) {
    auto t = std::make_unique<BasisTable>();
    t->shape = shape;
    t->order = order;
    t->family = family;
    t->lattice = LatticeNodes(shape, order, family);
    t->nodeCount = static_cast<int>(t->lattice.size());
    for (const auto& ijk : t->lattice) t->refNodes.push_back(LatticeRefCoords(shape, order, ijk));
    const int p = order;
    if (family == CellFamily::Lagrange) {
        switch (shape) {
            case CellShape::Tet:
                t->kind = BasisKind::TetLagrange;
                t->lineDegree = p;
                break;
            case CellShape::Hex:
                t->kind = BasisKind::HexLagrange;
                t->lineDegree = 3 * p;
                break;
            case CellShape::Wedge:
                t->kind = BasisKind::WedgeLagrange;
                t->lineDegree = 2 * p;
                break;
            case CellShape::Pyramid:
                t->kind = BasisKind::PyramidLagrange;
                t->polynomial = false;
                t->lineDegree = 2 * p;
                t->lineDenominatorPower = p;
                BuildPyramid(*t);
                break;
        }
    } else {
        switch (shape) {
            case CellShape::Hex:
                t->kind = BasisKind::HexSerendipity;
                t->lineDegree = 4;
                break;
            case CellShape::Wedge:
                t->kind = BasisKind::WedgeSerendipity;
                t->lineDegree = 3;
                break;
            case CellShape::Pyramid:
                t->kind = BasisKind::PyramidSerendipity;
                t->polynomial = false;
                t->lineDegree = 3;
                t->lineDenominatorPower = 1;
                break;
            case CellShape::Tet: HPRAY_CHECK_MSG(false, "no serendipity tet");
        }
        BuildSerendipity(*t);
    }
    return t;
}

}  // namespace

const BasisTable& GetBasis(CellShape shape, int order, CellFamily family) {
    // Tables live as long as the process: each thread remembers the ones it has seen, so
    // the per-cell calls of set-up and rendering take no lock.
    const int slot = order >= 0 && order <= kMaxOrder
                         ? (static_cast<int>(shape) * (kMaxOrder + 1) + order) * 2 +
                               static_cast<int>(family)
                         : -1;
    thread_local std::array<const BasisTable*, kNumCellShapes * (kMaxOrder + 1) * 2> seen{};
    if (slot >= 0 && slot < static_cast<int>(seen.size()) && seen[slot]) return *seen[slot];
    // Validates the combination (throws InternalError) before taking the lock.
    LatticeNodes(shape, order, family);
    static std::recursive_mutex mutex;  // serendipity tables build their Lagrange table
    static std::map<std::tuple<int, int, int>, std::unique_ptr<BasisTable>> cache;
    std::lock_guard<std::recursive_mutex> lock(mutex);
    auto key = std::make_tuple(static_cast<int>(shape), order, static_cast<int>(family));
    auto it = cache.find(key);
    if (it == cache.end()) it = cache.emplace(key, BuildBasis(shape, order, family)).first;
    if (slot >= 0 && slot < static_cast<int>(seen.size())) seen[slot] = it->second.get();
    return *it->second;
}

void EvalBasis(const BasisTable& basis, const double ref[3], double* values, double* dRef) {
    if (basis.family == CellFamily::Serendipity) {
        EvalSerendipity(basis, ref, values, dRef);
    } else {
        EvalLagrange(basis, ref, values, dRef);
    }
}

double RefOutsideDistance(CellShape shape, const double ref[3]) {
    const double r = ref[0], s = ref[1], t = ref[2];
    const double lo = std::max({-r, -s, -t});
    switch (shape) {
        case CellShape::Tet: return std::max(lo, (r + s + t - 1.0) / std::sqrt(3.0));
        case CellShape::Hex: return std::max({lo, r - 1.0, s - 1.0, t - 1.0});
        case CellShape::Wedge:
            return std::max({lo, (r + s - 1.0) / std::sqrt(2.0), t - 1.0});
        case CellShape::Pyramid: {
            const double inv = 1.0 / std::sqrt(1.25);
            const double h = 0.5 * t;
            return std::max({-t, (h - r) * inv, (h - s) * inv, (r + h - 1.0) * inv,
                             (s + h - 1.0) * inv});
        }
    }
    return 0.0;
}

std::array<double, 3> RefCenter(CellShape shape) {
    switch (shape) {
        case CellShape::Tet: return {0.25, 0.25, 0.25};
        case CellShape::Hex: return {0.5, 0.5, 0.5};
        case CellShape::Wedge: return {1.0 / 3.0, 1.0 / 3.0, 0.5};
        case CellShape::Pyramid: return {0.5, 0.5, 0.2};
    }
    return {0.0, 0.0, 0.0};
}

}  // namespace hpray
