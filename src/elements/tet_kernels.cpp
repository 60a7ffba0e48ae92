// Compile-time-sized Lagrange tetrahedron kernels (see tet_kernels.h). The arithmetic
// mirrors EvalTet of basis.cpp and the node sums of geometry.cpp and field.cpp operation
// for operation; only the loop bounds are constants and the basis values are consumed
// where they are made.
#include "elements/tet_kernels.h"

#include "elements/silvester.h"
#include "mesh/cell.h"
#include "util/check.h"

namespace hpray {
namespace {

// Visits the nodes in the internal order with their basis value and, if Derivative, their
// reference gradient, computed as EvalTet computes them.
template <int P, bool Derivative, typename Visit>
inline void ForEachNode(const double ref[3], Visit&& visit) {
    double a[P + 1], da[P + 1], b[P + 1], db[P + 1];
    double c[P + 1], dc[P + 1], e[P + 1], de[P + 1];
    Silvester<double>(P, ref[0], a, da);
    Silvester<double>(P, ref[1], b, db);
    Silvester<double>(P, ref[2], c, dc);
    Silvester<double>(P, 1.0 - ref[0] - ref[1] - ref[2], e, de);
    int m = 0;
    for (int k = 0; k <= P; ++k)
        for (int j = 0; j + k <= P; ++j)
            for (int i = 0; i + j + k <= P; ++i, ++m) {
                const int l = P - i - j - k;
                const double bc = b[j] * c[k];
                const double value = a[i] * bc * e[l];
                if constexpr (!Derivative) {
                    visit(m, value, nullptr);
                } else {
                    const double ae = a[i] * e[l];
                    const double ade = a[i] * de[l];
                    const double d[3] = {(da[i] * e[l] - ade) * bc,
                                         (db[j] * c[k] * ae) - ade * bc,
                                         (b[j] * dc[k] * ae) - ade * bc};
                    visit(m, value, d);
                }
            }
}

template <int P>
double Value(const double* u, const double ref[3]) {
    double f = 0.0;
    ForEachNode<P, false>(ref, [&](int m, double v, const double*) { f += u[m] * v; });
    return f;
}

template <int P>
double ValueGradient(const double* u, const double ref[3], double dRef[3]) {
    double f = 0.0, g[3] = {0.0, 0.0, 0.0};
    ForEachNode<P, true>(ref, [&](int m, double v, const double* d) {
        const double c = u[m];
        f += c * v;
        g[0] += c * d[0];
        g[1] += c * d[1];
        g[2] += c * d[2];
    });
    dRef[0] = g[0];
    dRef[1] = g[1];
    dRef[2] = g[2];
    return f;
}

template <int P>
void Map(const double* xyz, const double ref[3], double world[3], double* jacobian) {
    double x0 = 0, x1 = 0, x2 = 0;
    if (!jacobian) {
        ForEachNode<P, false>(ref, [&](int m, double v, const double*) {
            x0 += v * xyz[3 * m];
            x1 += v * xyz[3 * m + 1];
            x2 += v * xyz[3 * m + 2];
        });
    } else {
        double j[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
        ForEachNode<P, true>(ref, [&](int m, double v, const double* d) {
            x0 += v * xyz[3 * m];
            x1 += v * xyz[3 * m + 1];
            x2 += v * xyz[3 * m + 2];
            for (int i = 0; i < 3; ++i) {
                const double c = xyz[3 * m + i];
                j[3 * i] += c * d[0];
                j[3 * i + 1] += c * d[1];
                j[3 * i + 2] += c * d[2];
            }
        });
        for (int i = 0; i < 9; ++i) jacobian[i] = j[i];
    }
    world[0] = x0;
    world[1] = x1;
    world[2] = x2;
}

template <int P>
constexpr TetKernels Make() {
    return {P, &Value<P>, &ValueGradient<P>, &Map<P>};
}

constexpr TetKernels kTable[kMaxOrder + 1] = {
    TetKernels{}, Make<1>(), Make<2>(), Make<3>(), Make<4>(), Make<5>(),
    Make<6>(),    Make<7>(), Make<8>(), Make<9>(), Make<10>()};

}  // namespace

const TetKernels& TetKernelsFor(int p) {
    HPRAY_CHECK(p >= 1 && p <= kMaxOrder);
    return kTable[p];
}

}  // namespace hpray
