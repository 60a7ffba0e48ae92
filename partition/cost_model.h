// Estimated render cost of a cell, the weight the k-d splits balance: seconds on one core,
// calibrated against the renderer.
//
// Model. A rank spends on a cell
//   (a) a setup once per brick (geometry classification, traverser faces, gathered field
//       values and bounds): setup(shape, order, family, curved) seconds, and
//   (b) per ray segment through it (traversal share, Newton inversion in curved cells,
//       field samples for the projection, root finding or quadrature):
//       perSegment(shape, order, family, curved) seconds.
// The number of segments depends on the view. The partition is made before any view is
// known, so it assumes the data framed in a kReferencePixels^2 image: a convex cell is
// crossed by (its projected area) / (pixel area) rays, and over all view directions the
// mean projected area of a convex body is a quarter of its surface area (Cauchy's
// formula), so
//       cost = setup + perSegment * area / (4 * (rootDiagonal / kReferencePixels)^2)
// with `area` the surface area of the cell's straight-sided hull (corner vertices) and
// rootDiagonal the diagonal of the whole data's box. So a graded mesh weighs its large
// cells more than its small ones, as rendering does.
//
// Calibration (scripts/calibrate_cost.sh, which runs benchmarks/calibrate_cost and
// scripts/fit_cost_model.py). On one thread, for single-class data sets (builtin tets of
// order 1-8 and hexes of order 1-8, the same bent so every cell is curved, and the shared
// data: curved tets p2-p4, hexes q2/q3/p3, wedges p3, pyramids p2/p3 in mixed meshes):
//   - setup: the time to prepare the whole mesh for rendering divided by its cells;
//   - perSegment: the renderer's own per-segment timings (SegmentCostSample: the work of
//     each segment plus its share of the ray's traversal) summed by cell class, divided
//     by the segments of that class, in a volume scene whose transfer functions vary over
//     the whole field range, so every segment is integrated (the upper envelope: an
//     isosurface scene skips the cells whose guaranteed range holds no isovalue).
// The fit, per shape and affine/curved: perSegment = a + b * n * (L + 1) and setup = c +
// d * n, with n the node count and L the field's degree along a line (the samples one
// projection takes), by non-negative least squares on relative errors. The measurements
// are in partition/cost_calibration.csv; tests/partition check the fit against them
// (median model/measured ratio in [0.8, 1.25], every class measured on >= 10,000
// segments within a factor of 2.5) and the segment count against traced rays. Classes
// without measurements of their own borrow the coefficients named in the table.
//
// What the model leaves out (largest misfits of the calibration): curvature severity
// (MFEM's Escher quadratic tets cost 2.3x the bent builtin ones: more Newton iterations
// and curved boundary faces), cache misses of million-cell meshes (the 1.25M-tet mesh
// costs 1.5-1.8x per segment what a 20k-tet one does), and which cells a scene actually
// evaluates (isosurfaces skip cells whose range holds no isovalue; opaque surfaces hide
// what lies behind them). The in-memory split of `hpray render` measures the scene
// instead (partition/work_split.h).
#pragma once

#include <cmath>
#include <cstddef>

#include "mesh/cell.h"

namespace hpray::partition {

/// The reference view of the whole data the partition balances for: kReferencePixels^2.
inline constexpr double kReferencePixels = 1024;

/// Fitted coefficients of one (shape, affine or curved) class; seconds.
struct CellCostCoefficients {
    double segmentBase;     ///< a: seconds per segment
    double segmentPerWork;  ///< b: seconds per segment per node and line sample
    double setupBase;       ///< c: seconds per cell
    double setupPerNode;    ///< d: seconds per cell per node
};

// Fitted by scripts/fit_cost_model.py from partition/cost_calibration.csv (measured on one
// core of the 2-core development machine, Intel Xeon VM, Release build).
// clang-format off
inline constexpr CellCostCoefficients kAffineCost[kNumCellShapes] = {
    // FIT-AFFINE-BEGIN
    {6.090e-07, 2.415e-09, 7.734e-06, 4.459e-07},  // Tet: 10 rows
    {1.789e-06, 4.526e-10, 9.255e-06, 3.487e-07},  // Hex: 7 rows
    {6.090e-07, 3.677e-08, 7.734e-06, 4.459e-07},  // Wedge: 1 rows, setup of tet affine
    {6.090e-07, 1.311e-07, 7.734e-06, 4.459e-07},  // Pyramid: 1 rows, setup of tet affine
    // FIT-AFFINE-END
};
inline constexpr CellCostCoefficients kCurvedCost[kNumCellShapes] = {
    // FIT-CURVED-BEGIN
    {7.934e-06, 9.245e-08, 1.054e-05, 2.349e-07},  // Tet: 8 rows
    {7.214e-06, 1.798e-08, 7.193e-06, 3.679e-07},  // Hex: 9 rows
    {7.221e-06, 7.319e-08, 0.000e+00, 4.848e-07},  // Wedge: 3 rows
    {0.000e+00, 3.377e-07, 1.054e-05, 2.349e-07},  // Pyramid: 2 rows, setup of tet curved
    // FIT-CURVED-END
};
// clang-format on

/// Field degree along a straight line (elements/basis.h lineDegree) for a cell.
inline int CostLineDegree(CellShape shape, int order, CellFamily family) {
    if (family == CellFamily::Serendipity) return shape == CellShape::Hex ? 4 : 3;
    switch (shape) {
        case CellShape::Tet:
            return order;
        case CellShape::Hex:
            return 3 * order;
        case CellShape::Wedge:
            return 2 * order;
        case CellShape::Pyramid:
            return 2 * order;
    }
    return order;
}

/// The view-independent parts of a cell's cost: setup seconds and seconds per segment.
struct CellCostParts {
    double setup = 0;
    double perSegment = 0;
};

inline CellCostParts CellCostModel(CellShape shape, int order, CellFamily family,
                                   bool curved) {
    const CellCostCoefficients& k =
        (curved ? kCurvedCost : kAffineCost)[static_cast<int>(shape)];
    const double nodes = NodeCount(shape, order, family);
    const double samples = CostLineDegree(shape, order, family) + 1.0;
    return {k.setupBase + k.setupPerNode * nodes,
            k.segmentBase + k.segmentPerWork * nodes * samples};
}

/// Surface area of the straight-sided hull of a cell from its corners, given in the order
/// of mesh/cell.h Topology (the internal corner order): xyz interleaved, 4/8/6/5 corners,
/// faces from the same table. Quadrilaterals count |diagonal x diagonal| / 2 (exact when
/// planar).
double HullSurfaceArea(CellShape shape, const double* vertexXyz);

/// The same from all of a cell's nodes in internal order (xyz interleaved).
double CellHullSurfaceArea(CellShape shape, int order, CellFamily family,
                           const double* nodeXyz);

/// A cell's cost parts and hull area from its nodes in internal order (xyz interleaved),
/// classified affine or curved as the renderer does (elements/geometry.h).
struct CellCostInput {
    CellCostParts parts;
    double area = 0;
};
CellCostInput CellCostFromNodes(CellShape shape, int order, CellFamily family,
                                const double* nodeXyz);
/// The same for an order-1 Lagrange tet (always affine), without the lookups by kind.
CellCostInput LinearTetCost(const double* nodeXyz);
/// LinearTetCost of `count` tets at once, the nodes of tet i at nodeXyz[i], into out[i]:
/// the same doubles, with the square roots of all their faces taken together.
void LinearTetCosts(const double* const* nodeXyz, std::size_t count, CellCostInput* out);

/// Estimated seconds to render a cell in a kReferencePixels^2 view of the whole data
/// (box diagonal `rootDiagonal`), given its parts and hull surface area.
inline double CellRenderSeconds(const CellCostParts& parts, double area, double rootDiagonal) {
    const double pixel = rootDiagonal / kReferencePixels;
    if (!(pixel > 0)) return parts.setup + parts.perSegment;
    return parts.setup + parts.perSegment * area / (4.0 * pixel * pixel);
}

}  // namespace hpray::partition
