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
