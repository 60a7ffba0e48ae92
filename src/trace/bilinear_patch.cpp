// Ray / bilinear patch intersection, Reshetov's closed form in double precision.
#include "trace/bilinear_patch.h"

#include <cmath>

namespace hpray::trace {
namespace {

inline void Sub(const double* a, const double* b, double* r) {
    for (int k = 0; k < 3; ++k) r[k] = a[k] - b[k];
}
inline void Cross(const double* a, const double* b, double* r) {
    r[0] = a[1] * b[2] - a[2] * b[1];
    r[1] = a[2] * b[0] - a[0] * b[2];
    r[2] = a[0] * b[1] - a[1] * b[0];
}
inline double Dot(const double* a, const double* b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

}  // namespace

int IntersectBilinearPatch(const double origin[3], const double dir[3], const double q00[3],
                           const double q10[3], const double q11[3], const double q01[3],
                           PatchRoot roots[2]) {
    double e10[3], e11[3], e00[3], d0111[3], qn[3], p00[3], p10[3];
    Sub(q10, q00, e10);
    Sub(q11, q10, e11);
    Sub(q01, q00, e00);
    Sub(q01, q11, d0111);
    Cross(e10, d0111, qn);
    Sub(q00, origin, p00);
    Sub(q10, origin, p10);
    // The line meets the ruling at parameter u iff a + b u + c u^2 = 0.
    double tmp[3];
    Cross(p00, dir, tmp);
    const double a = Dot(tmp, e00);
    const double c = Dot(qn, dir);
    Cross(p10, dir, tmp);
    const double b = Dot(tmp, e11) - (a + c);
    double us[2];
    int nu = 0;
    if (c == 0) {
        if (b == 0) return 0;
        us[nu++] = -a / b;
    } else {
        const double disc = b * b - 4 * a * c;
        if (disc < 0) return 0;
        const double q = -0.5 * (b + std::copysign(std::sqrt(disc), b));
        if (q == 0) {
            us[nu++] = 0;  // a = b = 0: u = 0 is a (double) root
        } else {
            us[nu++] = q / c;
            us[nu++] = a / q;  // Vieta: u1 u2 = a / c
        }
    }
    int n = 0;
    for (int k = 0; k < nu; ++k) {
        const double u = us[k];
        // The ruling at u: pa + v pb, v in R; closest approach to the ray line.
        double pa[3], pb[3], nrm[3], m[3];
        for (int i = 0; i < 3; ++i) {
            pa[i] = p00[i] + u * (p10[i] - p00[i]);
            pb[i] = e00[i] + u * (e11[i] - e00[i]);
        }
        Cross(dir, pb, nrm);
        const double det = Dot(nrm, nrm);
        if (det == 0) continue;  // ruling parallel to the ray
        Cross(nrm, pa, m);
        roots[n].u = u;
        roots[n].t = Dot(m, pb) / det;
        roots[n].v = Dot(m, dir) / det;
        ++n;
    }
    return n;
}

}  // namespace hpray::trace
