// A scalar field along one ray segment inside one cell: world point -> reference point
// (closed form in affine cells, warm-started Newton in curved ones) -> true field value.
#pragma once

#include <cstdint>
#include <vector>

#include "elements/field.h"
#include "elements/mesh_geometry.h"
#include "render/stats.h"
#include "trace/ray.h"

namespace hpray {

/// Per-thread evaluator of one scalar field along a ray inside one cell. Reused across
/// segments without allocation once its buffers have grown to the largest cell.
class SegmentField {
public:
    /// Prepares cell `c` of `mesh` for evaluation along `ray`: gathers the cell's nodal
    /// values of `field` and, for affine cells, the linear map t -> reference point.
    void Begin(const Mesh& mesh, const MeshGeometry& geometry, const ScalarSelector& field,
               std::int64_t c, const Ray& ray, const InversionOptions& inversion);

    /// The field at ray parameter t (world distance along the ray). Counts inversions.
    double operator()(double t);
    /// The field at n ray parameters t[s] into out[s] (batched: sum-factorised for affine
    /// Lagrange hexahedra).
    void SampleBatch(const double* t, int n, double* out);
    /// Value and world gradient at t; returns false where the Jacobian is singular.
    bool ValueGradient(double t, double& value, double gradient[3]);

    /// True when the field restricted to the ray is a polynomial of known degree
    /// (affine cell, polynomial space): then `LineDegree()` samples make it exact.
    bool ExactAlongLine() const { return exact_; }
    int LineDegree() const { return lineDegree_; }

    /// Mapping-inversion counters accumulated since the last TakeCounters.
    void AddCountersTo(RenderCounters& counters);

private:
    void RefAt(double t, double ref[3]);

    const CellGeometry* cell_ = nullptr;
    CellScalar scalar_;
    std::vector<double> nodal_;
    Ray ray_;
    InversionOptions inversion_;
    bool affine_ = false;
    bool exact_ = false;
    int lineDegree_ = 0;
    double ref0_[3] = {0, 0, 0}, dref_[3] = {0, 0, 0};
    // The last two converged inversions (t, ref) along the ray: Newton's predictor.
    double guessT_[2] = {0, 0};
    double guessRef_[2][3] = {{0, 0, 0}, {0, 0, 0}};
    int guessCount_ = 0;
    EvalWorkspace ws_;
    std::vector<double> batchScratch_;
    double inversions_ = 0, iterations_ = 0, failures_ = 0, evaluations_ = 0;
};

}  // namespace hpray
