// Estimated render cost of a cell (shape, order, family), the weight the k-d splits
// balance; the constants are to be calibrated against the renderer's measured times.
//
// Model. Ray casting spends, per ray segment through a cell,
//   (a) a fixed traversal part: entering/leaving through the faces (proportional to the
//       number of faces, here folded into kCellCost[shape].traversal), and
//   (b) field and geometry evaluations: Newton inversion of the map at the entry and exit
//       points (kNewtonEvaluations evaluations), plus sampling along the segment for the
//       Legendre projection of the field (about lineDegree + 1 samples, lineDegree as in
//       elements/basis.h: the degree of the field along a straight line: tet p, wedge 2p,
//       pyramid 2p, hex 3p). Each evaluation touches every node once, so it costs
//       kCellCost[shape].perNodeEvaluation * nodeCount.
// Order-1 tetrahedra are affine and take the renderer's linear fast path: a single
// evaluation per segment. The number of rays per cell is assumed uniform (cells are sized
// to the features they resolve); costs are normalised so a linear tet costs 1.
//
// Calibration plan (once `hpray render` reports per-cell timings): render the shared data
// sets of one cell type and order each (tet p=1..4, hex p=1..9, wedge p=3, pyramid p=2..3
// from ../shared/data and builtins), record the render time per traversed segment, and
// fit traversal and perNodeEvaluation per shape (and kNewtonEvaluations) by non-negative
// least squares on time = traversal + perNodeEvaluation * nodes * evaluations(order);
// then replace the table below. The partitioner only needs relative costs to be right.
#pragma once

#include "mesh/cell.h"

namespace hpray::partition {

struct CellCostCoefficients {
    double traversal = 1.0;          ///< fixed cost per segment (faces, setup)
    double perNodeEvaluation = 0.1;  ///< cost of one basis evaluation, per node
};

/// Uncalibrated: traversal by face count (tet 4, hex 6, wedge 5, pyramid 5 faces,
/// relative to the tet's 4), one node-evaluation a tenth of a tet traversal.
inline constexpr CellCostCoefficients kCellCost[kNumCellShapes] = {
    {1.0, 0.1},   // Tet
    {1.5, 0.1},   // Hex
    {1.25, 0.1},  // Wedge
    {1.25, 0.1},  // Pyramid
};
/// Evaluations for the Newton inversion at the entry and exit of a curved cell.
inline constexpr double kNewtonEvaluations = 8.0;

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

/// Estimated render cost of one cell, in units of one linear tetrahedron.
inline double CellRenderCost(CellShape shape, int order, CellFamily family) {
    const CellCostCoefficients& k = kCellCost[static_cast<int>(shape)];
    const double nodes = NodeCount(shape, order, family);
    const bool affine =
        shape == CellShape::Tet && order == 1 && family == CellFamily::Lagrange;
    const double evaluations =
        affine ? 1.0 : kNewtonEvaluations + CostLineDegree(shape, order, family) + 1.0;
    const double linearTet =
        kCellCost[0].traversal + kCellCost[0].perNodeEvaluation * 4.0;
    return (k.traversal + k.perNodeEvaluation * nodes * evaluations) / linearTet;
}

}  // namespace hpray::partition
