// A scalar field along one ray segment inside one cell: world point -> reference point
// (closed form in affine cells, warm-started Newton in curved ones) -> true field value.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "elements/bounds.h"
#include "elements/field.h"
#include "elements/mesh_geometry.h"
#include "render/stats.h"
#include "trace/ray.h"

namespace hpray {

/// Per-cell data of one scalar field, built once per brick and shared by all threads: the
/// nodal values gathered in internal order (segments then need no gather) and, for affine
/// cells of polynomial spaces, a guaranteed bound of |df/dref_d| over the cell (the
/// derivatives lie in the cell's space, so their nodal interpolants are exact and the
/// Bernstein hull bounds them), used to rule out crossings without projecting.
struct FieldCellData {
    const Mesh* mesh = nullptr;
    std::vector<double> values;  ///< cell c's values start at mesh->cellOffsets[c]
    std::vector<std::array<double, 3>> refGradBound;  ///< +inf where no bound is kept
    /// Lagrange hexahedra whose nodal values are, to rounding, those of an interpolant of a
    /// lower order q (a quartic on order-8 cells, say): q and its (q + 1)^3 values, which
    /// every evaluation then uses. Empty when no cell has one.
    std::vector<std::uint8_t> reducedOrder;
    std::vector<std::vector<double>> reducedValues;
    std::int64_t reducedCells = 0;
    /// Largest bound, over the reduced cells, of |reduced interpolant - cell's| (absolute):
    /// the Lebesgue constant cubed times the nodal rounding.
    double reductionTolerance = 0;
    /// A point field's value at every point (PointValues): the field's own array for a
    /// one-component field (`pointField`), else the selected component or the magnitude
    /// gathered once into `pointStorage`. Null for a cell field.
    const double* pointField = nullptr;
    std::vector<double> pointStorage;
    const double* PointValues() const {
        return pointStorage.empty() ? pointField : pointStorage.data();
    }
    /// A point field on a mesh of linear tetrahedra only (every cell derived, see
    /// MeshGeometry::IsDerived) keeps nothing per cell: `values` and `refGradBound` stay
    /// empty, each tetrahedron reads its four values from PointValues(), and only the
    /// tetrahedra that SegmentField::BeginLinearTet cannot take (degenerate ones) keep a
    /// derivative bound: `fallbackBounds[k]` is cell `fallbackCells[k]`'s (sorted by
    /// cell).
    std::vector<std::int64_t> fallbackCells;
    std::vector<std::array<double, 3>> fallbackBounds;

    /// Cell c's nodal values: in `values`, or gathered from PointValues() into `scratch`
    /// (then valid until `scratch` changes).
    const double* CellValues(std::int64_t c, std::vector<double>& scratch) const;
    /// Cell c's derivative bound; nullptr where none is kept.
    const std::array<double, 3>* RefGradBound(std::int64_t c) const;

    static FieldCellData Build(const Mesh& mesh, const MeshGeometry& geometry,
                               const ScalarSelector& field);
};

/// Sub-cell bounds of one field over the Lagrange hexahedra and tetrahedra of order 2 and
/// more, built once per field that isosurfaces use (FieldCache::SubBounds): each
/// cell's reference domain cut into boxes (hexahedra: subN^3 equal boxes; tetrahedra:
/// the sub-tetrahedra of uniform refinements), and for each a world box that holds
/// its image under the cell's map and an interval that holds the field over it
/// (elements/bounds.h: HexSubBounds, TetSubBounds, on the map and the values the rays
/// evaluate, the reduced ones where a cell has them). Cell c has the boxes subStart[c]
/// .. subStart[c + 1] (a multiple of 8, at most 64; none for other cells), stored as 8
/// rows of floats from subData[8 subStart[c]], one entry per box: lower x, y, z, upper x,
/// y, z (padded by 1e-9 of the cell's size), lower and upper field bound (all rounded
/// outwards). Empty when no cell has any.
struct SubCellBounds {
    struct SubBox {
        float lo[3], hi[3];
        float fieldLo, fieldHi;
    };
    int subN = 0;
    std::vector<std::int64_t> subStart;
    /// Allocated for every cell with boxes but not initialised: the pages of cells never
    /// built are never touched (nor read: see `built`).
    std::unique_ptr<float[]> subData;
    std::int64_t subCells = 0;  ///< cells whose boxes are built
    /// Box b of cell c.
    SubBox SubBoxOf(std::int64_t c, int b) const {
        const std::int64_t n = subStart[c + 1] - subStart[c];
        const float* row = subData.get() + 8 * subStart[c] + b;
        return {{row[0], row[n], row[2 * n]},
                {row[3 * n], row[4 * n], row[5 * n]},
                row[6 * n],
                row[7 * n]};
    }

    /// Bit b set where box b of cell c may hold one of the `count` values (0 for a cell
    /// without boxes), and that for every cell.
    std::uint64_t Holding(std::int64_t c, const double* values, int count) const;
    std::vector<std::uint64_t> HoldingMasks(const double* values, int count) const;
    /// Narrows [t0, t1], the segment of `ray` in cell c, to the part where the field may
    /// take one of the values whose boxes are `holding` (Holding): a point of the
    /// segment lies in one of the cell's boxes, so it lies in that box's world box, and
    /// if the box's interval holds none of the values the field differs from each of them
    /// there. False when no part remains (the segment holds none of the values); true,
    /// with [t0, t1] unchanged, for a cell without boxes and where three boxes in four or
    /// more hold a value (their world boxes nearly always cover the segment, and the
    /// slabs would cost more than they save).
    bool Clip(std::int64_t c, const Ray& ray, std::uint64_t holding, double& t0,
              double& t1) const;

    /// Whether cell c's boxes are computed (built[c]); a cell with boxes whose are not
    /// (Extend has not been asked for it) counts as holding every value in every box.
    std::vector<std::uint8_t> built;

    /// The bounds of `data`'s field (the map and values its rays evaluate), in at most
    /// `budget` bytes: 64 boxes per cell where they fit, else 8 (hexahedra in 2 x 2 x 2,
    /// tetrahedra refined once), else none. The boxes are computed for the cells with
    /// need[c] != 0 only (all cells without `need`); Extend computes more.
    static SubCellBounds Build(const Mesh& mesh, const MeshGeometry& geometry,
                               const FieldCellData& data,
                               const std::vector<std::uint8_t>* need = nullptr,
                               std::int64_t budget = std::int64_t(256) << 20);
    /// Computes the boxes of the cells with need[c] != 0 (all without `need`) not yet
    /// built. Must not run while another thread reads those cells.
    void Extend(const Mesh& mesh, const MeshGeometry& geometry, const FieldCellData& data,
                const std::vector<std::uint8_t>* need);

  private:
    /// The refinements of an order-p tetrahedron: TetSubLevels(p), at most tetLevels_.
    int TetLevels(int p) const { return std::min(TetSubLevels(p), tetLevels_); }
    int tetLevels_ = 2;
};

/// The cofactors of the 3x3 matrix E (rows e[0..2]) as the columns of its adjugate:
/// c[0] = e1 x e2, c[1] = e2 x e0, c[2] = e0 x e1, so E^-1 = [c0 c1 c2] / det E; returns
/// det E = e0 . c0. Cramer's rule for the gradient of a linear field from a tetrahedron's
/// edges.
inline double EdgeCofactors(const double e[3][3], double c[3][3]) {
    c[0][0] = e[1][1] * e[2][2] - e[1][2] * e[2][1];
    c[0][1] = e[1][2] * e[2][0] - e[1][0] * e[2][2];
    c[0][2] = e[1][0] * e[2][1] - e[1][1] * e[2][0];
    c[1][0] = e[2][1] * e[0][2] - e[2][2] * e[0][1];
    c[1][1] = e[2][2] * e[0][0] - e[2][0] * e[0][2];
    c[1][2] = e[2][0] * e[0][1] - e[2][1] * e[0][0];
    c[2][0] = e[0][1] * e[1][2] - e[0][2] * e[1][1];
    c[2][1] = e[0][2] * e[1][0] - e[0][0] * e[1][2];
    c[2][2] = e[0][0] * e[1][1] - e[0][1] * e[1][0];
    return e[0][0] * c[0][0] + e[0][1] * c[0][1] + e[0][2] * c[0][2];
}

/// A linear pyramid's field along a segment [t0, t1] of an affine pyramid, in closed form
/// (SegmentField::PyramidLineOn). With x = (t - mid) / half in [-1, 1] and the reference
/// point moving linearly, R = r - h / 2 = r0 + r1 x, S = s - h / 2 = s0 + s1 x and U = 1
/// - h = u0 + u1 x (h the reference height; U > 0 below the apex, 0 <= R, S <= U inside),
/// the field is l0 + l1 x + k R S / U: LinearPyramidValue's basis expanded, with l the
/// affine part v0 U + (v1 - v0) R + (v2 - v0) S + v4 h and k = v0 - v1 - v2 + v3 (the
/// base's twist). Where the cell holds the segment, each of |R / U|, |S / U| and |R S /
/// U| is at most 1: evaluating it this way adds no cancellation.
struct PyramidLine {
    double mid = 0, half = 0, inverseHalf = 0;
    double l0 = 0, l1 = 0, r0 = 0, r1 = 0, s0 = 0, s1 = 0, u0 = 0, u1 = 0, k = 0;
    double AtX(double x) const {
        return l0 + l1 * x + k * (((r0 + r1 * x) * (s0 + s1 * x)) / (u0 + u1 * x));
    }
    double At(double t) const { return AtX((t - mid) * inverseHalf); }
};

/// Per-thread evaluator of one scalar field along a ray inside one cell. Reused across
/// segments without allocation once its buffers have grown to the largest cell.
class SegmentField {
public:
    /// Prepares cell `c` of `mesh` for evaluation along `ray`: gathers the cell's nodal
    /// values of `field` and, for affine cells, the linear map t -> reference point.
    void Begin(const Mesh& mesh, const MeshGeometry& geometry, const ScalarSelector& field,
               std::int64_t c, const Ray& ray, const InversionOptions& inversion);
    /// The same with the field's pre-gathered cell data (no gather; enables MayReach).
    void Begin(const FieldCellData& data, const MeshGeometry& geometry,
               const ScalarSelector& field, std::int64_t c, const Ray& ray,
               const InversionOptions& inversion);

    /// False only when it is proven that f - C has no root on [t0, t1] for any of the
    /// `count` isovalues C: by the mean value theorem with the cell's derivative bound,
    /// from f at the midpoint and, if needed, at the quarter points. True otherwise
    /// (including cells without a bound). Requires Begin with FieldCellData.
    bool MayReach(const double* isovalues, int count, double t0, double t1);

    /// The field at ray parameter t (world distance along the ray). Counts inversions.
    double operator()(double t);
    /// The field at n ray parameters t[s] into out[s] (batched: sum-factorised for affine
    /// Lagrange hexahedra).
    void SampleBatch(const double* t, int n, double* out);
    /// Reference points of this segment's cell at ray parameters tEnter and tExit (NaN
    /// where unknown), from the traversal's face crossings: the starting guesses of the
    /// inversions there. Cleared by Begin.
    void Seed(double tEnter, const double enter[3], double tExit, const double exit[3]);
    /// Value and world gradient at t; returns false where the Jacobian is singular.
    bool ValueGradient(double t, double& value, double gradient[3]);

    /// A linear tetrahedron begun by its closed form (BeginLinearTet): the field is a + b
    /// t along the ray, the same function operator() evaluates.
    bool LinearTetLine(double& a, double& b) const {
        a = lineA_;
        b = lineB_;
        return linearTet_;
    }
    /// True when the field restricted to the ray is a polynomial of known degree
    /// (affine cell, polynomial space): then `LineDegree()` samples make it exact.
    bool ExactAlongLine() const { return exact_; }
    /// The cell maps back to reference space in closed form (affine with an invertible
    /// linear part; every non-degenerate linear tetrahedron).
    bool Affine() const { return affine_; }
    int LineDegree() const { return lineDegree_; }
    /// A linear pyramid with an affine map and a point field, whose basis is rational:
    /// along the ray, with [t0, t1] mapped to x in [-1, 1], the field is
    /// q(x) + residue / (x - pole) with q linear and |pole| > 1 (the pole is where the
    /// line meets the apex plane, t = 1 in reference coordinates; the residue is the
    /// bilinear base's twist times the product of how far that point lies off the apex in
    /// r and s, over the slope of 1 - t in x). Where the field is a polynomial of degree
    /// at most 2 along the ray (no twist, or 1 - t constant along it) the pole and gap
    /// are infinite and the residue 0. False for every other cell, and where the segment
    /// reaches the apex plane. `gap` is |pole| - 1, computed without cancellation.
    bool RationalPole(double t0, double t1, double& pole, double& gap,
                      double& residue) const;
    /// The same linear pyramid's field on [t0, t1] in closed form (see PyramidLine): the
    /// basis expanded, not split into partial fractions. False where RationalPole is, and
    /// where 1 - t (reference) is not positive at both ends.
    bool PyramidLineOn(double t0, double t1, PyramidLine& out) const;
    /// The cell's nodal values of a point field (null otherwise).
    const double* NodalValues() const { return scalar_.nodal; }

    /// For an affine linear hexahedron (a trilinear field: degree 3 along a line) or
    /// wedge (degree 2): the field along the ray on [t0, t1] as a polynomial in x in
    /// [-1, 1], t = (t0 + t1) / 2 + x (t1 - t0) / 2, its monomial coefficients into
    /// mono[0..degree], by sum factorisation of the basis' linear factors (every term at
    /// most the largest nodal value, `magnitude`). False for every other cell.
    bool LinearCellLine(double t0, double t1, double mono[4], int& degree,
                        double& magnitude) const;

    /// Mapping-inversion counters accumulated since the last TakeCounters.
    void AddCountersTo(RenderCounters& counters);

private:
    /// A linear tetrahedron (derived geometry) with a point field: the field along the
    /// ray is a + b t with the world gradient from its corners, no cell geometry needed.
    /// False (and nothing set) for a degenerate tetrahedron.
    bool BeginLinearTet(const Mesh& mesh, std::int64_t c, const double* nodal,
                        const Ray& ray);
    void BeginCommon(const MeshGeometry& geometry, std::int64_t c, const Ray& ray,
                     const InversionOptions& inversion);
    void RefAt(double t, double ref[3]);

    const CellGeometry* cell_ = nullptr;  ///< stored, or derived into cellScratch_
    CellScratch cellScratch_;
    const std::array<double, 3>* gradBound_ = nullptr;
    int hexOrder_ = 0;  ///< order of the hexahedron field evaluated (reduced or the basis')
    double reductionMargin_ = 0;  ///< how far a reduced field may be from the cell's
    CellScalar scalar_;
    std::vector<double> nodal_;
    Ray ray_;
    InversionOptions inversion_;
    bool affine_ = false;
    bool linearTet_ = false;  ///< BeginLinearTet's closed form is in use
    double lineA_ = 0, lineB_ = 0, worldGradient_[3] = {0, 0, 0};
    bool exact_ = false;
    int lineDegree_ = 0;
    double ref0_[3] = {0, 0, 0}, dref_[3] = {0, 0, 0};
    // Converged inversions (t, ref, d ref / dt) in this segment in the order they came,
    // and histOrder_ their indices in order of t: Newton's predictor (see RefAt). At most
    // kHistory are kept; later ones are not.
    static constexpr int kHistory = 48;
    double histT_[kHistory];
    std::uint8_t histOrder_[kHistory];
    double histRef_[kHistory][3];
    double histSlope_[kHistory][3];
    int histCount_ = 0;
    // Seed(): up to two guesses (t, ref) for inversions near the segment's ends.
    double seedT_[2] = {0, 0};
    double seedRef_[2][3];
    int seedCount_ = 0;
    double seedReach_ = 0;    ///< how near t must be to a seed's to use it
    double contraction_ = 0;  ///< largest Newton contraction measured in this segment
    EvalWorkspace ws_;
    std::vector<double> batchScratch_;
    double inversions_ = 0, iterations_ = 0, failures_ = 0, evaluations_ = 0;
};

}  // namespace hpray
