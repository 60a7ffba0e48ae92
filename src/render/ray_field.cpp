// SegmentField: the true field along a ray inside one cell.
#include "render/ray_field.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <tbb/parallel_for.h>

#include "elements/tensor_eval.h"
#include "mesh/cell.h"

namespace hpray {

FieldCellData FieldCellData::Build(const Mesh& mesh, const MeshGeometry& geometry,
                                   const ScalarSelector& field) {
    FieldCellData d;
    d.mesh = &mesh;
    const std::int64_t cells = mesh.CellCount();
    d.values.resize(mesh.connectivity.size());
    const double inf = std::numeric_limits<double>::infinity();
    d.refGradBound.assign(cells, {inf, inf, inf});
    if (field.field->association != Association::Point) return d;
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, cells, 256),
                      [&](const tbb::blocked_range<std::int64_t>& range) {
        std::vector<double> nodal, deriv[3];
        EvalWorkspace ws;
        CellScratch scratch;
        for (std::int64_t c = range.begin(); c < range.end(); ++c) {
            GatherCellValues(mesh, *field.field, field.component, c, nodal);
            std::copy(nodal.begin(), nodal.end(), d.values.begin() + mesh.cellOffsets[c]);
            const CellGeometry& cell = geometry.Cell(c, scratch);
            const BasisTable& basis = *cell.basis;
            if (!cell.affine || !basis.polynomial) continue;
            // Reference derivatives at the nodes: exact nodal interpolants of dF/dref_d.
            const int n = basis.nodeCount;
            for (auto& v : deriv) v.assign(n, 0.0);
            if (basis.kind == BasisKind::HexLagrange) {
                // Tensor product: the 1-D differentiation matrix along each direction.
                const int p = basis.order, q = p + 1;
                double D[(kMaxOrder + 1) * (kMaxOrder + 1)], l[kMaxOrder + 1];
                for (int i = 0; i < q; ++i)
                    LagrangeEquispaced1D(p, double(i) / p, l, D + q * i);  // D[i][j] = l_j'(x_i)
                for (int k = 0; k < q; ++k)
                    for (int j = 0; j < q; ++j)
                        for (int i = 0; i < q; ++i) {
                            double dr = 0, ds = 0, dt = 0;
                            for (int m = 0; m < q; ++m) {
                                dr += D[q * i + m] * nodal[m + q * (j + q * k)];
                                ds += D[q * j + m] * nodal[i + q * (m + q * k)];
                                dt += D[q * k + m] * nodal[i + q * (j + q * m)];
                            }
                            const int node = i + q * (j + q * k);
                            deriv[0][node] = dr;
                            deriv[1][node] = ds;
                            deriv[2][node] = dt;
                        }
            } else
            for (int m = 0; m < n; ++m) {
                const double ref[3] = {basis.refNodes[m][0], basis.refNodes[m][1],
                                       basis.refNodes[m][2]};
                EvalBasis(basis, ref, ws.values.data(), ws.dRef.data());
                for (int q = 0; q < n; ++q)
                    for (int a = 0; a < 3; ++a) deriv[a][m] += nodal[q] * ws.dRef[3 * q + a];
            }
            for (int a = 0; a < 3; ++a) {
                const Interval i = FieldBounds(basis, deriv[a].data());
                d.refGradBound[c][a] = std::max(std::abs(i.lo), std::abs(i.hi));
            }
        }
    });
    return d;
}

void SegmentField::Begin(const FieldCellData& data, const MeshGeometry& geometry,
                         const ScalarSelector& field, std::int64_t c, const Ray& ray,
                         const InversionOptions& inversion) {
    (void)field;  // `data` was built for this field
    BeginCommon(geometry, c, ray, inversion);
    scalar_.nodal = data.values.data() + data.mesh->cellOffsets[c];
    gradBound_ = &data.refGradBound[c];
    lineDegree_ = cell_->basis->lineDegree;
}

bool SegmentField::MayReach(const double* isovalues, int count, double t0, double t1) {
    if (!gradBound_ || !affine_ || !scalar_.nodal) return true;
    // |df/dt| = |grad_ref f . dref/dt| <= sum_d M_d |dref_d|.
    double lipschitz = 0;
    for (int a = 0; a < 3; ++a) lipschitz += (*gradBound_)[a] * std::abs(dref_[a]);
    if (!std::isfinite(lipschitz)) return true;
    auto excluded = [&](double value, double halfWidth) {
        // A small relative margin covers the rounding of the evaluation.
        const double reach = lipschitz * halfWidth * (1 + 1e-12) + 1e-13 * std::abs(value);
        for (int k = 0; k < count; ++k)
            if (std::abs(value - isovalues[k]) <= reach) return false;
        return true;
    };
    const double h = 0.5 * (t1 - t0);
    if (excluded((*this)(t0 + h), h)) return false;
    return !(excluded((*this)(t0 + 0.5 * h), 0.5 * h) &&
             excluded((*this)(t1 - 0.5 * h), 0.5 * h));
}

void SegmentField::BeginCommon(const MeshGeometry& geometry, std::int64_t c, const Ray& ray,
                               const InversionOptions& inversion) {
    cell_ = &geometry.Cell(c, cellScratch_);
    ray_ = ray;
    inversion_ = inversion;
    gradBound_ = nullptr;
    affine_ = cell_->affine && cell_->linearInvertible;
    exact_ = affine_ && cell_->basis->polynomial;
    guessCount_ = 0;
    if (affine_) {
        // ref(t) = L^-1 (o + t d - origin): linear in t.
        const auto& inv = cell_->inverseLinear;
        double rel[3];
        for (int i = 0; i < 3; ++i) rel[i] = ray.origin[i] - cell_->origin[i];
        for (int i = 0; i < 3; ++i) {
            ref0_[i] = inv[3 * i] * rel[0] + inv[3 * i + 1] * rel[1] + inv[3 * i + 2] * rel[2];
            dref_[i] = inv[3 * i] * ray.dir[0] + inv[3 * i + 1] * ray.dir[1] +
                       inv[3 * i + 2] * ray.dir[2];
        }
    }
}

void SegmentField::Begin(const Mesh& mesh, const MeshGeometry& geometry,
                         const ScalarSelector& field, std::int64_t c, const Ray& ray,
                         const InversionOptions& inversion) {
    BeginCommon(geometry, c, ray, inversion);
    if (field.field->association == Association::Point) {
        GatherCellValues(mesh, *field.field, field.component, c, nodal_);
        scalar_.nodal = nodal_.data();
    } else {
        scalar_.nodal = nullptr;
        scalar_.constant = ScalarValue(field, c);
    }
    lineDegree_ = scalar_.nodal ? cell_->basis->lineDegree : 0;
}

void SegmentField::RefAt(double t, double ref[3]) {
    if (affine_) {
        for (int i = 0; i < 3; ++i) ref[i] = ref0_[i] + t * dref_[i];
        return;
    }
    double world[3];
    for (int i = 0; i < 3; ++i) world[i] = ray_.origin[i] + t * ray_.dir[i];
    InversionOptions options = inversion_;
    // Start Newton from the secant prediction through the last two inverted points along
    // the ray (the reference path is smooth), else from the last point.
    double start[3];
    if (guessCount_ >= 2 && guessT_[1] != guessT_[0]) {
        const double w = (t - guessT_[1]) / (guessT_[1] - guessT_[0]);
        for (int i = 0; i < 3; ++i) start[i] = guessRef_[1][i] + w * (guessRef_[1][i] - guessRef_[0][i]);
        options.initialGuess = start;
    } else if (guessCount_ == 1) {
        options.initialGuess = guessRef_[1];
    }
    const InversionResult r = RefFromWorld(*cell_, world, ws_, options);
    inversions_ += 1;
    iterations_ += r.iterations;
    if (!r.converged) failures_ += 1;
    for (int i = 0; i < 3; ++i) ref[i] = r.ref[i];
    if (r.converged) {
        guessT_[0] = guessT_[1];
        for (int i = 0; i < 3; ++i) guessRef_[0][i] = guessRef_[1][i];
        guessT_[1] = t;
        for (int i = 0; i < 3; ++i) guessRef_[1][i] = r.ref[i];
        guessCount_ = std::min(guessCount_ + 1, 2);
    }
}

double SegmentField::operator()(double t) {
    evaluations_ += 1;
    if (!scalar_.nodal) return scalar_.constant;
    double ref[3];
    RefAt(t, ref);
    return FieldValue(*cell_, scalar_, ref, ws_);
}

void SegmentField::SampleBatch(const double* t, int n, double* out) {
    if (scalar_.nodal && cell_->basis->kind == BasisKind::HexLagrange) {
        const int p = cell_->basis->order;
        batchScratch_.resize(HexLineScratchSize(p, n) + 3 * n);
        if (affine_) {
            HexFieldValuesAlongLine(p, scalar_.nodal, ref0_, dref_, t, n, out,
                                    batchScratch_.data());
        } else {
            // Invert the points in order along the ray (each warm-starts the next), then
            // evaluate them together.
            double* refs = batchScratch_.data() + HexLineScratchSize(p, n);
            for (int s = 0; s < n; ++s) RefAt(t[s], refs + 3 * s);
            HexFieldValuesAt(p, scalar_.nodal, refs, n, out, batchScratch_.data());
        }
        evaluations_ += n;
        return;
    }
    for (int s = 0; s < n; ++s) out[s] = (*this)(t[s]);
}

bool SegmentField::ValueGradient(double t, double& value, double gradient[3]) {
    evaluations_ += 1;
    double ref[3];
    RefAt(t, ref);
    return FieldValueGradient(*cell_, scalar_, ref, ws_, value, gradient);
}

void SegmentField::AddCountersTo(RenderCounters& counters) {
    counters.inversions += inversions_;
    counters.inversionIterations += iterations_;
    counters.inversionFailures += failures_;
    counters.fieldEvaluations += evaluations_;
    inversions_ = iterations_ = failures_ = evaluations_ = 0;
}

}  // namespace hpray
