// The map from a cell's reference domain to world space: evaluation, Jacobian, affine
// detection and inversion by damped Newton.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "elements/basis.h"
#include "elements/hex_kernels.h"
#include "elements/tet_kernels.h"

namespace hpray {

/// Scratch for basis evaluation, owned by one thread and reused across calls: sized for
/// the largest cell at construction, so no call that takes it allocates.
struct EvalWorkspace {
    EvalWorkspace() : values(kMaxBasisNodes), dRef(3 * kMaxBasisNodes) {}
    std::vector<double> values;
    std::vector<double> dRef;
};

/// A cell's geometry, classified once. Jacobians are row-major 3x3:
/// jacobian[3 * i + j] = d world_i / d ref_j.
struct CellGeometry {
    const BasisTable* basis = nullptr;
    /// World coordinates of the nodes, x y z interleaved, internal order. Borrowed: the
    /// caller keeps them alive as long as this object is used.
    const double* nodes = nullptr;
    /// All nodes are the affine image of the reference lattice (within affineTolerance
    /// times `size`): the map is exactly worldFromRef = linear * ref + origin.
    bool affine = false;
    /// Least-squares affine fit of the nodes (exact for affine cells); the Newton start.
    std::array<double, 9> linear{};
    std::array<double, 3> origin{};
    std::array<double, 9> inverseLinear{};
    bool linearInvertible = false;
    /// Largest distance of a node from the affine fit (world units).
    double affineDeviation = 0.0;
    /// Diagonal of the nodes' bounding box (world units): the scale of tolerances.
    double size = 0.0;
    /// Along a straight world line through an affine cell, (1 - t)^lineDenominatorPower
    /// times a field is a polynomial of degree lineDegree (see BasisTable); meaningful only
    /// when `affine`.
    int lineDegree = 0;
    int lineDenominatorPower = 0;
    /// Lagrange hexahedra: the kernels that evaluate the map, of order mapOrder, from the
    /// (mapOrder + 1)^3 nodes mapNodes (borrowed, internal hex order). That is the basis
    /// order and `nodes`, unless the map is exactly of a lower order q (a trilinear cell
    /// stored with order-8 nodes, say; MeshGeometry finds these): then q and its nodes.
    /// Null for other cells.
    const HexKernels* hexMap = nullptr;
    int mapOrder = 0;
    const double* mapNodes = nullptr;
    /// Lagrange tetrahedra: the kernels of their order, which evaluate the map from
    /// `nodes`. Null for other cells.
    const TetKernels* tetMap = nullptr;
};

/// The lowest order q < p (q <= maxOrder) whose tensor Lagrange interpolant reproduces every
/// node of a Lagrange hexahedron of order p within `tolerance` (world units), with its
/// (q + 1)^3 nodes (internal order) in `reduced`; 0 if there is none. Two maps of order <= p
/// that agree on the (p + 1)^3 lattice are the same polynomial, so the reduced map is the
/// cell's map up to that tolerance everywhere.
int ReducedHexMapOrder(const BasisTable& basis, const double* nodeXyz, double tolerance,
                       int maxOrder, std::vector<double>& reduced);

/// Relative tolerance (against CellGeometry::size) under which two maps are the same: the
/// affine test and the reduced-order test.
inline constexpr double kAffineTolerance = 1e-13;

/// Classifies a cell: affine fit, affine flag (relative tolerance against `size`).
/// `nodeXyz`: 3 * basis.nodeCount world coordinates in internal order (borrowed).
CellGeometry MakeCellGeometry(const BasisTable& basis, const double* nodeXyz,
                              double affineTolerance = kAffineTolerance);

/// World point of reference point `ref` and, if `jacobian` is not null, d world / d ref.
void WorldFromRef(const CellGeometry& cell, const double ref[3], EvalWorkspace& ws,
                  double world[3], double jacobian[9]);

/// Why an inversion stopped.
enum class InversionStatus : std::uint8_t {
    Converged,     ///< Newton step below tolerance: `ref` is the preimage
    LeftDomain,    ///< iterates went farther than leaveDistance from the cell: outside
    NotConverged,  ///< iteration limit reached: no answer (a failure, count it)
    Singular       ///< Jacobian singular at an iterate: no answer (a failure, count it)
};

struct InversionResult {
    std::array<double, 3> ref{};  ///< last iterate (reference coordinates)
    InversionStatus status = InversionStatus::NotConverged;
    bool converged = false;  ///< status == Converged
    /// converged and RefOutsideDistance(ref) <= insideTolerance.
    bool inside = false;
    int iterations = 0;  ///< Newton iterations over all starts (0 for affine cells)
    double outsideDistance = 0.0;  ///< RefOutsideDistance(shape, ref)
    /// Newton's measured quadratic contraction |delta_k+1| / |delta_k|^2 (largest over
    /// consecutive full steps of at most 1e-2; 0 when there were fewer than two).
    double contraction = 0.0;
    /// Curved cells, when converged: the inverse Jacobian d ref / d world at the last
    /// iterate (within the tolerance of `ref`); a predictor's slope. Zero otherwise.
    std::array<double, 9> inverseJacobian{};
};

struct InversionOptions {
    /// Newton stops when the max-norm of its step is below this (reference units), or
    /// when the error left is predicted below it (see `contraction`).
    double tolerance = 1e-13;
    /// Reference-distance tolerance of the `inside` test.
    double insideTolerance = 1e-10;
    int maxIterations = 50;
    /// An iterate this far (reference units) outside the cell ends the search: LeftDomain.
    double leaveDistance = 1.0;
    /// Optional start (reference coordinates); default: the inverse of the affine fit.
    const double* initialGuess = nullptr;
    /// An estimate K of the cell's quadratic contraction (InversionResult::contraction of
    /// earlier inversions in it, with a margin), or 0. With it Newton also stops after a
    /// step of at most 1e-3 once K step^2 <= tolerance / 16: the error the next step would
    /// remove is that far below the tolerance, so computing it is saved.
    double contraction = 0.0;
};

/// Reference coordinates of world point `world`. Affine cells: closed form. Curved cells:
/// damped Newton from the guess (or the affine fit), then once more from the cell centre
/// if the first start fails. Points outside the cell come back converged with
/// inside == false, or as LeftDomain; failures are never reported as inside.
InversionResult RefFromWorld(const CellGeometry& cell, const double world[3],
                             EvalWorkspace& ws, const InversionOptions& options = {});

/// RefFromWorld for a curved Lagrange hexahedron or tetrahedron (cell.hexMap or
/// cell.tetMap set, not affine) from the initial guess `start`, on its common path only:
/// Newton converges by full steps within options.maxIterations. Returns false wherever
/// RefFromWorld would do anything else (a damped step, a singular Jacobian, an iterate
/// leaving the cell, no convergence); the caller then calls RefFromWorld. When true,
/// `ref`, `iterations`, `contraction` and `inverseJacobian` are bitwise what RefFromWorld
/// returns (converged), without its general set-up.
bool NewtonFullSteps(const CellGeometry& cell, const double world[3],
                     const double start[3], const InversionOptions& options,
                     double ref[3], int& iterations, double& contraction,
                     double inverseJacobian[9]);

/// Inverse of a 3x3 row-major matrix; returns its determinant (0: `inverse` untouched).
double Invert3x3(const double m[9], double inverse[9]);

}  // namespace hpray
