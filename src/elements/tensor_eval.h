// Sum-factorised evaluation of fields on Lagrange hexahedra: O(p^3) multiply-adds per point
// instead of forming all (p+1)^3 basis functions, and a batched form along a line.
#pragma once

#include <vector>

namespace hpray {

/// The 1-D equispaced Lagrange polynomials of degree p on [0, 1] at x (and derivatives if
/// dl is not null): l_i(x) = S_i(x) S_{p-i}(1 - x) with the Silvester factors of basis.h.
void LagrangeEquispaced1D(int p, double x, double* l, double* dl);

/// f(ref) for nodal values u in the internal hex order (i fastest, then j, then k).
double HexFieldValue(int p, const double* u, const double ref[3]);

/// f(ref) and its reference gradient.
double HexFieldValueGradient(int p, const double* u, const double ref[3], double dRef[3]);

/// The map of a Lagrange hexahedron with interleaved node coordinates xyz (internal order):
/// world point and, if jacobian is not null, d world_i / d ref_j (row-major).
void HexMapValueJacobian(int p, const double* xyz, const double ref[3], double world[3],
                         double* jacobian);

/// f at the n points ref0 + t[s] * dref (a straight line in reference space), into out[s].
/// `scratch` must hold HexLineScratchSize(p, n) doubles.
void HexFieldValuesAlongLine(int p, const double* u, const double ref0[3],
                             const double dref[3], const double* t, int n, double* out,
                             double* scratch);
/// f at n arbitrary reference points refs[3 s .. 3 s + 2], into out[s] (vectorised over the
/// points). `scratch` must hold HexLineScratchSize(p, n) doubles.
void HexFieldValuesAt(int p, const double* u, const double* refs, int n, double* out,
                      double* scratch);
/// Re-samples a tensor Lagrange interpolant of order p (nodal values with `components`
/// interleaved components, internal hex order) at the order-q lattice: (q + 1)^3 *
/// components values into `out` (resized). With q < p, interpolating those at order q gives
/// the lower-order interpolant that agrees with the original on the order-q lattice.
void HexResample(int p, int components, const double* values, int q, std::vector<double>& out);

/// The order-q interpolant (nodal values `reduced`) minus the order-p one, at the order-p
/// nodes, per component, into `deviation` (resized to (p + 1)^3 * components).
void HexReductionDeviation(int p, int components, const double* values, int q,
                           const double* reduced, std::vector<double>& deviation);

inline int HexLineScratchSize(int p, int n) {
    const int padded = (n + 3) / 4 * 4;
    return 3 * (p + 1) * padded + 6 * padded;
}

}  // namespace hpray
