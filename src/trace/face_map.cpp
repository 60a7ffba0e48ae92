// Nodal bases of triangle and quadrilateral faces (see face_map.h).
#include "trace/face_map.h"

#include "util/check.h"

namespace hpray::trace {
namespace {

// Silvester factor L_m(x) = prod_{q < m} (x - q) / (q + 1) and its derivative.
void Silvester(int m, double x, double& value, double& deriv) {
    double v = 1, d = 0;
    for (int q = 0; q < m; ++q) {
        const double f = (x - q) / (q + 1);
        d = d * f + v / (q + 1);
        v *= f;
    }
    value = v;
    deriv = d;
}

// Equispaced 1-D Lagrange polynomials l_i(u), i = 0..p, on nodes q / p, and derivatives.
void Lagrange1D(int p, double u, double* l, double* dl) {
    for (int i = 0; i <= p; ++i) {
        double v = 1, d = 0;
        for (int q = 0; q <= p; ++q) {
            if (q == i) continue;
            const double f = (u - double(q) / p) / (double(i - q) / p);
            d = d * f + v * (p / double(i - q));
            v *= f;
        }
        l[i] = v;
        dl[i] = d;
    }
}

}  // namespace

int FaceNodeCount(FaceBasis basis, int order) {
    switch (basis) {
        case FaceBasis::Triangle: return (order + 1) * (order + 2) / 2;
        case FaceBasis::Quad: return (order + 1) * (order + 1);
        case FaceBasis::QuadSerendipity: return 8;
    }
    return 0;
}

std::array<int, 2> FaceNodeLattice(FaceBasis basis, int order, int m) {
    switch (basis) {
        case FaceBasis::Triangle:
            for (int j = 0; j <= order; ++j) {
                if (m <= order - j) return {m, j};
                m -= order - j + 1;
            }
            break;
        case FaceBasis::Quad: return {m % (order + 1), m / (order + 1)};
        case FaceBasis::QuadSerendipity: {
            static const int kIJ[8][2] = {{0, 0}, {1, 0}, {2, 0}, {0, 1},
                                          {2, 1}, {0, 2}, {1, 2}, {2, 2}};
            return {kIJ[m][0], kIJ[m][1]};
        }
    }
    HPRAY_CHECK_MSG(false, "face node " << m << " of order " << order);
    return {0, 0};
}

void EvalFaceBasis(FaceBasis basis, int p, double u, double v, double* values, double* dU,
                   double* dV) {
    switch (basis) {
        case FaceBasis::Triangle: {
            // Barycentric lambda = (1 - u - v, u, v); node (i, j) has multi-index
            // (p - i - j, i, j) and N = L_{p-i-j}(p l0) L_i(p l1) L_j(p l2).
            double L[3][11], D[3][11];
            const double lam[3] = {1 - u - v, u, v};
            for (int a = 0; a < 3; ++a)
                for (int m = 0; m <= p; ++m) Silvester(m, p * lam[a], L[a][m], D[a][m]);
            int n = 0;
            for (int j = 0; j <= p; ++j)
                for (int i = 0; i <= p - j; ++i, ++n) {
                    const int k = p - i - j;
                    values[n] = L[0][k] * L[1][i] * L[2][j];
                    const double d0 = D[0][k] * L[1][i] * L[2][j];
                    if (dU) dU[n] = p * (D[1][i] * L[0][k] * L[2][j] - d0);
                    if (dV) dV[n] = p * (D[2][j] * L[0][k] * L[1][i] - d0);
                }
            return;
        }
        case FaceBasis::Quad: {
            double lu[11], du[11], lv[11], dv[11];
            Lagrange1D(p, u, lu, du);
            Lagrange1D(p, v, lv, dv);
            int n = 0;
            for (int j = 0; j <= p; ++j)
                for (int i = 0; i <= p; ++i, ++n) {
                    values[n] = lu[i] * lv[j];
                    if (dU) dU[n] = du[i] * lv[j];
                    if (dV) dV[n] = lu[i] * dv[j];
                }
            return;
        }
        case FaceBasis::QuadSerendipity: {
            // On xi = 2u - 1, eta = 2v - 1 in [-1, 1]; node (i, j) at (i - 1, j - 1).
            const double x = 2 * u - 1, y = 2 * v - 1;
            for (int m = 0; m < 8; ++m) {
                const auto ij = FaceNodeLattice(basis, 2, m);
                const double xi = ij[0] - 1, yi = ij[1] - 1;
                double val, dx, dy;
                if (xi != 0 && yi != 0) {
                    val = 0.25 * (1 + x * xi) * (1 + y * yi) * (x * xi + y * yi - 1);
                    dx = 0.25 * xi * (1 + y * yi) * (2 * x * xi + y * yi);
                    dy = 0.25 * yi * (1 + x * xi) * (2 * y * yi + x * xi);
                } else if (xi == 0) {
                    val = 0.5 * (1 - x * x) * (1 + y * yi);
                    dx = -x * (1 + y * yi);
                    dy = 0.5 * (1 - x * x) * yi;
                } else {
                    val = 0.5 * (1 + x * xi) * (1 - y * y);
                    dx = 0.5 * xi * (1 - y * y);
                    dy = -y * (1 + x * xi);
                }
                values[m] = val;
                if (dU) dU[m] = 2 * dx;
                if (dV) dV[m] = 2 * dy;
            }
            return;
        }
    }
}

}  // namespace hpray::trace
