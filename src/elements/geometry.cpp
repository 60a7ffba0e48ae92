// Reference-to-world maps of cells: affine classification, evaluation, Newton inversion.
#include "elements/geometry.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "elements/tensor_eval.h"
#include "elements/tet_kernels.h"
#include "util/check.h"

namespace hpray {
namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();

inline double MaxAbs3(const double v[3]) {
    return std::max({std::abs(v[0]), std::abs(v[1]), std::abs(v[2])});
}

inline void MatVec(const double m[9], const double v[3], double out[3]) {
    for (int i = 0; i < 3; ++i) out[i] = m[3 * i] * v[0] + m[3 * i + 1] * v[1] + m[3 * i + 2] * v[2];
}

// Moves a start point into the cell (pyramids: away from the apex plane t = 1, where the
// rational map is singular off the axis).
void ClampToCell(CellShape shape, double ref[3]) {
    auto clamp01 = [](double& v) { v = std::min(1.0, std::max(0.0, v)); };
    switch (shape) {
        case CellShape::Hex:
            for (int d = 0; d < 3; ++d) clamp01(ref[d]);
            break;
        case CellShape::Tet: {
            for (int d = 0; d < 3; ++d) ref[d] = std::max(0.0, ref[d]);
            const double sum = ref[0] + ref[1] + ref[2];
            if (sum > 1.0)
                for (int d = 0; d < 3; ++d) ref[d] /= sum;
            break;
        }
        case CellShape::Wedge: {
            ref[0] = std::max(0.0, ref[0]);
            ref[1] = std::max(0.0, ref[1]);
            const double sum = ref[0] + ref[1];
            if (sum > 1.0) {
                ref[0] /= sum;
                ref[1] /= sum;
            }
            clamp01(ref[2]);
            break;
        }
        case CellShape::Pyramid: {
            ref[2] = std::min(0.9, std::max(0.0, ref[2]));
            const double h = 0.5 * ref[2];
            for (int d = 0; d < 2; ++d) ref[d] = std::min(1.0 - h, std::max(h, ref[d]));
            break;
        }
    }
}

struct NewtonOutcome {
    InversionStatus status = InversionStatus::NotConverged;
    int iterations = 0;
    double contraction = 0;  ///< largest |delta_k| / |delta_k-1|^2 seen (full steps)
    double inverseJacobian[9] = {};  ///< at the last iterate before convergence
};

// Steps no longer than this (reference units) are in Newton's quadratic regime, where
// |delta_k+1| ~ K |delta_k|^2 is measured and used.
constexpr double kQuadraticRegime = 1e-3;

// Damped Newton on F(ref) = worldFromRef(ref) - target, starting at `ref` (updated).
NewtonOutcome Newton(const CellGeometry& cell, const double target[3], double ref[3],
                     EvalWorkspace& ws, const InversionOptions& opt, int maxIterations) {
    NewtonOutcome out;
    const CellShape shape = cell.basis->shape;
    const double roundLevel = 8.0 * kEps * (MaxAbs3(target) + cell.size);
    double x[3], jac[9], f[3];
    WorldFromRef(cell, ref, ws, x, jac);
    for (int d = 0; d < 3; ++d) f[d] = x[d] - target[d];
    double fn = MaxAbs3(f);
    double previousStep = 0;  // of the last full (undamped) step
    for (int it = 0; it < maxIterations; ++it) {
        double inv[9];
        const double det = Invert3x3(jac, inv);
        double jn = 0.0;
        for (double v : jac) jn = std::max(jn, std::abs(v));
        if (!(std::abs(det) > 1e-14 * jn * jn * jn) || !std::isfinite(det)) {
            out.status = InversionStatus::Singular;
            return out;
        }
        double delta[3];
        MatVec(inv, f, delta);
        for (double& v : delta) v = -v;
        ++out.iterations;
        const double step = MaxAbs3(delta);
        if (previousStep > 0 && previousStep <= 10 * kQuadraticRegime)
            out.contraction = std::max(out.contraction, step / (previousStep * previousStep));
        // Converged: the step is below the tolerance, or (with the cell's contraction K
        // measured by earlier inversions) the error left after it, about K step^2, is
        // far below the tolerance.
        if (step <= opt.tolerance || fn <= roundLevel ||
            (opt.contraction > 0 && step <= kQuadraticRegime &&
             opt.contraction * step * step <= opt.tolerance / 16)) {
            for (int d = 0; d < 3; ++d) ref[d] += delta[d];
            std::copy(inv, inv + 9, out.inverseJacobian);
            out.status = InversionStatus::Converged;
            return out;
        }
        double alpha = 1.0;
        if (shape == CellShape::Pyramid && ref[2] < 1.0 && ref[2] + delta[2] >= 1.0)
            alpha = 0.5 * (1.0 - ref[2]) / delta[2];  // stop halfway to the apex plane
        double cand[3], xc[3], jc[9], fc[3], fcn = 0.0;
        bool accepted = false;
        for (int halving = 0; halving < 30; ++halving, alpha *= 0.5) {
            for (int d = 0; d < 3; ++d) cand[d] = ref[d] + alpha * delta[d];
            WorldFromRef(cell, cand, ws, xc, jc);
            for (int d = 0; d < 3; ++d) fc[d] = xc[d] - target[d];
            fcn = MaxAbs3(fc);
            if (fcn < fn || alpha * step <= opt.tolerance) {
                accepted = std::isfinite(fcn);
                break;
            }
        }
        if (!accepted) {
            // No decrease along a descent direction: the residual is at rounding level
            // (converged as far as double precision allows) or the map misbehaves.
            out.status = fn <= 64.0 * roundLevel ? InversionStatus::Converged
                                                 : InversionStatus::NotConverged;
            return out;
        }
        previousStep = alpha == 1.0 ? step : 0.0;
        std::copy(cand, cand + 3, ref);
        std::copy(jc, jc + 9, jac);
        std::copy(fc, fc + 3, f);
        fn = fcn;
        if (RefOutsideDistance(shape, ref) > opt.leaveDistance) {
            out.status = InversionStatus::LeftDomain;
            return out;
        }
    }
    out.status = InversionStatus::NotConverged;
    return out;
}

}  // namespace

double Invert3x3(const double m[9], double inverse[9]) {
    const double c00 = m[4] * m[8] - m[5] * m[7];
    const double c01 = m[5] * m[6] - m[3] * m[8];
    const double c02 = m[3] * m[7] - m[4] * m[6];
    const double det = m[0] * c00 + m[1] * c01 + m[2] * c02;
    if (det == 0.0 || !std::isfinite(det)) return 0.0;
    const double id = 1.0 / det;
    inverse[0] = c00 * id;
    inverse[1] = (m[2] * m[7] - m[1] * m[8]) * id;
    inverse[2] = (m[1] * m[5] - m[2] * m[4]) * id;
    inverse[3] = c01 * id;
    inverse[4] = (m[0] * m[8] - m[2] * m[6]) * id;
    inverse[5] = (m[2] * m[3] - m[0] * m[5]) * id;
    inverse[6] = c02 * id;
    inverse[7] = (m[1] * m[6] - m[0] * m[7]) * id;
    inverse[8] = (m[0] * m[4] - m[1] * m[3]) * id;
    return det;
}

namespace {
/// The rest of MakeCellGeometry once `linear`, `origin` and `size` are set: the largest
/// distance of a node from the affine map, invertibility and the affine flag.
void FinishCellGeometry(const BasisTable& basis, const double* nodeXyz,
                        double affineTolerance, CellGeometry& g) {
    double dev = 0.0;
    for (int m = 0; m < basis.nodeCount; ++m) {
        double x[3];
        MatVec(g.linear.data(), basis.refNodes[m].data(), x);
        double e2 = 0.0;
        for (int d = 0; d < 3; ++d) {
            const double e = x[d] + g.origin[d] - nodeXyz[3 * m + d];
            e2 += e * e;
        }
        dev = std::max(dev, std::sqrt(e2));
    }
    g.affineDeviation = dev;
    g.linearInvertible = Invert3x3(g.linear.data(), g.inverseLinear.data()) != 0.0;
    g.affine = g.linearInvertible && dev <= affineTolerance * g.size;
}
}  // namespace

CellGeometry MakeCellGeometry(const BasisTable& basis, const double* nodeXyz,
                              double affineTolerance) {
    CellGeometry g;
    g.basis = &basis;
    g.nodes = nodeXyz;
    g.lineDegree = basis.lineDegree;
    g.lineDenominatorPower = basis.lineDenominatorPower;
    if (basis.kind == BasisKind::HexLagrange) {
        g.hexMap = &HexKernelsFor(basis.order);
        g.mapOrder = basis.order;
        g.mapNodes = nodeXyz;
    }
    if (basis.kind == BasisKind::TetLagrange) g.tetMap = &TetKernelsFor(basis.order);
    const int n = basis.nodeCount;
    if (basis.shape == CellShape::Tet && basis.order == 1) {
        // The linear tetrahedron (reference corners 0, e1, e2, e3): the map through its
        // corners is x = p0 + [p1 - p0, p2 - p0, p3 - p0] r, in closed form. Large linear
        // meshes derive this per ray segment (MeshGeometry), so no fit is run.
        double lo[3], hi[3];
        for (int d = 0; d < 3; ++d) {
            g.origin[d] = nodeXyz[d];
            lo[d] = hi[d] = nodeXyz[d];
            for (int m = 1; m < 4; ++m) {
                const double x = nodeXyz[3 * m + d];
                g.linear[3 * d + (m - 1)] = x - nodeXyz[d];
                lo[d] = std::min(lo[d], x);
                hi[d] = std::max(hi[d], x);
            }
        }
        g.size = std::sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                           (hi[2] - lo[2]) * (hi[2] - lo[2]));
        // Corner m maps to origin + column m - 1: exact up to the rounding of x - p0.
        FinishCellGeometry(basis, nodeXyz, affineTolerance, g);
        return g;
    }
    // Least-squares affine fit about the centroids: x - xBar = A (r - rBar).
    double rBar[3] = {0, 0, 0}, xBar[3] = {0, 0, 0}, lo[3], hi[3];
    for (int d = 0; d < 3; ++d) {
        lo[d] = std::numeric_limits<double>::infinity();
        hi[d] = -lo[d];
    }
    for (int m = 0; m < n; ++m)
        for (int d = 0; d < 3; ++d) {
            rBar[d] += basis.refNodes[m][d];
            const double x = nodeXyz[3 * m + d];
            xBar[d] += x;
            lo[d] = std::min(lo[d], x);
            hi[d] = std::max(hi[d], x);
        }
    for (int d = 0; d < 3; ++d) {
        rBar[d] /= n;
        xBar[d] /= n;
    }
    g.size = std::sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                       (hi[2] - lo[2]) * (hi[2] - lo[2]));
    double s[9] = {0}, xr[9] = {0};  // s = sum dr dr^T, xr = sum dx dr^T
    for (int m = 0; m < n; ++m) {
        double dr[3], dx[3];
        for (int d = 0; d < 3; ++d) {
            dr[d] = basis.refNodes[m][d] - rBar[d];
            dx[d] = nodeXyz[3 * m + d] - xBar[d];
        }
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) {
                s[3 * i + j] += dr[i] * dr[j];
                xr[3 * i + j] += dx[i] * dr[j];
            }
    }
    double sInv[9];
    HPRAY_CHECK(Invert3x3(s, sInv) != 0.0);  // the lattice always spans 3-D
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            double v = 0.0;
            for (int k = 0; k < 3; ++k) v += xr[3 * i + k] * sInv[3 * k + j];
            g.linear[3 * i + j] = v;
        }
    double ar[3];
    MatVec(g.linear.data(), rBar, ar);
    for (int d = 0; d < 3; ++d) g.origin[d] = xBar[d] - ar[d];
    FinishCellGeometry(basis, nodeXyz, affineTolerance, g);
    return g;
}

void WorldFromRef(const CellGeometry& cell, const double ref[3], EvalWorkspace& ws,
                  double world[3], double jacobian[9]) {
    if (cell.affine) {
        MatVec(cell.linear.data(), ref, world);
        for (int d = 0; d < 3; ++d) world[d] += cell.origin[d];
        if (jacobian) std::copy(cell.linear.begin(), cell.linear.end(), jacobian);
        return;
    }
    if (cell.hexMap) {
        cell.hexMap->map(cell.mapNodes, ref, world, jacobian);
        return;
    }
    if (cell.tetMap) {
        cell.tetMap->map(cell.nodes, ref, world, jacobian);
        return;
    }
    const int n = cell.basis->nodeCount;
    double* v = ws.values.data();
    double* dv = jacobian ? ws.dRef.data() : nullptr;
    EvalBasis(*cell.basis, ref, v, dv);
    double x0 = 0, x1 = 0, x2 = 0;
    const double* p = cell.nodes;
    for (int m = 0; m < n; ++m) {
        x0 += v[m] * p[3 * m];
        x1 += v[m] * p[3 * m + 1];
        x2 += v[m] * p[3 * m + 2];
    }
    world[0] = x0;
    world[1] = x1;
    world[2] = x2;
    if (!jacobian) return;
    double j[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
    for (int m = 0; m < n; ++m) {
        const double* d = dv + 3 * m;
        for (int i = 0; i < 3; ++i) {
            const double c = p[3 * m + i];
            j[3 * i] += c * d[0];
            j[3 * i + 1] += c * d[1];
            j[3 * i + 2] += c * d[2];
        }
    }
    std::copy(j, j + 9, jacobian);
}

int ReducedHexMapOrder(const BasisTable& basis, const double* nodeXyz, double tolerance,
                       int maxOrder, std::vector<double>& reduced) {
    if (basis.kind != BasisKind::HexLagrange) return 0;
    const int p = basis.order;
    std::vector<double> deviation;
    for (int q = 1; q < p && q <= maxOrder; ++q) {
        HexResample(p, 3, nodeXyz, q, reduced);
        // Does the order-q map reproduce every order-p node?
        HexReductionDeviation(p, 3, nodeXyz, q, reduced.data(), deviation);
        bool same = true;
        for (std::size_t m = 0; m < deviation.size() && same; m += 3)
            same = std::sqrt(deviation[m] * deviation[m] + deviation[m + 1] * deviation[m + 1] +
                             deviation[m + 2] * deviation[m + 2]) <= tolerance;
        if (same) return q;
    }
    reduced.clear();
    return 0;
}

bool NewtonFullSteps(const CellGeometry& cell, const double target[3],
                     const double start[3], const InversionOptions& opt, double ref[3],
                     int& iterations, double& contraction, double inverseJacobian[9]) {
    // Newton() above, operation for operation, on the path where every step is full (no
    // pyramid: its steps may be shortened towards the apex).
    HPRAY_CHECK(cell.hexMap || cell.tetMap);
    const auto map = [&](const double* r, double* x, double* j) {
        if (cell.hexMap)
            cell.hexMap->map(cell.mapNodes, r, x, j);
        else
            cell.tetMap->map(cell.nodes, r, x, j);
    };
    const double roundLevel = 8.0 * kEps * (MaxAbs3(target) + cell.size);
    for (int d = 0; d < 3; ++d) ref[d] = start[d];
    double x[3], jac[9], f[3];
    map(ref, x, jac);
    for (int d = 0; d < 3; ++d) f[d] = x[d] - target[d];
    double fn = MaxAbs3(f);
    double previousStep = 0;
    iterations = 0;
    contraction = 0;
    for (int it = 0; it < opt.maxIterations; ++it) {
        double inv[9];
        const double det = Invert3x3(jac, inv);
        double jn = 0.0;
        for (double v : jac) jn = std::max(jn, std::abs(v));
        if (!(std::abs(det) > 1e-14 * jn * jn * jn) || !std::isfinite(det)) return false;
        double delta[3];
        MatVec(inv, f, delta);
        for (double& v : delta) v = -v;
        ++iterations;
        const double step = MaxAbs3(delta);
        if (previousStep > 0 && previousStep <= 10 * kQuadraticRegime)
            contraction = std::max(contraction, step / (previousStep * previousStep));
        if (step <= opt.tolerance || fn <= roundLevel ||
            (opt.contraction > 0 && step <= kQuadraticRegime &&
             opt.contraction * step * step <= opt.tolerance / 16)) {
            for (int d = 0; d < 3; ++d) ref[d] += delta[d];
            std::copy(inv, inv + 9, inverseJacobian);
            return true;
        }
        double cand[3], xc[3], jc[9], fc[3];
        for (int d = 0; d < 3; ++d) cand[d] = ref[d] + 1.0 * delta[d];
        map(cand, xc, jc);
        for (int d = 0; d < 3; ++d) fc[d] = xc[d] - target[d];
        const double fcn = MaxAbs3(fc);
        if (!(fcn < fn || step <= opt.tolerance) || !std::isfinite(fcn)) return false;
        previousStep = step;
        std::copy(cand, cand + 3, ref);
        std::copy(jc, jc + 9, jac);
        std::copy(fc, fc + 3, f);
        fn = fcn;
        if (RefOutsideDistance(cell.basis->shape, ref) > opt.leaveDistance) return false;
    }
    return false;
}

InversionResult RefFromWorld(const CellGeometry& cell, const double world[3],
                             EvalWorkspace& ws, const InversionOptions& options) {
    InversionResult res;
    const CellShape shape = cell.basis->shape;
    double affineRef[3] = {0, 0, 0};
    if (cell.linearInvertible) {
        const double dx[3] = {world[0] - cell.origin[0], world[1] - cell.origin[1],
                              world[2] - cell.origin[2]};
        MatVec(cell.inverseLinear.data(), dx, affineRef);
    }
    if (cell.affine) {
        std::copy(affineRef, affineRef + 3, res.ref.begin());
        res.status = InversionStatus::Converged;
    } else {
        double ref[3];
        if (options.initialGuess) {
            std::copy(options.initialGuess, options.initialGuess + 3, ref);
        } else {
            std::copy(affineRef, affineRef + 3, ref);
            ClampToCell(shape, ref);
        }
        NewtonOutcome o = Newton(cell, world, ref, ws, options, options.maxIterations);
        res.iterations = o.iterations;
        res.contraction = o.contraction;
        // Further starts before declaring the point outside or failed: the node nearest to
        // the point (in a strongly curved cell the affine fit can be far off: MFEM's
        // order-9 spiral), then the centre.
        for (int start = 0; start < 2 && o.status != InversionStatus::Converged; ++start) {
            double ref2[3];
            if (start == 0) {
                const int n = cell.basis->nodeCount;
                int nearest = 0;
                double best = std::numeric_limits<double>::infinity();
                for (int m = 0; m < n; ++m) {
                    const double* x = cell.nodes + 3 * m;
                    const double d2 = (x[0] - world[0]) * (x[0] - world[0]) +
                                      (x[1] - world[1]) * (x[1] - world[1]) +
                                      (x[2] - world[2]) * (x[2] - world[2]);
                    if (d2 < best) {
                        best = d2;
                        nearest = m;
                    }
                }
                std::copy(cell.basis->refNodes[nearest].begin(),
                          cell.basis->refNodes[nearest].end(), ref2);
            } else {
                const auto c = RefCenter(shape);
                std::copy(c.begin(), c.end(), ref2);
            }
            NewtonOutcome o2 = Newton(cell, world, ref2, ws, options, options.maxIterations);
            res.iterations += o2.iterations;
            if (o2.status == InversionStatus::Converged ||
                o.status != InversionStatus::LeftDomain) {
                o = o2;
                std::copy(ref2, ref2 + 3, ref);
            }
        }
        std::copy(ref, ref + 3, res.ref.begin());
        if (o.status == InversionStatus::Converged)
            std::copy(o.inverseJacobian, o.inverseJacobian + 9, res.inverseJacobian.begin());
        res.status = o.status;
    }
    res.converged = res.status == InversionStatus::Converged;
    res.outsideDistance = RefOutsideDistance(shape, res.ref.data());
    res.inside = res.converged && res.outsideDistance <= options.insideTolerance;
    return res;
}

}  // namespace hpray
