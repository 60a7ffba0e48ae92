// Fields restricted to one cell: value and world gradient at a reference or world point.
#pragma once

#include <array>

#include "elements/geometry.h"

namespace hpray {

/// A scalar field on one cell: nodal coefficients of a point field (internal node order,
/// basis.nodeCount values, borrowed) or the constant of a cell field (nodal == nullptr).
struct CellScalar {
    const double* nodal = nullptr;
    double constant = 0.0;
    /// Lagrange hexahedra: > 0 when `nodal` holds the (hexOrder + 1)^3 values of an
    /// interpolant of that (lower) order instead of the basis' nodes.
    int hexOrder = 0;
};

/// The field of a linear wedge (nodes in the internal order: the triangle's corners at
/// ref[2] = 0, then at 1) at `ref`: the nodal sum with the basis values of
/// basis.cpp's wedge at order 1, formed by the same operations in the same order, so
/// bitwise the value of the table-driven evaluation (without its loops and dispatch).
inline double LinearWedgeValue(const double* v, const double ref[3]) {
    const double e = 1.0 - ref[0] - ref[1];
    const double l0 = 1.0 - ref[2], l1 = ref[2];
    double f = 0.0;
    f += v[0] * (e * l0);
    f += v[1] * (ref[0] * l0);
    f += v[2] * (ref[1] * l0);
    f += v[3] * (e * l1);
    f += v[4] * (ref[0] * l1);
    f += v[5] * (ref[1] * l1);
    return f;
}

/// The same for the linear (rational) pyramid: base corners then apex, as basis.cpp's
/// order-1 pyramid (collapsed coordinates a, b; the axis limit on the apex plane).
inline double LinearPyramidValue(const double* v, const double ref[3]) {
    const double u = 1.0 - ref[2];
    double a = 0.5, b = 0.5;
    if (u != 0.0) {
        a = (ref[0] - 0.5 * ref[2]) / u;
        b = (ref[1] - 0.5 * ref[2]) / u;
    }
    const double la0 = 1.0 - a, lb0 = 1.0 - b;
    double f = 0.0;
    f += v[0] * ((la0 * lb0) * u);
    f += v[1] * ((a * lb0) * u);
    f += v[2] * ((la0 * b) * u);
    f += v[3] * ((a * b) * u);
    f += v[4] * ref[2];
    return f;
}

/// Field value at reference point `ref`.
double FieldValue(const CellGeometry& cell, const CellScalar& field, const double ref[3],
                  EvalWorkspace& ws);

/// Field value and world gradient (J^-T times the reference gradient; zero for a cell
/// field) at reference point `ref`. Returns false, with a zero gradient, where the
/// Jacobian is singular.
bool FieldValueGradient(const CellGeometry& cell, const CellScalar& field,
                        const double ref[3], EvalWorkspace& ws, double& value,
                        double worldGradient[3]);

/// A field sampled at a world point: the inversion that located it, then the value and
/// gradient there (only meaningful when inversion.converged).
struct FieldSample {
    InversionResult inversion;
    double value = 0.0;
    std::array<double, 3> gradient{};
};

/// Inverts `world` in the cell, then evaluates value (and the gradient if `gradient`).
FieldSample SampleFieldAtWorld(const CellGeometry& cell, const CellScalar& field,
                               const double world[3], EvalWorkspace& ws,
                               const InversionOptions& options = {}, bool gradient = true);

}  // namespace hpray
