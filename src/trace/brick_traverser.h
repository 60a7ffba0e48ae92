// Ray traversal of one brick: for a ray clipped to the brick's box and to [tMin, tMax],
// the ordered segments (cell, tEnter, tExit) where it is inside cells — exact and
// watertight.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "mesh/mesh.h"
#include "trace/ray.h"

namespace hpray {

/// One brick: a mesh (a whole mesh, or the cells of one k-d leaf, ghosts included) and
/// the axis-aligned box it owns. Rays are cut at the box. The mesh is borrowed: it must
/// outlive every traverser built from it and must not change meanwhile.
struct Brick {
    const Mesh* mesh = nullptr;
    Box box{};

    /// The whole mesh as one brick: box = the mesh bounds.
    static Brick WholeMesh(const Mesh& mesh) { return Brick{&mesh, mesh.Bounds()}; }
};

/// Tolerances of the traversal (dimensionless; "size" = diagonal of the face's or mesh's
/// bounding box in world units).
struct TraceOptions {
    /// Points within mergeTolerance * (mesh bounds diagonal) of each other are one point
    /// for face matching, so meshes that store private copies of shared nodes (deal.II)
    /// are traversed like node-shared ones. 0: bitwise equal positions only.
    double mergeTolerance = 1e-10;
    /// A face whose nodes all lie within straightTolerance * size of the (bi)linear
    /// interpolation of its corners is straight; a straight quadrilateral whose corners
    /// are coplanar to this tolerance is planar.
    double straightTolerance = 1e-12;
    /// Newton on a curved face converges once the face point is within mappingTolerance *
    /// size of the ray; it then polishes while its steps still shrink quadratically.
    double mappingTolerance = 1e-12;
    int maxNewtonIterations = 30;
};

/// Build figures of a traverser.
struct TraverserStats {
    double buildSeconds = 0;        ///< whole build, wall clock (topology + acceleration)
    double accelSeconds = 0;        ///< the Embree scene alone (`timing_s.accel` part)
    std::size_t topologyBytes = 0;  ///< faces, adjacency, merged points, curved face data
    std::size_t accelBytes = 0;     ///< bytes Embree allocated for the scene
    std::int64_t cells = 0;
    std::int64_t points = 0;
    std::int64_t mergedPoints =
        0;  ///< distinct positions after merging coincident points
    std::int64_t faces = 0;
    std::int64_t boundaryFaces =
        0;  ///< faces with one cell (what the Embree scene holds)
    std::int64_t bilinearFaces = 0;  ///< non-planar straight quadrilaterals
    std::int64_t curvedFaces = 0;
    /// Non-conforming input (cells that agree on their corners but not on the other
    /// nodes of a shared face or edge): shared faces whose two cells give different
    /// nodes, and edges whose inner nodes differ between the faces built around them
    /// (a face is built from its lower-numbered cell). The traversal uses one
    /// representation of each: a face's lower-numbered cell's, an edge's first face's.
    /// nonConformity is the largest distance between two versions of a node over the
    /// edge length or face size.
    std::int64_t nonConformingEdges = 0;
    std::int64_t nonConformingFaces = 0;
    double nonConformity = 0;

    std::size_t Bytes() const { return topologyBytes + accelBytes; }
    double BytesPerCell() const { return cells ? double(Bytes()) / double(cells) : 0.0; }
};

/// Counts of numerically hard events met by queries so far (all threads).
struct TraceCounters {
    /// Curved crossings whose Newton iteration failed in a sub-patch at the subdivision
    /// limit (their t is the face point at the sub-patch's centre; counts are
    /// unaffected).
    std::int64_t newtonFailures = 0;
    std::int64_t walkRepairs = 0;   ///< cells left through a tolerant exit search
    std::int64_t walkFailures = 0;  ///< walks abandoned (rest found by the next entry)
    /// Spans that started inside the mesh (tMin past the mesh boundary, a clip box) begun
    /// at the cell located there instead of walked to from the boundary.
    std::int64_t locatedStarts = 0;
    /// Filtered queries (Trace with a CellFilter) where a kept cell's crossings did not
    /// pair up (non-conforming neighbours), answered by the walk instead.
    std::int64_t unpairedRays = 0;
};

/// Where a ray crosses a planar triangular face: the face's corners (point indices of the
/// brick's mesh), the barycentric weights of the crossing on them (each >= 0, sum 1) and
/// its ray parameter t = sum w_k z_k. Computed from the face's one canonical
/// representation, so both cells of a face get bitwise the same point. With it, bounds of
/// how far the point sum w_k P_k lies from the ray point at t, in the ray frame
/// (trace/ray_frame.h: x, y across the ray, z its parameter): off[0] and off[1] across
/// the ray (|sum w_k x_k| and |sum w_k y_k|, the rounding of those sums, and
/// cornerError), off[2] along it (the rounding of t's sum; with a factor 4 eps on the
/// sums of w_k |coordinate|).
struct FacePoint {
    /// Not available. Every other member is set together with v (MakeFacePoint) and read
    /// only when Valid: the walk makes two per segment, none of them zero-filled first.
    FacePoint() { v[0] = -1; }
    std::int32_t v[3];  ///< v[0] < 0: not available
    double w[3];
    double t;
    double off[3];
    /// Bound of the error of each corner's x and y (ray frame) against the exact
    /// transformation of its world position.
    double cornerError;

    bool Valid() const { return v[0] >= 0; }
    /// Becomes `other`, or not available where it is not: copies only set members.
    void SetFrom(const FacePoint& other) {
        if (other.Valid())
            *this = other;
        else
            v[0] = -1;
    }
};

/// The face points where a segment's ray enters and leaves its cell (walked linear
/// tetrahedra only; elsewhere not Valid). A segment clipped to a box or range starts or
/// ends between them.
struct SegmentEnds {
    SegmentEnds() {}  // user-provided: a new element is not zero-filled (see FacePoint)
    FacePoint enter, exit;
};

/// Where a segment's ray enters and leaves its cell (at ray parameters tEnter and tExit,
/// those of the face crossings: a clipped segment starts or ends elsewhere), in the
/// cell's reference coordinates from the face parameters of the crossings (faces of
/// hexahedra, tetrahedra and wedges other than the straight triangles of linear cells);
/// NaN where unknown. A starting guess for inverting the cell map there: exact for the
/// face the crossing was computed on, and within the face's own tolerance for curved
/// faces (for planar quadrilaterals other than parallelograms, an approximation).
struct SegmentSeed {
    double tEnter, enter[3], tExit, exit[3];
};

/// Ray caster of one brick. Built once (adjacency over faces matched by merged corner
/// positions, and an Embree scene over the boundary faces), then queried from any number
/// of threads.
///
/// Design: Embree finds where a ray enters the mesh (boundary faces only, as user
/// geometry whose intersector is the exact test below), then the ray walks from cell to
/// neighbouring cell through the shared faces. Measured on cube-tets-60 (1.08M tets, one
/// core of a loaded 2-core machine, benchmarks/bench_trace.cpp): the walk gives 2.3M
/// exact segments/s at 102 bytes/cell in all (Embree: 4 bytes/cell). A BVH over all faces
/// as Embree float triangles, merely collecting every hit, runs at 7.6M hits/s but needs
/// 139 bytes/cell for the BVH alone, is not watertight in the sense below (float tests,
/// no common tie rule), and would still need exact re-intersection and sorting; a BVH
/// over cell boxes yields 15M candidates/s, 2.4 candidates per segment, each needing an
/// exact cell intersection. The walk was kept for exactness, watertightness by
/// construction and memory; it is bound by memory latency (random access to faces and
/// points), so spatially ordered cells and points are its main speed lever.
///
/// Each face is intersected from ONE canonical representation (corners ordered by
/// position) whichever cell asks, so the two cells of a face get bitwise the same t.
/// Planar faces: exact plane crossing. Non-planar bilinear quadrilaterals: Reshetov's
/// closed form, counted on their two triangles by the watertight rule of
/// trace/ray_frame.h. Curved faces (trace/curved_face.h): their Bernstein control net,
/// whose boundary rows are built from each edge's nodes in a canonical order and so are
/// bitwise shared with the neighbouring faces; how often the ray crosses a face is the
/// winding number of its boundary curves around the (perturbed) ray, a sum of one exact,
/// direction-antisymmetric count per edge (straight edges: the same exact segment
/// predicate as planar faces), so the counts of the faces around a closed cell sum to
/// zero and no ray leaks or double counts at an edge; each crossing is located by
/// subdividing the face into sub-patches proven injective and Newton in each. The
/// crossings are exact to the mapping tolerance except for rays tangent to a curved face
/// within about 1e-6 of its parameter range (a double root): such a pair of crossings may
/// be dropped together, which keeps the walk consistent. Measured on quadratic tets and
/// hexes bounding a paraboloid (tests/trace), by a ray's distance from tangency in
/// g = z - x^2 - y^2: chord ends within 1e-10 from 1e-9 on, 1e-9 at 1e-11..1e-10, 4e-6
/// at 1e-12..1e-11; below 1e-12 the two crossings of a nearly tangent ray may vanish
/// together. Speed (bench_trace, loaded 2-core machine): 0.5-0.6M segments/s on 69k
/// curved quadratic tets and 0.4-0.5M on 64k curved quadratic hexes (the tessellation-
/// decided test it replaced: 0.5M and 0.3M), against 7M on the same tets straight;
/// straight cells never enter the curved path. Curved data: about 650 bytes/cell for the
/// tets, 1.4 kB/cell for the hexes (control nets of every face).
/// A subset of a brick's cells with a tree of their boxes
/// (BrickTraverser::MakeCellFilter), for queries that need no other cell: an isosurface
/// only needs the cells whose range holds its value.
class CellFilter;

/// Receives a ray's segments one at a time, in t order, while a Trace finds them (see
/// BrickTraverser::Trace): a renderer whose ray ends at an opaque surface stops the walk
/// there instead of walking the cells behind it.
class SegmentSink {
  public:
    virtual ~SegmentSink() = default;
    /// Segment `index` of the Trace's `out` (and of its `seeds`) is found, and so are all
    /// before it; they will not change. False stops the Trace: `out` then ends there.
    virtual bool Take(std::size_t index) = 0;
};

class BrickTraverser {
  public:
    /// Builds the traverser. Throws InputError for meshes it cannot traverse (a face
    /// shared by more than two cells, overlapping cells, more than 2^31 - 1 faces).
    explicit BrickTraverser(const Brick& brick, const TraceOptions& options = {});
    ~BrickTraverser();
    BrickTraverser(const BrickTraverser&) = delete;
    BrickTraverser& operator=(const BrickTraverser&) = delete;

    /// Fills `out` (cleared first; caller-owned, reused without reallocation once large
    /// enough) with the segments of `ray` inside cells, clipped to the brick box and to
    /// [tMin, tMax], sorted by t, each of positive length. While the ray stays inside the
    /// mesh a segment's tExit equals the next tEnter bitwise. Thread-safe.
    void Trace(const Ray& ray, double tMin, double tMax, std::vector<Segment>& out) const;
    /// The same, and for each segment of `out` the face points where the ray enters and
    /// leaves its cell (`ends`, cleared first, one entry per segment). They are Valid
    /// where a planar tetrahedron was walked from face to face and the brick's points
    /// are its mesh's (FacePoints() is true); the segments are those of the plain Trace.
    /// With a `sink` (and no `ends`), each segment goes to it as soon as it is found, and
    /// the walk stops where the sink says so.
    void Trace(const Ray& ray, double tMin, double tMax, std::vector<Segment>& out,
               std::vector<SegmentEnds>* ends, std::vector<SegmentSeed>* seeds = nullptr,
               SegmentSink* sink = nullptr) const;
    /// The segments of the cells of `filter` only (built by this traverser), in [tMin,
    /// tMax] sorted by t: for each cell whose box (or one of whose given boxes) the ray
    /// meets, its faces' crossings
    /// paired as the walk pairs them, so a segment is the walk's segment of that cell
    /// (without walking the cells in between). Thread-safe. With a `sink`, the cells are
    /// visited in the order of their boxes along the ray, and each segment goes to the
    /// sink as soon as no cell still to visit can hold an earlier one (the same segments
    /// in the same order); the search stops where the sink says so.
    void Trace(const Ray& ray, double tMin, double tMax, std::vector<Segment>& out,
               const CellFilter& filter, std::vector<SegmentSeed>* seeds = nullptr,
               SegmentSink* sink = nullptr) const;
    /// Whether the brick has faces whose crossings give SegmentSeeds (bilinear or
    /// curved faces): the `seeds` of the Trace calls above (one per segment) are then
    /// worth asking for.
    bool HasSeeds() const;
    /// A filter of the cells c with keep[c] != 0 (keep has one entry per cell). With
    /// `boxStart` (one entry per cell and one more) and `boxes` (lo x y z, hi x y z per
    /// box), a kept cell c is found through its boxes boxes[6 boxStart[c] ..
    /// 6 boxStart[c + 1]) instead of its own box: a ray that meets none of them does not
    /// get the cell's segment (the boxes of the parts of the cell that matter, say). A
    /// kept cell without boxes is found through its own box.
    std::shared_ptr<const CellFilter> MakeCellFilter(
        const std::vector<std::uint8_t>& keep,
        const std::vector<std::int64_t>* boxStart = nullptr,
        const std::vector<float>* boxes = nullptr) const;
    /// True when the face points' corners are point indices of the brick's mesh (no two
    /// of its points were merged into one).
    bool FacePoints() const;

    const TraverserStats& Stats() const;
    TraceCounters Counters() const;
    const Brick& GetBrick() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace hpray
