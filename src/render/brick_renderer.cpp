// Ray casting one brick (see brick_renderer.h).
#include "render/brick_renderer.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <mutex>

#include "render/ray_field.h"
#include "util/check.h"
#include "util/error.h"
#include "util/log.h"

namespace hpray {

BrickSetup MakeBrickSetup(const Mesh& mesh, const MeshGeometry& geometry,
                          const BrickTraverser& traverser, const Scene& scene,
                          FieldCache* cache, bool subCellBounds) {
    std::optional<FieldCache> own;
    if (!cache) cache = &own.emplace(mesh, geometry);
    BrickSetup s;
    s.mesh = &mesh;
    s.geometry = &geometry;
    s.traverser = &traverser;
    s.lighting = scene.lighting;
    const std::string source = scene.sourcePath.empty() ? "scene" : scene.sourcePath;
    for (std::size_t k = 0; k < scene.isosurfaces.size(); ++k) {
        const SceneIsosurface& iso = scene.isosurfaces[k];
        const auto sel = SelectScalar(mesh, iso.field);
        const std::string key = "isosurfaces." + std::to_string(k) + ".field";
        if (!sel)
            throw InputError(source, key, "the mesh has no field '" + iso.field + "'");
        if (sel->field->association != Association::Point)
            throw InputError(
                source, key,
                "'" + iso.field + "' is a cell field; isosurfaces need a point field");
        int index = -1;
        for (std::size_t f = 0; f < s.fields.size(); ++f)
            if (s.fields[f].field == sel->field &&
                s.fields[f].component == sel->component)
                index = static_cast<int>(f);
        if (index < 0) {
            index = static_cast<int>(s.fields.size());
            s.fields.push_back(*sel);
        }
        BrickSetup::Iso entry{index, iso.value, iso.color, iso.opacity, std::nullopt, {}};
        if (!iso.colorField.empty()) {
            const auto by = SelectScalar(mesh, iso.colorField);
            if (!by)
                throw InputError(source, "isosurfaces." + std::to_string(k) + ".color_field",
                                 "the mesh has no field '" + iso.colorField + "'");
            entry.colorField = *by;
            entry.colorTf = MakeColorTf(iso.colorTf);
        }
        s.isos.push_back(std::move(entry));
    }
    // Per field: the nodal values gathered once per cell (shared with the ray loop), the
    // guaranteed per-cell ranges, which cells' ranges hold one of its isovalues (s.fields
    // holds the isosurfaces' fields only), and the sub-cell bounds of those cells (no ray
    // needs the others') with the boxes that may hold an isovalue.
    std::vector<std::vector<std::uint8_t>> holds(s.fields.size());
    for (std::size_t f = 0; f < s.fields.size(); ++f) {
        s.fieldData.push_back(cache->Data(s.fields[f]));
        s.cellRanges.push_back(cache->Ranges(s.fields[f]));
        std::vector<double> values;
        for (const BrickSetup::Iso& iso : s.isos)
            if (iso.field == int(f)) values.push_back(iso.value);
        const std::vector<Interval>& ranges = *s.cellRanges[f];
        holds[f].assign(ranges.size(), 0);
        for (std::size_t c = 0; c < ranges.size(); ++c)
            for (double v : values) holds[f][c] |= v >= ranges[c].lo && v <= ranges[c].hi;
        if (subCellBounds) {
            s.subBounds.push_back(cache->SubBounds(s.fields[f], holds[f]));
            s.subHolding.push_back(
                s.subBounds[f]->HoldingMasks(values.data(), int(values.size())));
        } else {
            s.subBounds.push_back(nullptr);
            s.subHolding.emplace_back();
        }
    }
    for (const ScalarSelector& f : s.fields) {
        const auto r = f.field->Range(f.component);
        s.fieldScale.push_back(std::max(std::abs(r[0]), std::abs(r[1])));
    }
    const SceneAccuracy& acc = scene.accuracy;
    for (BrickSetup::Iso& iso : s.isos) {
        const auto r = s.fields[iso.field].field->Range(s.fields[iso.field].component);
        iso.residualTarget = acc.targetResidual * (r[1] - r[0]);
    }
    s.projection.tolerance = acc.projectionTolerance;
    // A residual target loosens the projection (SceneParser: its tolerance follows the
    // target): a piece whose tail is three orders of magnitude below that needs no
    // checks.
    if (acc.targetResidual > 0) s.projection.checkMargin = 1e-3;
    if (acc.projectionOrder > 0) {
        s.projection.startDegree = acc.projectionOrder;
        s.projection.maxDegree = acc.projectionOrder;
    }
    s.roots.rootTolerance = acc.rootTolerance;
    s.roots.polish = acc.polish;
    // (Not loosened with a residual target: the residual reported at a hit must be the
    // true field's at the hit's own point.)
    s.inversion.tolerance = acc.mappingTolerance;
    const double diag = mesh.Bounds().Diagonal();
    s.duplicateDistance = 1e-9 * diag;
    s.sliverLength = 1e-12 * diag;
    s.tNear = std::max(0.0, scene.clip.near);
    s.tFar = scene.clip.far;
    if (scene.clip.box) s.clipBox = *scene.clip.box;
    if (scene.volume) s.volume = MakeVolumeSetup(mesh, scene, *cache);
    for (std::size_t k = 0; k < scene.slices.size(); ++k) {
        const SceneSlice& in = scene.slices[k];
        const auto sel = SelectScalar(mesh, in.field);
        if (!sel)
            throw InputError(source, "slices." + std::to_string(k) + ".field",
                             "the mesh has no field '" + in.field + "'");
        BrickSetup::Slice slice;
        const double len = std::hypot(in.normal[0], in.normal[1], in.normal[2]);
        slice.offset = 0;
        for (int d = 0; d < 3; ++d) {
            slice.normal[d] = in.normal[d] / len;
            slice.offset += slice.normal[d] * in.point[d];
        }
        slice.field = *sel;
        slice.colorTf = MakeColorTf(in.colorTf);
        slice.opacity = in.opacity;
        s.slices.push_back(std::move(slice));
    }
    // Isosurfaces alone need only the cells whose guaranteed range holds an isovalue:
    // where those are few, rays visit them through a tree of their boxes instead of
    // walking every cell on the way (the segments of those cells are the walk's).
    if (!s.isos.empty() && !s.volume && s.slices.empty()) {
        const std::int64_t cells = mesh.CellCount();
        std::vector<std::uint8_t> keep(cells, 0);
        std::int64_t kept = 0;
        for (std::int64_t c = 0; c < cells; ++c) {
            for (const auto& h : holds) keep[c] |= h[c];
            kept += keep[c];
        }
        // Measured: 15% of the cells (deal.II step-65) renders 1.5x faster, 36% (nk-sinc)
        // 1.4x, 45% (MFEM escher) 1.07x; 90% (ball-p2) 1.5x slower.
        if (2 * kept <= cells) {
            // A kept cell with sub-cell bounds is found through the world boxes of its
            // sub-boxes whose interval holds an isovalue of their field (a ray that
            // misses them all would have its segment there ruled out by Clip).
            std::vector<std::int64_t> boxStart(cells + 1, 0);
            std::vector<float> boxes;
            if (subCellBounds) {
                for (std::int64_t c = 0; c < cells; ++c) {
                    boxStart[c + 1] = boxStart[c];
                    if (!keep[c]) continue;
                    const std::size_t before = boxes.size();
                    bool all = true;  // every field with an isovalue here has sub-boxes
                    for (std::size_t f = 0; f < s.fields.size() && all; ++f) {
                        if (!holds[f][c]) continue;
                        const SubCellBounds& d = *s.subBounds[f];
                        if (d.subStart.empty() || d.subStart[c + 1] == d.subStart[c] ||
                            !d.built[c]) {
                            all = false;
                            break;
                        }
                        const std::uint64_t holding = s.subHolding[f][c];
                        for (int b = 0; b < int(d.subStart[c + 1] - d.subStart[c]); ++b) {
                            if (!(holding >> b & 1u)) continue;
                            const SubCellBounds::SubBox x = d.SubBoxOf(c, b);
                            boxes.insert(boxes.end(), x.lo, x.lo + 3);
                            boxes.insert(boxes.end(), x.hi, x.hi + 3);
                        }
                    }
                    if (!all) boxes.resize(before);  // found through its own box
                    boxStart[c + 1] = static_cast<std::int64_t>(boxes.size() / 6);
                    // A cell kept by its range with no sub-box holding a value is found
                    // by no ray: none of its segments could hold a root.
                    if (all && boxStart[c + 1] == boxStart[c]) keep[c] = 0;
                }
            }
            s.isoCells = subCellBounds ? traverser.MakeCellFilter(keep, &boxStart, &boxes)
                                       : traverser.MakeCellFilter(keep);
        }
    }
    return s;
}

namespace {
using CostClock = std::chrono::steady_clock;

/// Appends the cost sample of each segment of a ray as its work ends (see
/// SegmentCostSample); inactive when `out` is null.
class SegmentCostRecorder {
  public:
    SegmentCostRecorder(std::vector<SegmentCostSample>* out, const Ray& ray,
                        const std::vector<Segment>& segments, double traceSeconds)
        : out_(out), ray_(ray), segments_(segments) {
        if (!out_ || segments.empty()) return;
        traceShare_ = traceSeconds / static_cast<double>(segments.size());
        start_ = CostClock::now();
    }
    /// Whether costs are being measured (else every call is a no-op).
    bool Active() const { return out_ != nullptr; }
    /// Segment `index`'s work is done (called for every segment reached, in order).
    void Done(std::size_t index) {
        if (!out_) return;
        const auto now = CostClock::now();
        Add(index, std::chrono::duration<double>(now - start_).count());
        start_ = now;
        next_ = index + 1;
        if (pending_) {
            occluded_ = true;
            std::copy(stop_, stop_ + 3, occluder_);
            pending_ = false;
        }
    }
    /// The ray would have stopped at t (inside the current segment): later segments are
    /// occluded from here.
    void Stopped(double t) {
        pending_ = true;
        for (int d = 0; d < 3; ++d) stop_[d] = ray_.origin[d] + t * ray_.dir[d];
    }
    /// The segments never reached (after an opaque hit) cost their traversal share.
    ~SegmentCostRecorder() {
        if (!out_) return;
        for (std::size_t i = next_; i < segments_.size(); ++i) Add(i, 0.0);
    }

  private:
    void Add(std::size_t index, double work) {
        const Segment& seg = segments_[index];
        SegmentCostSample s;
        s.cell = seg.cell;
        for (int d = 0; d < 3; ++d) {
            s.enter[d] = ray_.origin[d] + seg.tEnter * ray_.dir[d];
            s.exit[d] = ray_.origin[d] + seg.tExit * ray_.dir[d];
        }
        s.seconds = static_cast<float>(work + traceShare_);
        s.occluded = occluded_;
        std::copy(occluder_, occluder_ + 3, s.occluder);
        out_->push_back(s);
    }

    std::vector<SegmentCostSample>* out_;
    const Ray& ray_;
    const std::vector<Segment>& segments_;
    double traceShare_ = 0;
    CostClock::time_point start_;
    std::size_t next_ = 0;
    bool occluded_ = false, pending_ = false;
    double occluder_[3] = {0, 0, 0}, stop_[3] = {0, 0, 0};
};
}  // namespace

/// Per-thread scratch of the ray loop: grown once, then reused without allocation.
class RayIntegrator {
  public:
    /// `costSamples`: when not null, one sample per traversed segment is appended.
    void Integrate(const BrickSetup& setup, const Ray& ray, Pixel& out,
                   RenderCounters& counters,
                   std::vector<SegmentCostSample>* costSamples = nullptr);

  private:
    /// Something the ray meets at one point of a segment: an isosurface root or a slice
    /// plane. The volume is the continuous source, integrated between events.
    struct Event {
        double t;
        int iso;  ///< isosurface index, or -1 for a slice
        double residual;
        int slice = -1;  ///< slice index, or -1 for an isosurface
    };
    // Event sources. Each appends the events of one segment to events_ (the compositing
    // loop sorts them): a new kind of effect is one more source.
    void BeginRaySources(const BrickSetup& setup, const Ray& ray);
    /// Marks the isosurfaces whose value lies in the cell's guaranteed field range; true
    /// if any does.
    bool IsoSourceRelevant(const BrickSetup& setup, const Segment& seg);
    /// The roots of the relevant isosurfaces (opaque ones first; the first opaque hit
    /// bounds the search of the others); returns that bound (+inf if none).
    double IsoSource(const BrickSetup& setup, const Ray& ray, const Segment& seg,
                     const RaySpan& span, RenderCounters& counters);
    /// The slice planes segment `si` owns (a plane through a face shared by two segments
    /// belongs to the second; see the definition for planes through boundary faces); true
    /// if any.
    bool SliceSource(const BrickSetup& setup, std::size_t si, const RaySpan& span,
                     double tMin, double tMax);
    /// The one front-to-back loop: volume up to each event, the event, ..., the rest of
    /// the segment up to `cutoff`. True when the ray is done (opaque).
    bool Composite(const BrickSetup& setup, const Ray& ray, const Segment& seg,
                   double cutoff, bool volumeHere, RayComposite& composite, Pixel& out,
                   RenderCounters& counters, SegmentCostRecorder& recorder);
    /// Where the ray turns opaque at t: true (stop) when rendering; the cost observer
    /// instead notes t and lets the ray go on, to measure what lies behind.
    static bool StopsHere(double t, RayComposite& composite, SegmentCostRecorder& recorder);
    void Shade(const BrickSetup& setup, const Ray& ray, std::int64_t cell, const Event& e,
               SegmentField& field, Pixel& out, double& transmittance,
               RenderCounters& counters);
    void ShadeSlice(const BrickSetup& setup, const Ray& ray, const Segment& seg,
                    const Event& e, RayComposite& composite, RenderCounters& counters);

    std::vector<Segment> segments_;
    std::vector<SegmentEnds> ends_;  ///< per segment, when the volume uses them
    std::vector<SegmentSeed> seeds_;     ///< per segment, when the isosurfaces use them
    const SegmentSeed* seed_ = nullptr;  ///< the current segment's, if any
    SegmentField field_;
    std::vector<std::vector<ProjectedPiece>> pieces_;  ///< per field
    std::vector<char> fieldUsed_;
    std::vector<double> isoValues_;
    std::vector<double> polyRoots_;  ///< PolyRoots' roots
    ProjectionStats projectionStats_;
    /// Per field, the span of the segment the isosurface source projects the field on,
    /// and whether it has.
    std::vector<double> projectT0_, projectT1_;
    std::vector<char> projected_;
    std::vector<double> scratch_;
    std::vector<Event> events_;
    int fieldLoaded_ = -1;  ///< the field field_ was last begun for in this segment
    std::vector<double> lastHit_;
    std::vector<char> relevant_;
    std::vector<double> sliceT_;
    SegmentField sliceField_;
    VolumeRayMarcher marcher_;
};

void RayIntegrator::ShadeSlice(const BrickSetup& setup, const Ray& ray,
                               const Segment& seg, const Event& e,
                               RayComposite& composite, RenderCounters& counters) {
    const BrickSetup::Slice& slice = setup.slices[e.slice];
    // The true field on the plane: the cell of this segment holds the crossing point.
    sliceField_.Begin(*setup.mesh, *setup.geometry, slice.field, seg.cell, ray,
                      setup.inversion);
    const double value = sliceField_(e.t);
    sliceField_.AddCountersTo(counters);
    double color[3];
    slice.colorTf.Eval(value, color);
    const double T = composite.transmittance, alpha = slice.opacity;
    double rgb[3];
    for (int c = 0; c < 3; ++c) rgb[c] = T * alpha * color[c];
    composite.AddColor(rgb);
    composite.rgba[3] += T * alpha;
    composite.transmittance = T * (1 - alpha);
}

void RayIntegrator::Shade(const BrickSetup& setup, const Ray& ray, std::int64_t cell,
                          const Event& e, SegmentField& field, Pixel& out,
                          double& transmittance, RenderCounters& counters) {
    const BrickSetup::Iso& iso = setup.isos[e.iso];
    std::array<double, 3> color = iso.color;
    if (iso.colorField) {
        // The colouring field's true value at the hit, in the cell that holds it.
        sliceField_.Begin(*setup.mesh, *setup.geometry, *iso.colorField, cell, ray,
                          setup.inversion);
        const double value = sliceField_(e.t);
        sliceField_.AddCountersTo(counters);
        iso.colorTf.Eval(value, color.data());
    }
    double value, g[3];
    field.ValueGradient(e.t, value, g);
    const double gn = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
    double n[3];
    if (gn > 0 && std::isfinite(gn)) {
        for (int i = 0; i < 3; ++i) n[i] = g[i] / gn;
    } else {
        for (int i = 0; i < 3; ++i) n[i] = -ray.dir[i];
    }
    // Two-sided: the normal faces the camera.
    double nd = n[0] * ray.dir[0] + n[1] * ray.dir[1] + n[2] * ray.dir[2];
    if (nd > 0) {
        for (double& v : n) v = -v;
        nd = -nd;
    }
    const double nl = -nd;  // headlight: L = V = -dir, so H = L and N.H = N.L
    const SceneLighting& L = setup.lighting;
    const double spec = L.specular * std::pow(std::max(0.0, nl), L.shininess);
    const double alpha = iso.opacity;
    for (int c = 0; c < 3; ++c) {
        const double radiance = std::min(
            1.0, color[c] * (L.ambient + L.diffuse * std::max(0.0, nl)) + spec);
        out.rgba[c] += transmittance * alpha * radiance;
    }
    out.rgba[3] += transmittance * alpha;
    transmittance *= 1 - alpha;
    if (out.isoId < 0) {
        out.isoId = e.iso;
        out.z = e.t;
        for (int i = 0; i < 3; ++i) out.normal[i] = n[i];
        out.isoResidual = e.residual;
    }
    counters.isoHits += 1;
    counters.isoResidualSqSum += e.residual * e.residual;
    counters.isoResidualMax = std::max(counters.isoResidualMax, e.residual);
}


void RayIntegrator::Integrate(const BrickSetup& setup, const Ray& ray, Pixel& out,
                              RenderCounters& counters,
                              std::vector<SegmentCostSample>* costSamples) {
    out = Pixel{};
    counters.rays += 1;
    RaySpan span{setup.tNear, setup.tFar};
    if (setup.clipBox && !ClipRayToBox(ray, *setup.clipBox, span)) return;
    const bool hasVolume = setup.volume.has_value();
    if (!(span.t0 < span.t1) ||
        (setup.isos.empty() && !hasVolume && setup.slices.empty()))
        return;
    // The traverser clips to its brick box by the same arithmetic, so segments cut by a
    // clip plane start or end exactly at tMin / tMax. The brick owns the points of the
    // span (geom/box.h): where an end is open, a neighbouring brick owns that point, so
    // an isosurface hit or a slice exactly there is left to it.
    if (!ClipRayToBox(ray, setup.traverser->GetBrick().box, span)) return;
    const double tMin = span.t0, tMax = span.t1;
    const CostClock::time_point traceStart =
        costSamples ? CostClock::now() : CostClock::time_point{};
    // Linear tetrahedra take their volume fields from the face points of the walk.
    const bool facePoints = hasVolume && setup.traverser->FacePoints();
    // Isosurfaces on bilinear or curved faces: the face parameters where the ray enters
    // and leaves each cell start the inversions of the cell map there.
    std::vector<SegmentSeed>* seeds =
        !setup.isos.empty() && setup.traverser->HasSeeds() ? &seeds_ : nullptr;
    if (!seeds) seeds_.clear();
    // Without a volume or slices, a segment needs nothing of those after it: the walk
    // hands each over as it is found, and stops where the ray ends (at an opaque
    // surface), without walking the cells behind. (The volume's error budget needs the
    // whole path's length first, slices the next segment; measuring costs goes on past
    // the end.)
    const bool incremental = !hasVolume && setup.slices.empty() && !costSamples;
    auto trace = [&](SegmentSink* sink) {
        if (setup.isoCells)
            setup.traverser->Trace(ray, tMin, tMax, segments_, *setup.isoCells, seeds,
                                   sink);
        else
            setup.traverser->Trace(ray, tMin, tMax, segments_,
                                   facePoints ? &ends_ : nullptr, seeds, sink);
    };
    if (!incremental) trace(nullptr);
    // (Inactive when the walk is incremental: costs are not being measured.)
    SegmentCostRecorder recorder(
        costSamples, ray, segments_,
        costSamples ? std::chrono::duration<double>(CostClock::now() - traceStart).count()
                    : 0.0);
    BeginRaySources(setup, ray);
    RayComposite composite;
    composite.rgba = out.rgba;
    if (hasVolume && !segments_.empty())
        marcher_.BeginRay(*setup.volume, ray, segments_.front().tEnter,
                          segments_.back().tExit);
    bool volumeSeen = false;
    // The volume on linear tetrahedra: their segments in one call each, except where an
    // isosurface may cross one (its value in the cell's guaranteed range of its field).
    const bool linearTets =
        facePoints && setup.slices.empty() && !costSamples && !setup.isoCells;
    const bool anyIso = !setup.isos.empty();
    // Runs of such segments go in one call each; the segment that ends a run (one
    // LinearTet does not take, or one where an isosurface may lie) takes the general path
    // below.
    VolumeRayMarcher::IsoCells isoCells;
    const bool runs = linearTets && setup.isos.size() <= VolumeRayMarcher::IsoCells::kMax;
    if (runs) {
        for (const BrickSetup::Iso& iso : setup.isos) {
            isoCells.ranges[isoCells.count] = setup.cellRanges[iso.field]->data();
            isoCells.values[isoCells.count++] = iso.value;
        }
    }
    std::size_t runFrom = 0;  // where the next run may start
    // Segment si (and, through a run of linear tetrahedra, those after it: si is left at
    // the last one taken). True when the ray ends there.
    auto step = [&](std::size_t& si) {
        bool lean = linearTets;
        if (runs && si >= runFrom) {
            const VolumeRayMarcher::LinearTetRunResult r = marcher_.LinearTetRun(
                *setup.geometry, segments_.data(), ends_.data(), si, segments_.size(),
                setup.sliverLength, tMin, tMax, anyIso ? &isoCells : nullptr, composite);
            counters.segmentsCulled += r.culled;
            volumeSeen |= r.seen;
            if (r.stop || r.next == segments_.size()) return true;
            si = r.next;
            runFrom = si + 1;
            lean = false;
        }
        const Segment& seg = segments_[si];
        // A clip plane through a face meets the ray a few ulps off the face: the sliver
        // it leaves in the next cell is skipped.
        if (IsSpanEndSliver(seg, setup.sliverLength, tMin, tMax)) {
            counters.segmentsCulled += 1;
            recorder.Done(si);
            return false;
        }
        // Isosurfaces whose field's guaranteed range in the cell holds their value.
        const bool isoHere = anyIso && IsoSourceRelevant(setup, seg);
        if (lean && !isoHere) {
            using R = VolumeRayMarcher::LinearTetResult;
            const R r = marcher_.LinearTet(*setup.geometry, seg, ends_[si], composite);
            if (r == R::kEmpty) {
                counters.segmentsCulled += 1;
                return false;
            }
            if (r != R::kOther) {
                volumeSeen = true;
                return r == R::kStop;
            }
        }
        // What LinearTet queued comes first.
        if (linearTets && marcher_.FlushLinearTets(composite)) return true;
        // The sources of this segment: isosurfaces whose field's guaranteed range holds
        // their value, slice planes it owns, and the volume unless its transfer functions
        // map the cell's guaranteed ranges to nothing (empty-space skipping).
        events_.clear();
        const bool sliceHere = SliceSource(setup, si, span, tMin, tMax);
        const bool volumeHere =
            hasVolume &&
            marcher_.BeginSegment(*setup.mesh, *setup.geometry, seg, counters,
                                  facePoints ? &ends_[si] : nullptr);
        if (!isoHere && !sliceHere && !volumeHere) {
            counters.segmentsCulled += 1;
            recorder.Done(si);
            return false;
        }
        volumeSeen |= volumeHere;
        fieldLoaded_ = -1;
        seed_ = seeds_.empty() ? nullptr : &seeds_[si];
        const double cutoff =
            isoHere ? IsoSource(setup, ray, seg, span, counters)
                    : std::numeric_limits<double>::infinity();
        std::sort(events_.begin(), events_.end(), [](const Event& a, const Event& b) {
            return a.t < b.t || (a.t == b.t && (a.iso < b.iso ||
                                                (a.iso == b.iso && a.slice < b.slice)));
        });
        const bool done = Composite(setup, ray, seg, cutoff, volumeHere, composite, out,
                                    counters, recorder);
        recorder.Done(si);
        return done;
    };
    if (incremental) {
        // (No runs of linear tetrahedra here: they are a volume's.)
        struct Sink final : SegmentSink {
            decltype(step)& take;
            explicit Sink(decltype(step)& t) : take(t) {}
            bool Take(std::size_t index) override {
                std::size_t si = index;
                return !take(si);
            }
        } sink(step);
        trace(&sink);
    } else {
        for (std::size_t si = 0; si < segments_.size(); ++si)
            if (step(si)) break;
    }
    counters.segments += static_cast<double>(segments_.size());
    if (linearTets) marcher_.FlushLinearTets(composite);
    if (volumeSeen) {
        marcher_.FinishRay(composite);
        out.volError =
            std::max({composite.error[0], composite.error[1], composite.error[2]});
        counters.volumePixels += 1;
        counters.volumeErrorSqSum += out.volError * out.volError;
        counters.volumeErrorMax = std::max(counters.volumeErrorMax, out.volError);
    }
}

void RayIntegrator::BeginRaySources(const BrickSetup& setup, const Ray& ray) {
    const std::size_t nIso = setup.isos.size(), nSlices = setup.slices.size();
    lastHit_.assign(nIso, -std::numeric_limits<double>::infinity());
    relevant_.resize(nIso);
    // Ray parameter of each slice plane (NaN for a ray parallel to it).
    sliceT_.resize(nSlices);
    for (std::size_t k = 0; k < nSlices; ++k) {
        const BrickSetup::Slice& sl = setup.slices[k];
        double nd = 0, no = 0;
        for (int d = 0; d < 3; ++d) {
            nd += sl.normal[d] * ray.dir[d];
            no += sl.normal[d] * ray.origin[d];
        }
        sliceT_[k] =
            nd != 0 ? (sl.offset - no) / nd : std::numeric_limits<double>::quiet_NaN();
    }
}

bool RayIntegrator::IsoSourceRelevant(const BrickSetup& setup, const Segment& seg) {
    bool any = false;
    for (std::size_t k = 0; k < setup.isos.size(); ++k) {
        const Interval& r = (*setup.cellRanges[setup.isos[k].field])[seg.cell];
        relevant_[k] = setup.isos[k].value >= r.lo && setup.isos[k].value <= r.hi;
        any |= relevant_[k] != 0;
    }
    return any;
}

bool RayIntegrator::SliceSource(const BrickSetup& setup, std::size_t si, const RaySpan& span,
                                double tMin, double tMax) {
    // A plane through a face shared by two segments belongs to the second; the end of the
    // last segment of a run inside the mesh is closed. Where a run enters or leaves the
    // mesh through a boundary face lying in the plane, the plane's t and the face's differ
    // by rounding either way: the run's first (last) segment also owns the plane up to
    // `snap` before (after) it, inside the brick's span and outside the neighbouring
    // segments and what the previous run's last segment owns; the slice is then drawn at
    // the segment's end.
    if (setup.slices.empty()) return false;
    const Segment& seg = segments_[si];
    const bool runStart = si == 0 || segments_[si - 1].tExit != seg.tEnter;
    const bool runEnd = si + 1 == segments_.size() || segments_[si + 1].tEnter != seg.tExit;
    const bool closedEnd = runEnd && (seg.tExit != tMax || span.closed1);
    const bool openStart = seg.tEnter == tMin && !span.closed0;
    const double snap = setup.duplicateDistance;
    auto owns = [&](double t) {
        if ((t > seg.tEnter || (t == seg.tEnter && !openStart)) &&
            (t < seg.tExit || (closedEnd && t == seg.tExit)))
            return true;
        if (!span.Holds(t)) return false;
        if (runEnd && t > seg.tExit)
            return t <= seg.tExit + snap &&
                   (si + 1 == segments_.size() || t < segments_[si + 1].tEnter);
        if (runStart && t < seg.tEnter)
            return t >= seg.tEnter - snap && (si == 0 || t > segments_[si - 1].tExit + snap);
        return false;
    };
    bool any = false;
    for (std::size_t k = 0; k < setup.slices.size(); ++k) {
        const double t = sliceT_[k];
        if (owns(t)) {
            events_.push_back({std::clamp(t, seg.tEnter, seg.tExit), -1, 0.0, int(k)});
            any = true;
        }
    }
    return any;
}

namespace {
/// The root of field - C on [t0, t1] where the field is a linear tetrahedron's (linear
/// along the ray) and the decision is clear of rounding: true with r the root (kind
/// Simple, its residual on the field there) where the field's end values lie on opposite
/// sides of C and the root at least 1e-9 of the span from either end, or with r.kind None
/// where both end values lie on one side, farther from C than 1e-12 of the field's scale
/// (the projection's error bound is below 3e-14 of it, so FindRoots would find none
/// either); false otherwise (near an end, or tangent), where FindRoots decides.
bool LinearRoot(SegmentField& field, double C, double scale, double t0, double t1,
                RootResult& r) {
    double a, b;
    if (!field.LinearTetLine(a, b) || !(t1 > t0)) return false;
    const double v0 = a + b * t0 - C, v1 = a + b * t1 - C;
    const double clear = 1e-12 * scale;
    if ((v0 > clear && v1 > clear) || (v0 < -clear && v1 < -clear)) {
        r.kind = RootKind::None;
        return true;
    }
    if (!((v0 < 0 && v1 > 0) || (v0 > 0 && v1 < 0))) return false;
    const double t = (C - a) / b;
    const double margin = 1e-9 * (t1 - t0);
    if (!(t > t0 + margin && t < t1 - margin)) return false;
    r.kind = RootKind::Simple;
    r.t = t;
    r.residual = std::abs(field(t) - C);
    return true;
}
}  // namespace

/// The roots of field - C on [t0, t1] where the field is an affine linear hexahedron's or
/// wedge's (a polynomial of degree 3 or 2 along the ray, SegmentField::LinearCellLine)
/// and every decision is clear of rounding: true with the roots in `roots` (ascending,
/// none possibly) where the polynomial keeps farther from C than its rounding and 1e-12
/// of the field's scale at both ends and at its critical points (so each monotone stretch
/// between them holds a root exactly when its end values lie on opposite sides, and it is
/// simple), and each root at least 1e-9 of the span from either end; false otherwise (a
/// tangent, a root near an end, another cell), where FindRoots decides.
bool PolyRoots(SegmentField& field, double C, double scale, double t0, double t1,
               std::vector<double>& roots) {
    double mono[4], magnitude;
    int degree = 0;
    if (!(t1 > t0) || !field.LinearCellLine(t0, t1, mono, degree, magnitude))
        return false;
    const PolyLine p = MakePolyLine(t0, t1, mono, degree);
    double sum = 0;
    for (const double c : p.m) sum += std::abs(c);
    // The coefficients' rounding (as the volume's series of them) and Horner's, with
    // room.
    const double clear = 1e-12 * scale + 256 * std::numeric_limits<double>::epsilon() *
                                             std::max(sum, magnitude);
    double points[4];
    int count = 0;
    points[count++] = -1;
    count += PolyCriticalPoints(p, points + 1);
    points[count++] = 1;
    for (int k = 0; k < count; ++k)
        if (!(std::abs(p.AtX(points[k]) - C) > clear)) return false;
    roots.clear();
    PolyLevelCrossings(p, C, t0, t1, roots);
    const double margin = 1e-9 * (t1 - t0);
    for (double t : roots)
        if (!(t > t0 + margin && t < t1 - margin)) return false;
    return true;
}

/// PolyRoots for an affine linear pyramid (SegmentField::PyramidLineOn: its field along
/// the ray l0 + l1 x + k R S / U, U > 0): the critical points are the roots of the
/// quadratic numerator of its derivative, l1 U^2 + k ((r1 S + R s1) U - R S u1); the
/// roots those of the quadratic (f - C) U (PyramidLevelCrossings); and their count must
/// be the number of sign changes of f - C over the ends and critical points.
bool PyramidRoots(SegmentField& field, double C, double scale, double t0, double t1,
                  std::vector<double>& roots) {
    PyramidLine p;
    if (!(t1 > t0) || !field.PyramidLineOn(t0, t1, p)) return false;
    const double g0 = p.r1 * p.s0 + p.r0 * p.s1, g1 = 2 * p.r1 * p.s1;
    const double n0 = p.l1 * p.u0 * p.u0 + p.k * (g0 * p.u0 - p.u1 * p.r0 * p.s0);
    const double n1 = 2 * p.l1 * p.u0 * p.u1 + p.k * g1 * p.u0;
    const double n2 = p.l1 * p.u1 * p.u1 + 0.5 * p.k * g1 * p.u1;
    double points[4];
    int count = 0;
    points[count++] = -1;
    count += QuadraticRootsInside(n2, n1, n0, points + 1);
    points[count++] = 1;
    // The evaluation's rounding (R / U, S / U, R S / U at most 1 in the cell), with room.
    const double terms =
        std::abs(p.l0) + std::abs(p.l1) +
        std::abs(p.k) * (3 + std::abs(p.r0) + std::abs(p.r1) + std::abs(p.s0) +
                         std::abs(p.s1) + std::abs(p.u0) + std::abs(p.u1));
    const double clear =
        1e-12 * scale + 256 * std::numeric_limits<double>::epsilon() * terms;
    int changes = 0;
    double previous = 0;
    for (int k = 0; k < count; ++k) {
        const double v = p.AtX(points[k]) - C;
        if (!(std::abs(v) > clear)) return false;
        if (k > 0 && (v < 0) != (previous < 0)) ++changes;
        previous = v;
    }
    roots.clear();
    PyramidLevelCrossings(p, C, t0, t1, roots);
    if (int(roots.size()) != changes) return false;
    std::sort(roots.begin(), roots.end());
    const double margin = 1e-9 * (t1 - t0);
    for (double t : roots)
        if (!(t > t0 + margin && t < t1 - margin)) return false;
    return true;
}

double RayIntegrator::IsoSource(const BrickSetup& setup, const Ray& ray, const Segment& seg,
                                const RaySpan& span, RenderCounters& counters) {
    const std::size_t nIso = setup.isos.size();
    double cutoff = std::numeric_limits<double>::infinity();
    fieldLoaded_ = -1;
    const std::size_t nFields = setup.fields.size();
    if (pieces_.size() < nFields) pieces_.resize(nFields);
    projectT0_.resize(nFields);
    projectT1_.resize(nFields);
    projected_.resize(nFields);
    fieldUsed_.assign(nFields, 0);
    for (std::size_t k = 0; k < nIso; ++k)
        if (relevant_[k]) fieldUsed_[setup.isos[k].field] = 1;
    // Opaque isosurfaces first: their first hit bounds the search of the others.
    for (int pass = 0; pass < 2; ++pass)
        for (std::size_t f = 0; f < nFields; ++f) {
            if (!fieldUsed_[f]) continue;
            bool any = false;
            for (std::size_t k = 0; k < nIso; ++k)
                any |= relevant_[k] && setup.isos[k].field == int(f) &&
                       (setup.isos[k].opacity >= 1) == (pass == 0);
            if (!any) continue;
            // The second pass over the same field keeps the first's set-up and the points it
            // inverted (Newton's predictor).
            if (fieldLoaded_ != int(f)) {
                field_.Begin(*setup.fieldData[f], *setup.geometry, setup.fields[f], seg.cell,
                             ray, setup.inversion);
                if (seed_)
                    field_.Seed(seed_->tEnter, seed_->enter, seed_->tExit, seed_->exit);
            }
            fieldLoaded_ = int(f);
            if (fieldUsed_[f] == 1) {  // project once per field and segment
                fieldUsed_[f] = 2;
                // Rule the segment out cheaply when the mean value theorem proves that no
                // isovalue of this field is crossed in it.
                isoValues_.clear();
                for (std::size_t k = 0; k < nIso; ++k)
                    if (relevant_[k] && setup.isos[k].field == int(f))
                        isoValues_.push_back(setup.isos[k].value);
                // The part of the segment where the sub-cell bounds allow an isovalue.
                double t0 = seg.tEnter, t1 = seg.tExit;
                const SubCellBounds* sub =
                    f < setup.subHolding.size() && !setup.subHolding[f].empty()
                        ? setup.subBounds[f].get()
                        : nullptr;
                // (The masks hold every isovalue of the field: a superset of these.)
                const bool culled =
                    sub &&
                    !sub->Clip(seg.cell, ray, setup.subHolding[f][seg.cell], t0, t1);
                if (sub && (t0 != seg.tEnter || t1 != seg.tExit))
                    counters.isoSubcellClipped += 1;
                if (culled) counters.isoSubcellCulled += 1;
                if (culled ||
                    !field_.MayReach(isoValues_.data(), int(isoValues_.size()), t0, t1)) {
                    for (std::size_t k = 0; k < nIso; ++k)
                        if (setup.isos[k].field == int(f)) relevant_[k] = 0;
                    fieldUsed_[f] = 0;
                    field_.AddCountersTo(counters);
                    continue;
                }
                projectT0_[f] = t0;
                projectT1_[f] = t1;
                projected_[f] = 0;
            }
            // The projection of the field on [projectT0_, projectT1_], once per field and
            // segment, when a root search needs it.
            auto project = [&] {
                if (projected_[f]) return;
                projected_[f] = 1;
                ProjectionOptions projection = setup.projection;
                projection.scaleFloor = setup.fieldScale[f];
                // Only the isovalues matter: a projection far from all of them may stop
                // before it converges.
                projection.exclude = isoValues_.data();
                projection.excludeCount = int(isoValues_.size());
                if (field_.ExactAlongLine())
                    projection.exactDegree = std::max(1, field_.LineDegree());
                projectionStats_ = ProjectionStats{};
                ProjectSegment(field_, projectT0_[f], projectT1_[f], projection,
                               pieces_[f], projectionStats_, scratch_);
                counters.projections += projectionStats_.pieces;
                counters.projectionOrderSum += projectionStats_.degreeSum;
                counters.projectionOrderMax =
                    std::max<double>(counters.projectionOrderMax, projectionStats_.maxDegree);
                counters.projectionUnconverged += projectionStats_.unconverged;
            };
            for (std::size_t k = 0; k < nIso; ++k) {
                const BrickSetup::Iso& iso = setup.isos[k];
                if (!relevant_[k] || iso.field != int(f) || (iso.opacity >= 1) != (pass == 0))
                    continue;
                double previous = lastHit_[k];
                auto onRoot = [&](const RootResult& r) {
                    if (r.t > cutoff) return true;
                    if (!span.Holds(r.t)) return false;
                    if (r.t - previous <= setup.duplicateDistance) return false;
                    previous = r.t;
                    events_.push_back({r.t, int(k), r.residual});
                    if (iso.opacity >= 1) {
                        cutoff = std::min(cutoff, r.t);
                        return true;
                    }
                    return false;
                };
                // A linear tetrahedron's field is linear along the ray: its one root in
                // closed form, where the segment's ends are clear of the isovalue.
                if (RootResult r; LinearRoot(field_, iso.value, setup.fieldScale[f],
                                             projectT0_[f], projectT1_[f], r)) {
                    if (r.kind != RootKind::None) onRoot(r);
                    continue;
                }
                // An affine linear hexahedron's or wedge's polynomial, or a linear
                // pyramid's rational field: its simple roots in closed form, each with
                // its residual on the field.
                if (PolyRoots(field_, iso.value, setup.fieldScale[f], projectT0_[f],
                              projectT1_[f], polyRoots_) ||
                    PyramidRoots(field_, iso.value, setup.fieldScale[f], projectT0_[f],
                                 projectT1_[f], polyRoots_)) {
                    for (const double t : polyRoots_) {
                        RootResult r;
                        r.kind = RootKind::Simple;
                        r.t = t;
                        r.residual = std::abs(field_(t) - iso.value);
                        if (onRoot(r)) break;
                    }
                    continue;
                }
                project();
                RootOptions roots = setup.roots;
                roots.residualTarget = iso.residualTarget;
                counters.rootFailures +=
                    FindRoots(field_, pieces_[f], iso.value, roots, scratch_, onRoot);
            }
            field_.AddCountersTo(counters);
        }
    return cutoff;
}

bool RayIntegrator::StopsHere(double t, RayComposite& composite,
                              SegmentCostRecorder& recorder) {
    if (!recorder.Active()) return true;
    // Measuring costs: note where the ray would have stopped and go on as if transparent,
    // so the segments behind are measured too (and marked occluded).
    recorder.Stopped(t);
    composite.transmittance = 1;
    return false;
}

bool RayIntegrator::Composite(const BrickSetup& setup, const Ray& ray, const Segment& seg,
                              double cutoff, bool volumeHere, RayComposite& composite,
                              Pixel& out, RenderCounters& counters,
                              SegmentCostRecorder& recorder) {
    double& transmittance = composite.transmittance;
    // The field the isosurface source left loaded in this cell (its last inversions, near
    // the roots, start the shading's).
    int loaded = fieldLoaded_;
    double tDone = seg.tEnter;
    bool stop = false;
    // Front to back: the volume up to each event, the event, ..., the rest.
    for (const Event& e : events_) {
        if (e.t > cutoff) break;
        if (volumeHere) {
            stop = marcher_.Integrate(tDone, e.t, composite, counters);
            tDone = std::max(tDone, e.t);
            if (stop && (stop = StopsHere(e.t, composite, recorder))) break;
        }
        if (e.slice >= 0) {
            ShadeSlice(setup, ray, seg, e, composite, counters);
        } else {
            const int f = setup.isos[e.iso].field;
            if (f != loaded) {
                field_.Begin(*setup.fieldData[f], *setup.geometry, setup.fields[f], seg.cell,
                             ray, setup.inversion);
                loaded = f;
            }
            lastHit_[e.iso] = e.t;
            const double before[3] = {out.rgba[0], out.rgba[1], out.rgba[2]};
            Shade(setup, ray, seg.cell, e, field_, out, transmittance, counters);
            if (composite.depthError > 0)
                for (int c = 0; c < 3; ++c)
                    composite.error[c] += std::abs(out.rgba[c] - before[c]) * composite.depthError;
        }
        if (transmittance <= 0 && StopsHere(e.t, composite, recorder)) break;
    }
    if (volumeHere && !stop && transmittance > 0)
        stop = marcher_.Integrate(tDone, std::min(seg.tExit, cutoff), composite, counters);
    if (loaded >= 0) field_.AddCountersTo(counters);
    if (transmittance <= 0 || stop)
        return StopsHere(std::min(seg.tExit, cutoff), composite, recorder);
    return false;
}

void IntegrateRay(const BrickSetup& setup, const Ray& ray, Pixel& sample,
                  RenderCounters& counters) {
    thread_local RayIntegrator integrator;
    integrator.Integrate(setup, ray, sample, counters);
}

namespace {

/// Renders tiles [begin, end) of the camera's image (already sized) with `threads` threads.
void RenderTiles(const BrickSetup& setup, const Camera& camera, int threads, int begin,
                 int end, Image& image, RenderCounters& counters,
                 std::vector<SegmentCostSample>* costSamples, const Image* front) {
    const int W = camera.Width(), H = camera.Height();
    HPRAY_CHECK(image.width == W && image.height == H);
    std::unique_ptr<tbb::global_control> limit;
    if (threads > 0)
        limit = std::make_unique<tbb::global_control>(
            tbb::global_control::max_allowed_parallelism, threads);
    struct ThreadState {
        RayIntegrator integrator;
        RenderCounters counters;
        std::vector<SegmentCostSample> costSamples;
    };
    tbb::enumerable_thread_specific<ThreadState> states;
    const int tilesX = (W + kRenderTile - 1) / kRenderTile;
    // Progress: tiles done, and the next time a line is due (any thread may print it).
    using Clock = std::chrono::steady_clock;
    const auto started = Clock::now();
    std::atomic<int> tilesDone{0};
    // On a terminal the line is rewritten twice a second; otherwise a line every interval.
    const double interval = setup.progressSeconds > 0 && log::ProgressOnTerminal()
                                ? std::min(0.5, setup.progressSeconds)
                                : setup.progressSeconds;
    std::atomic<double> nextReport{setup.progressSeconds};
    std::atomic<bool> reported{false};
    auto report = [&] {
        const int done = ++tilesDone;
        if (!(setup.progressSeconds > 0)) return;
        const double elapsed = std::chrono::duration<double>(Clock::now() - started).count();
        double due = nextReport.load();
        if (elapsed < due || !nextReport.compare_exchange_strong(due, elapsed + interval))
            return;
        const double share = double(done) / std::max(1, end - begin);
        char text[200];
        std::snprintf(text, sizeof text,
                      "rendering %dx%d: %.0f%% of the tiles after %.1f s (%.0f tiles/s), "
                      "about %.0f s left",
                      W, H, 100 * share, elapsed, done / elapsed,
                      elapsed * (1 - share) / share);
        log::Progress(text);
        reported = true;
    };
    tbb::parallel_for(begin, end, [&](int tile) {
        if (setup.cancelled && setup.cancelled()) return;
        ThreadState& st = states.local();
        const int x0 = (tile % tilesX) * kRenderTile, y0 = (tile / tilesX) * kRenderTile;
        Pixel s;
        for (int j = y0; j < std::min(H, y0 + kRenderTile); ++j)
            for (int i = x0; i < std::min(W, x0 + kRenderTile); ++i) {
                // Behind an opaque pixel nothing shows: leave it empty, untraced.
                if (front && front->a[static_cast<std::size_t>(j) * W + i] >= 1.0) continue;
                const CameraRay cr = camera.PixelRay(i, j);
                Ray ray;
                for (int d = 0; d < 3; ++d) {
                    ray.origin[d] = cr.origin[d];
                    ray.dir[d] = cr.direction[d];
                }
                st.integrator.Integrate(setup, ray, s, st.counters,
                                        costSamples ? &st.costSamples : nullptr);
                StorePixel(image, static_cast<std::size_t>(j) * W + i, s);
            }
        report();
    });
    if (reported) log::EndProgress();
    for (const ThreadState& st : states) {
        counters.Merge(st.counters);
        if (costSamples)
            costSamples->insert(costSamples->end(), st.costSamples.begin(),
                                st.costSamples.end());
    }
}

}  // namespace

int RenderTileCount(const Camera& camera) {
    const int tilesX = (camera.Width() + kRenderTile - 1) / kRenderTile;
    const int tilesY = (camera.Height() + kRenderTile - 1) / kRenderTile;
    return tilesX * tilesY;
}

void RenderBrick(const BrickSetup& setup, const Camera& camera, int threads, Image& image,
                 RenderCounters& counters, std::vector<SegmentCostSample>* costSamples,
                 const Image* front) {
    image.Resize(camera.Width(), camera.Height());
    if (front) HPRAY_CHECK(front->width == image.width && front->height == image.height);
    RenderTiles(setup, camera, threads, 0, RenderTileCount(camera), image, counters,
                costSamples, front);
}

void RenderBrickTiles(const BrickSetup& setup, const Camera& camera, int threads, int begin,
                      int end, Image& image, RenderCounters& counters) {
    HPRAY_CHECK(0 <= begin && begin <= end && end <= RenderTileCount(camera));
    RenderTiles(setup, camera, threads, begin, end, image, counters, nullptr, nullptr);
}

}  // namespace hpray
