// Fields restricted to one cell (see field.h).
#include "elements/field.h"

#include <algorithm>

#include "elements/tensor_eval.h"
#include "elements/tet_kernels.h"

namespace hpray {

double FieldValue(const CellGeometry& cell, const CellScalar& field, const double ref[3],
                  EvalWorkspace& ws) {
    if (!field.nodal) return field.constant;
    if (cell.basis->kind == BasisKind::HexLagrange)
        return HexKernelsFor(field.hexOrder ? field.hexOrder : cell.basis->order)
            .value(field.nodal, ref);
    if (cell.basis->shape == CellShape::Tet && cell.basis->order == 1) {
        // Barycentric: corner m sits at reference point e_m (corner 0 at the origin).
        const double* v = field.nodal;
        return v[0] * (1.0 - ref[0] - ref[1] - ref[2]) + v[1] * ref[0] + v[2] * ref[1] +
               v[3] * ref[2];
    }
    if (cell.basis->kind == BasisKind::TetLagrange)
        return TetKernelsFor(cell.basis->order).value(field.nodal, ref);
    if (cell.basis->order == 1 && cell.basis->kind == BasisKind::WedgeLagrange)
        return LinearWedgeValue(field.nodal, ref);
    if (cell.basis->order == 1 && cell.basis->kind == BasisKind::PyramidLagrange)
        return LinearPyramidValue(field.nodal, ref);
    const int n = cell.basis->nodeCount;
    EvalBasis(*cell.basis, ref, ws.values.data(), nullptr);
    double v = 0.0;
    for (int m = 0; m < n; ++m) v += field.nodal[m] * ws.values[m];
    return v;
}

bool FieldValueGradient(const CellGeometry& cell, const CellScalar& field,
                        const double ref[3], EvalWorkspace& ws, double& value,
                        double worldGradient[3]) {
    worldGradient[0] = worldGradient[1] = worldGradient[2] = 0.0;
    if (!field.nodal) {
        value = field.constant;
        return true;
    }
    const int n = cell.basis->nodeCount;
    const double* d = ws.dRef.data();
    double f = 0.0, g[3] = {0.0, 0.0, 0.0};
    // Kernels per order (hexahedra, tetrahedra): the Jacobian then comes from the map's.
    const bool tensor = cell.basis->kind == BasisKind::HexLagrange;
    const bool kernel = tensor || cell.basis->kind == BasisKind::TetLagrange;
    if (tensor) {
        f = HexKernelsFor(field.hexOrder ? field.hexOrder : cell.basis->order)
                .valueGradient(field.nodal, ref, g);
    } else if (kernel) {
        f = TetKernelsFor(cell.basis->order).valueGradient(field.nodal, ref, g);
    } else {
        const double* v = ws.values.data();
        EvalBasis(*cell.basis, ref, ws.values.data(), ws.dRef.data());
        for (int m = 0; m < n; ++m) {
            const double c = field.nodal[m];
            f += c * v[m];
            g[0] += c * d[3 * m];
            g[1] += c * d[3 * m + 1];
            g[2] += c * d[3 * m + 2];
        }
    }
    value = f;
    double jac[9], inv[9];
    if (cell.affine) {
        std::copy(cell.inverseLinear.begin(), cell.inverseLinear.end(), inv);
    } else if (kernel) {
        double world[3];
        WorldFromRef(cell, ref, ws, world, jac);
        if (Invert3x3(jac, inv) == 0.0) return false;
    } else {
        // The basis derivatives are still in ws.dRef: contract them with the nodes.
        for (double& x : jac) x = 0.0;
        for (int m = 0; m < n; ++m)
            for (int i = 0; i < 3; ++i) {
                const double c = cell.nodes[3 * m + i];
                for (int j = 0; j < 3; ++j) jac[3 * i + j] += c * d[3 * m + j];
            }
        if (Invert3x3(jac, inv) == 0.0) return false;
    }
    // grad_world = J^-T grad_ref: component i = sum_j inv[j][i] g[j].
    for (int i = 0; i < 3; ++i)
        worldGradient[i] = inv[i] * g[0] + inv[3 + i] * g[1] + inv[6 + i] * g[2];
    return true;
}

FieldSample SampleFieldAtWorld(const CellGeometry& cell, const CellScalar& field,
                               const double world[3], EvalWorkspace& ws,
                               const InversionOptions& options, bool gradient) {
    FieldSample s;
    s.inversion = RefFromWorld(cell, world, ws, options);
    if (!s.inversion.converged) return s;
    if (gradient) {
        FieldValueGradient(cell, field, s.inversion.ref.data(), ws, s.value,
                           s.gradient.data());
    } else {
        s.value = FieldValue(cell, field, s.inversion.ref.data(), ws);
    }
    return s;
}

}  // namespace hpray
