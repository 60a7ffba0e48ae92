// Brick traversal: topology (coincident points merged, faces matched by merged corners,
// canonical face representations), the Embree scene over boundary faces, and the exact
// cell-to-cell walk. See brick_traverser.h for the design and trace/ray_frame.h for the
// watertightness rule.
#include "trace/brick_traverser.h"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <mutex>
#include <new>
#include <numeric>
#include <sstream>
#include <type_traits>
#include <unordered_map>

#include "elements/basis.h"
#include "trace/bilinear_patch.h"
#include "trace/curved_face.h"
#include "trace/face_map.h"
#include "trace/face_point.h"
#include "trace/ray_frame.h"
#include "util/check.h"
#include "util/error.h"

namespace hpray {
namespace {

using trace::CrossTriangle;
using trace::FaceBasis;
using trace::MakeFacePoint;
using trace::RayFrame;
using trace::ShearedPoint;
using trace::TriangleCrossing;

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr int kMaxEdgeNodes = 11;  // order 10

enum class FaceKind : std::uint8_t {
    Triangle,      // planar triangle: the crossing of its plane
    PlanarQuad,    // planar quadrilateral: two triangles of one plane
    BilinearQuad,  // non-planar straight quadrilateral: Reshetov's closed form
    Curved,     // high-order face: exact crossings of its Bernstein net (curved_face.h)
    Degenerate  // repeated corners: never crossed
};

// One face in its canonical representation: corners ordered by position (see
// Canonicalize). cell[0] is the cell the canonical normal (B - A) x (C - A) points out
// of.
struct FaceRec {
    std::int32_t v[4] = {-1, -1, -1, -1};
    std::int32_t cell[2] = {-1, -1};
    std::int32_t curved = -1;
    FaceKind kind = FaceKind::Triangle;
    // For each side s (the cell cell[s]): the local corners at the face parameters
    // (0, 0), (1, 0) and (0, 1) of its crossings, 3 bits each at bit 9 s, and bit 18 + s
    // when set (SegmentSeed). In the struct's padding.
    std::uint8_t seed[3] = {0, 0, 0};
    // A triangle of a tetrahedron with a tet code (BuildTetCodes): the corner of cell[s]
    // off this face, -1 where unknown, kept where a planar triangle has room (v[3] for
    // side 0, `curved` for side 1, neither used otherwise). The walk entering cell[s]
    // through this face reads its one new corner here, from the record it has just
    // crossed, instead of from a record of the cell's other faces, which would wait for
    // the cell's face list first.
    std::int32_t Opposite(int s) const { return s == 0 ? v[3] : curved; }
    void SetOpposite(int s, std::int32_t id) { (s == 0 ? v[3] : curved) = id; }
};
static_assert(sizeof(FaceRec) == 32);

std::uint32_t SeedBits(const FaceRec& rec) {
    return rec.seed[0] | std::uint32_t(rec.seed[1]) << 8 |
           std::uint32_t(rec.seed[2]) << 16;
}

void SetSeedCorners(FaceRec& rec, int side, int c0, int c1, int c2) {
    std::uint32_t bits = SeedBits(rec);
    bits &= ~(std::uint32_t(0x1ff) << (9 * side));
    bits |= std::uint32_t(c0 | c1 << 3 | c2 << 6) << (9 * side) | 1u << (18 + side);
    for (int k = 0; k < 3; ++k) rec.seed[k] = std::uint8_t(bits >> (8 * k));
}

// Cells whose reference coordinates of a face point are the affine image of the face
// parameters (pyramids collapse a face onto the apex), and that need them (a linear
// tetrahedron's map is inverted in closed form).
bool SeedShape(CellShape shape, int order) {
    return shape != CellShape::Pyramid && !(shape == CellShape::Tet && order == 1);
}

bool SeedCorners(const FaceRec& rec, int side, int corner[3]) {
    const std::uint32_t bits = SeedBits(rec);
    if (!(bits >> (18 + side) & 1)) return false;
    for (int k = 0; k < 3; ++k) corner[k] = bits >> (9 * side + 3 * k) & 7;
    return true;
}

// A tetrahedron's face records in its own terms. Number its corners L0, L1, L2 = the
// corners of its first face record (cellFaces order) in that record's order, and L3 =
// the corner off that face. Then the code holds, 2 bits each: at bit 2 L, which of the
// cell's faces lies opposite corner L; at bit 8 + 6 (k - 1) + 2 q (k = 1..3, q = 0..2),
// the local corner of face k's record corner q (face 0's are L0, L1, L2 by definition);
// bit 31 marks a valid code (0: none). (The walk reads L3 itself from the face records:
// FaceRec::Opposite.)
namespace tetcode {
constexpr std::uint32_t kValid = 1u << 31;
inline int FaceOpposite(std::uint32_t code, int corner) {
    return code >> (2 * corner) & 3;
}
/// The record corners' local corners of all four faces, 6 bits a face from bit 0 (face
/// 0's are 0, 1, 2).
inline std::uint32_t Corners(std::uint32_t code) {
    return (code & 0x3ffff00) >> 2 | 0x24;
}
inline int LocalCorner(std::uint32_t corners, int face, int q) {
    return corners >> (6 * face + 2 * q) & 3;
}
}  // namespace tetcode

struct CurvedRec {
    std::int64_t nodeStart = 0;  // into curvedNodes: the node lattice, j-major
    std::int64_t netStart = 0;   // into curvedNet (points): the Bernstein control net
    std::uint8_t order = 1;      // of the net (serendipity faces: a Q_2 net)
    FaceBasis basis = FaceBasis::Triangle;
    std::uint8_t straightEdges = 0;             // bit e: boundary edge e is straight
    double size = 0;                            // diagonal of the control net's box
    Box box;  // control net box, padded: holds the face
};

// A crossing of the ray with a face. side +1: along the face's canonical normal, i.e.
// out of face.cell[0] into face.cell[1]; -1: the reverse.
struct Crossing {
    double t;
    std::int32_t face;
    std::int32_t side;
    // Face parameters of the crossing (NaN where none were computed): the SegmentSeed of
    // the cell it enters or leaves.
    double u = std::numeric_limits<double>::quiet_NaN();
    double v = std::numeric_limits<double>::quiet_NaN();
};

// The crossings of a curved face for one ray, kept for the face's other cell (the walk
// visits every interior face twice): a pure function of face and ray, so reusing it is
// bitwise the same as recomputing it.
struct CurvedCacheEntry {
    std::uint64_t ray = 0;
    std::int32_t face = -1;
    std::int32_t count = 0;
    Crossing x[4];
};

struct Scratch {
    std::vector<Crossing> boundary;
    std::vector<Crossing> cell;
    std::vector<std::int64_t> candidates;  // cells whose box holds a located point
    std::vector<trace::FaceCrossing> face;
    std::vector<std::pair<Segment, SegmentSeed>> seeded;  // sorting filtered segments
    // A filtered Trace with a sink: its cells in order, per cell the number of the Trace
    // that took it, their segments not yet passed on, and one cell's segments.
    std::vector<std::pair<double, std::int64_t>> order;
    std::vector<std::uint64_t> cellMark;
    std::vector<std::pair<Segment, SegmentSeed>> waiting;
    std::vector<Segment> cellSegments;
    std::vector<SegmentSeed> cellSeeds;
    std::uint64_t ray = 0;  // id of the current Trace call on this thread
    // A planar face that PlanarCellExit or PlanarTetExit found the ray line of Trace
    // call singleRay to cross exactly once, at singleT (see PlanarCellExit).
    std::uint64_t singleRay = 0;
    std::int32_t singleFace = -1;
    double singleT = 0;
    CurvedCacheEntry cache[8];
    int cacheNext = 0;
};
thread_local Scratch tScratch;

double Now() {
    using Clock = std::chrono::steady_clock;
    return std::chrono::duration<double>(Clock::now().time_since_epoch()).count();
}

inline double Dist2(const double* a, const double* b) {
    const double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    return dx * dx + dy * dy + dz * dz;
}

// Union-find with the smallest index as the root, so merging is independent of order.
std::int64_t Find(std::vector<std::int64_t>& parent, std::int64_t i) {
    while (parent[i] != i) {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    return i;
}
void Union(std::vector<std::int64_t>& parent, std::int64_t a, std::int64_t b) {
    a = Find(parent, a);
    b = Find(parent, b);
    if (a == b) return;
    if (a < b)
        parent[b] = a;
    else
        parent[a] = b;
}

// Merges points closer than tol (world units; 0: bitwise equal) into one id; ids are
// numbered in order of the first point of each group, the representative position is
// that first point's.
void MergePoints(const std::vector<double>& points, double tol, double diag,
                 std::vector<std::int32_t>& mergedOf, std::vector<double>& xyz) {
    const std::int64_t n = static_cast<std::int64_t>(points.size() / 3);
    double lo[3] = {kInf, kInf, kInf};
    for (std::int64_t i = 0; i < n; ++i)
        for (int d = 0; d < 3; ++d) lo[d] = std::min(lo[d], points[3 * i + d]);
    // Grid cells much wider than tol: a point needs its neighbour cells only when it lies
    // within tol of its cell's side, which is rare.
    const double cellSize = diag > 0 ? std::max(16 * tol, 1e-9 * diag) : 1.0;
    std::vector<std::array<std::int64_t, 3>> key(n);
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, n, 16384),
                      [&](const tbb::blocked_range<std::int64_t>& range) {
                          for (std::int64_t i = range.begin(); i < range.end(); ++i)
                              for (int d = 0; d < 3; ++d)
                                  key[i][d] = static_cast<std::int64_t>(
                                      std::floor((points[3 * i + d] - lo[d]) / cellSize));
                      });
    std::vector<std::int64_t> order(n);
    std::iota(order.begin(), order.end(), 0);
    // (key, index) is a total order: the sorted order is unique, however it is sorted.
    tbb::parallel_sort(order.begin(), order.end(), [&](std::int64_t a, std::int64_t b) {
        const auto& ka = key[a];
        const auto& kb = key[b];
        if (ka[0] != kb[0]) return ka[0] < kb[0];
        if (ka[1] != kb[1]) return ka[1] < kb[1];
        if (ka[2] != kb[2]) return ka[2] < kb[2];
        return a < b;
    });
    std::vector<std::int64_t> parent(n);
    std::iota(parent.begin(), parent.end(), 0);
    const double tol2 = tol * tol;
    auto close = [&](std::int64_t a, std::int64_t b) {
        return tol > 0 ? Dist2(&points[3 * a], &points[3 * b]) <= tol2
                       : (points[3 * a] == points[3 * b] &&
                          points[3 * a + 1] == points[3 * b + 1] &&
                          points[3 * a + 2] == points[3 * b + 2]);
    };
    auto runOf = [&](const std::array<std::int64_t, 3>& k) {
        auto first =
            std::lower_bound(order.begin(), order.end(), k,
                             [&](std::int64_t a, const std::array<std::int64_t, 3>& kk) {
                                 return key[a] < kk;
                             });
        auto last = first;
        while (last != order.end() && key[*last] == k) ++last;
        return std::make_pair(first, last);
    };
    for (std::int64_t r = 0; r < n;) {
        std::int64_t e = r + 1;
        while (e < n && key[order[e]] == key[order[r]]) ++e;
        for (std::int64_t a = r; a < e; ++a)
            for (std::int64_t b = a + 1; b < e; ++b)
                if (close(order[a], order[b])) Union(parent, order[a], order[b]);
        r = e;
    }
    if (tol > 0) {
        for (std::int64_t i = 0; i < n; ++i) {
            int lowSide[3], highSide[3];
            bool any = false;
            for (int d = 0; d < 3; ++d) {
                const double x = points[3 * i + d] - lo[d] - key[i][d] * cellSize;
                lowSide[d] = x <= tol;
                highSide[d] = x >= cellSize - tol;
                any = any || lowSide[d] || highSide[d];
            }
            if (!any) continue;
            for (int dz = -1; dz <= 1; ++dz)
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx) {
                        const int off[3] = {dx, dy, dz};
                        bool ok = !(dx == 0 && dy == 0 && dz == 0);
                        for (int d = 0; d < 3 && ok; ++d)
                            ok = off[d] == 0 || (off[d] < 0 ? lowSide[d] : highSide[d]);
                        if (!ok) continue;
                        std::array<std::int64_t, 3> k = {key[i][0] + dx, key[i][1] + dy,
                                                         key[i][2] + dz};
                        auto [first, last] = runOf(k);
                        for (auto it = first; it != last; ++it)
                            if (close(i, *it)) Union(parent, i, *it);
                    }
        }
    }
    mergedOf.assign(n, -1);
    xyz.clear();
    std::int32_t next = 0;
    for (std::int64_t i = 0; i < n; ++i) {
        const std::int64_t root = Find(parent, i);
        if (root == i) {
            mergedOf[i] = next++;
            for (int d = 0; d < 3; ++d) xyz.push_back(points[3 * i + d]);
        } else {
            mergedOf[i] = mergedOf[root];
        }
    }
}

// Canonical order of a face given as a corner cycle of merged ids, by corner POSITION
// (lexicographic x, y, z; merged points have distinct positions), so that it does not
// depend on how points are numbered: triangles ascending, quads from the smallest corner
// towards its smaller neighbour. Returns whether the canonical cycle keeps the given
// orientation.
template <typename Less>
bool Canonicalize(const std::int32_t* ids, int n, std::int32_t* out, Less less) {
    if (n == 3) {
        int perm[3] = {0, 1, 2};
        for (int k = 1; k < 3; ++k)
            for (int q = k; q > 0 && less(ids[perm[q]], ids[perm[q - 1]]); --q)
                std::swap(perm[q], perm[q - 1]);
        for (int k = 0; k < 3; ++k) out[k] = ids[perm[k]];
        // Even permutations of (0 1 2) are the rotations.
        return (perm[1] - perm[0] + 3) % 3 == 1;
    }
    int m = 0;
    for (int k = 1; k < 4; ++k)
        if (less(ids[k], ids[m])) m = k;
    const bool forward = less(ids[(m + 1) % 4], ids[(m + 3) % 4]);
    for (int k = 0; k < 4; ++k) out[k] = ids[forward ? (m + k) % 4 : (m + 4 - k) % 4];
    return forward;
}

}  // namespace

namespace {
/// An array whose pages are first written by all threads: assign(n, value) fills it in
/// parallel (std::vector::assign is one thread's memset and page faults: 28 ms for t16's
/// 2.5M face records). Elements are plain data, never constructed one by one.
template <typename T>
class BuildArray {
    static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T>);

  public:
    void assign(std::size_t n, const T& value) {
        data_.reset(static_cast<T*>(::operator new(
            std::max<std::size_t>(n, 1) * sizeof(T), std::align_val_t(alignof(T)))));
        size_ = n;
        T* data = data_.get();
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, std::size_t(1) << 16),
                          [&](const tbb::blocked_range<std::size_t>& range) {
                              std::uninitialized_fill(data + range.begin(),
                                                      data + range.end(), value);
                          });
    }
    T& operator[](std::size_t i) { return data_.get()[i]; }
    const T& operator[](std::size_t i) const { return data_.get()[i]; }
    std::size_t size() const { return size_; }
    std::size_t capacity() const { return size_; }
    const T& back() const { return data_.get()[size_ - 1]; }

  private:
    struct Free {
        void operator()(T* p) const {
            ::operator delete(p, std::align_val_t(alignof(T)));
        }
    };
    std::unique_ptr<T, Free> data_;
    std::size_t size_ = 0;
};
}  // namespace

// The triangle a walk last left a planar tetrahedron or another cell with planar faces
// by, with its corners in the ray frame in the face record's order: the next cell's
// entry face, whose corners a planar tet need not transform again (Transform is a pure
// function of the point, so a kept corner is bitwise the one a new transform would
// give).
struct TetWalkFace {
    std::int32_t face = -1;
    int side = 0;  ///< the crossing's side: the sign of each of the face's edges
    ShearedPoint p[3];
};

struct BrickTraverser::Impl {
    Brick brick;
    TraceOptions options;
    TraverserStats stats;

    std::vector<double> xyz;  // merged points, then private points (serendipity centres)
    BuildArray<FaceRec> faces;
    BuildArray<std::int64_t> cellFaceOffset;
    BuildArray<std::int32_t> cellFaces;
    std::vector<CurvedRec> curved;
    std::vector<std::int32_t> curvedNodes;
    std::vector<double> curvedNet;  // control points of curved faces, 3 per point
    std::vector<std::int32_t> boundaryFaces;
    std::vector<float> boundaryBoxes;  // 6 per boundary face: lower, upper
    Box queryBox{};                // mesh bounds, padded for the float query ray
    double queryPad = 0;

    RTCDevice device = nullptr;
    RTCScene scene = nullptr;
    std::atomic<std::int64_t> embreeBytes{0};
    // Cells boxed like the boundary faces, for locating where a span that starts inside
    // the mesh begins (see LocateStart); built the first time one does.
    mutable std::once_flag cellSceneOnce;
    mutable RTCScene cellScene = nullptr;
    mutable std::vector<float> cellBoxes;
    mutable std::atomic<bool> cellSceneReady{false};
    // Cells walked before the span they were walked for: once they are as many as the
    // brick's cells, the cell scene (whose build costs about as much as visiting each
    // cell once) is built and spans start at located cells from then on.
    mutable std::atomic<std::int64_t> walkedBefore{0};

    mutable std::atomic<std::int64_t> newtonFailures{0};
    mutable std::atomic<std::int64_t> walkRepairs{0};
    mutable std::atomic<std::int64_t> walkFailures{0};
    mutable std::atomic<std::int64_t> locatedStarts{0};
    mutable std::atomic<std::int64_t> unpairedRays{0};

    ~Impl() {
        if (cellScene) rtcReleaseScene(cellScene);
        if (scene) rtcReleaseScene(scene);
        if (device) rtcReleaseDevice(device);
    }

    void Build();
    // BuildTopology's phases, in order; each hands its results to the next in `t`.
    struct TopologyBuild;
    void BuildTopology();
    void MergeCellPoints(TopologyBuild& t);
    void FindCellCorners(TopologyBuild& t);
    void MatchFaces(TopologyBuild& t);
    void NumberFaces(TopologyBuild& t);
    void BuildFaceRecords(TopologyBuild& t);
    void CollectBoundary(TopologyBuild& t);
    void BuildScene();

    const double* P(std::int32_t id) const {
        return &xyz[3 * static_cast<std::size_t>(id)];
    }

    // Appends every crossing of the ray line with face f (any t).
    void AppendCrossings(std::int32_t f, const RayFrame& frame,
                         std::vector<Crossing>& out) const;
    // The crossings of a Triangle or PlanarQuad face f into out (at most two), as
    // AppendCrossings appends them; their count.
    int PlanarCrossings(std::int32_t f, const FaceRec& rec, const RayFrame& frame,
                        Crossing* out) const;
    // FindExit for a cell whose nf faces cf[] are all planar (triangles, planar quads or
    // degenerate) and that the ray line crosses exactly twice: false where that is not
    // so (the general pairing then decides); else true, with found as ForEachPair's.
    // exitPoint and lastFace as FindExit's (set where c is left through a triangle).
    bool PlanarCellExit(std::int64_t c, const std::int32_t* cf, int nf,
                        std::int32_t entryFace, double entryT, const RayFrame& frame,
                        Crossing& exit, bool& found, FacePoint* exitPoint,
                        TetWalkFace* lastFace) const;
    void AppendCurvedCrossings(std::int32_t f, const RayFrame& frame,
                               std::vector<Crossing>& out) const;
    // FindExit for any other cell, by ForEachPair; exitPoint as FindExit's.
    bool GeneralCellExit(std::int64_t c, std::int32_t entryFace, double entryT,
                         const RayFrame& frame, Crossing& exit,
                         FacePoint* exitPoint) const;
    // The crossing by which the ray leaves cell c after entering it by the crossing of
    // face entryFace at (unclamped) entryT; tIn = the walk's t there (>= entryT).
    // exitPoint (optional): the exit's face point where a planar tet is left through a
    // triangle, or another cell through a triangle into a planar tet, and meshPointIds
    // holds; else not Valid.
    // lastFace (optional): the triangle the walk left its previous planar tet or other
    // planar cell by, with its corners in the ray frame, updated here (see TetWalkFace).
    bool FindExit(std::int64_t c, std::int32_t entryFace, double entryT, double tIn,
                  const RayFrame& frame, Crossing& exit, FacePoint* exitPoint = nullptr,
                  TetWalkFace* lastFace = nullptr) const;
    // FindExit for a tetrahedron c whose faces cf[0..3] are planar triangles.
    bool PlanarTetExit(std::int64_t c, const std::int32_t* cf, std::int32_t entryFace,
                       const RayFrame& frame, Crossing& exit, FacePoint* exitPoint,
                       TetWalkFace* lastFace) const;
    // The face point of the crossing `x` of triangular face f (not Valid if f is not a
    // triangle or its crossing is not x).
    void EntryPoint(const Crossing& x, const RayFrame& frame, FacePoint& fp) const;
    // EntryPoint where x leads into a planar tetrahedron (one with a tet code), whose
    // linear field the face points give (a cell of another shape left into a tet); else
    // fp is left as it is.
    void TetEntryPoint(const Crossing& x, const RayFrame& frame, FacePoint& fp) const;
    bool meshPointIds = false;  // merged point ids are the mesh's point indices
    // Every cell is a tetrahedron whose four faces are planar triangles (cell c's faces
    // at cellFaces[4 c]).
    bool planarTetsOnly = false;
    // Per cell, for tetrahedra with four triangular faces and four distinct corners
    // (else 0): how the corners of its face records relate, so that a walk step needs no
    // search by vertex id (see tetcode).
    BuildArray<std::uint32_t> tetCodes;
    void BuildTetCodes();
    bool TolerantExit(std::int64_t c, double tIn, const RayFrame& frame,
                      Crossing& exit) const;
    void Tessellation(std::int32_t f,
                      std::vector<std::array<std::int32_t, 3>>& tris) const;
    bool Leaves(const Crossing& x, std::int64_t c) const {
        return faces[x.face].cell[x.side > 0 ? 0 : 1] == c;
    }
    // The cell whose segment of the ray line holds t (entering crossing at or before t,
    // its paired leaving one after it, as FindExit pairs them), with that entering
    // crossing: where a walk from the mesh boundary would be at t, found without walking
    // there. False if no cell holds t (outside the mesh, or within rounding of a face
    // where the pairs do not meet).
    bool LocateStart(double t, const Ray& ray, const RayFrame& frame, std::int64_t& cell,
                     Crossing& entry) const;
    void BuildCellScene() const;
    // The box of cell c (its faces' corners and curved faces' control nets) padded for
    // float queries, as 6 floats (an empty box for a cell without faces).
    void CellBox(std::int64_t c, std::vector<std::array<std::int32_t, 3>>& tris,
                 float* box) const;
    // Grows [lo, hi] by face f (curved faces: their control net's box, which holds them;
    // straight ones: their corners).
    void ExtendByFace(std::int32_t f, std::vector<std::array<std::int32_t, 3>>& tris,
                      double lo[3], double hi[3]) const;
    // [lo, hi] padded by queryPad and rounded outwards to floats (an empty box for an
    // empty range).
    void FloatBox(const double lo[3], const double hi[3], float* box) const;
    // An Embree scene of `count` user primitives boxed by boxes[6 i .. 6 i + 5] whose
    // intersector appends the primitive's index to the query's candidates.
    RTCScene MakeBoxScene(const float* boxes, std::size_t count) const;
    // Cells (primitive indices of a box scene) whose boxes a float ray over [t0, t1]
    // about the ray passes through, sorted and each once (or, !sorted, in the order
    // found, possibly repeated), into `out`.
    void BoxCandidates(RTCScene boxScene, const Ray& ray, double t0, double t1,
                       std::vector<std::int64_t>& out, bool sorted = true) const;
    // The crossings of cell c's faces along the ray line, sorted and paired entering ->
    // leaving as FindExit pairs them: visit(in, out) for each pair in order, true to stop
    // (then ForEachPair returns true).
    template <typename Visit>
    bool ForEachPair(std::int64_t c, const RayFrame& frame, Visit&& visit) const;
    /// The reference point of cell c at crossing x (SegmentSeed), or NaN.
    void SeedRef(const Crossing& x, std::int64_t c, double ref[3]) const {
        ref[0] = ref[1] = ref[2] = std::numeric_limits<double>::quiet_NaN();
        if (!(x.u == x.u)) return;
        const FaceRec& rec = faces[x.face];
        const int side = rec.cell[0] == c ? 0 : rec.cell[1] == c ? 1 : -1;
        int corner[3];
        if (side < 0 || !SeedCorners(rec, side, corner)) return;
        const CellTopology& topo = Topology(brick.mesh->cellShape[c]);
        const int* a = topo.lattice[corner[0]];
        const int* b = topo.lattice[corner[1]];
        const int* d = topo.lattice[corner[2]];
        for (int k = 0; k < 3; ++k)
            ref[k] = a[k] + x.u * (b[k] - a[k]) + x.v * (d[k] - a[k]);
    }
    // Appends to `out` the segments of cell c in [tLo, tHi]: its faces' crossings paired
    // as FindExit pairs them. False when some crossing found no partner (a cell that does
    // not close up: non-conforming neighbours), where the walk would repair its way.
    // With seeds: one per segment appended.
    bool CellSegments(std::int64_t c, const RayFrame& frame, double tLo, double tHi,
                      std::vector<Segment>& out,
                      std::vector<SegmentSeed>* seeds = nullptr) const;
};

// ---------------------------------------------------------------------------------------
// Build

namespace {
constexpr const char* kSource = "mesh";
// nbCell entries other than a neighbour's index.
constexpr std::int32_t kNone = -1, kDegenerate = -2;
}  // namespace

/// What the phases of BuildTopology hand to each other; freed when it returns.
struct BrickTraverser::Impl::TopologyBuild {
    double diag = 0;                       ///< diagonal of the mesh's point bounds
    std::vector<std::int32_t> mergedOf;    ///< point -> merged id
    BuildArray<std::int32_t> corners;      ///< 8 per cell: merged ids of its corners
    BuildArray<std::int8_t> orient;        ///< per cell: +1, or -1 for a mirrored cell
    BuildArray<std::int32_t> nbCell;       ///< 6 per cell: neighbour, kNone, kDegenerate
    BuildArray<std::int8_t> nbFace;        ///< 6 per cell: the neighbour's face
    /// 6 per cell, for triangles with a neighbour: 1 where the two cells' outward corner
    /// cycles of the face turn the same way (the cells overlap), else 0.
    BuildArray<std::uint8_t> nbSameSense;
    std::int64_t nFaces = 0;
};

void BrickTraverser::Impl::Build() {
    const double t0 = Now();
    BuildTopology();
    meshPointIds = stats.mergedPoints == stats.points;
    {
        const Mesh& mesh = *brick.mesh;
        const std::int64_t n = mesh.CellCount();
        bool tets = n > 0 && static_cast<std::int64_t>(cellFaces.size()) == 4 * n;
        for (std::int64_t c = 0; c < n && tets; ++c)
            tets = mesh.cellShape[c] == CellShape::Tet && cellFaceOffset[c] == 4 * c;
        for (std::size_t f = 0; f < faces.size() && tets; ++f)
            tets = faces[f].kind == FaceKind::Triangle;
        planarTetsOnly = tets;
    }
    BuildTetCodes();
    const double t1 = Now();
    BuildScene();
    const double t2 = Now();
    stats.buildSeconds = t2 - t0;
    stats.accelSeconds = t2 - t1;
    stats.accelBytes =
        static_cast<std::size_t>(std::max<std::int64_t>(0, embreeBytes.load()));
    stats.topologyBytes = xyz.capacity() * sizeof(double) +
                          faces.capacity() * sizeof(FaceRec) +
                          cellFaceOffset.capacity() * sizeof(std::int64_t) +
                          cellFaces.capacity() * sizeof(std::int32_t) +
                          tetCodes.capacity() * sizeof(std::uint32_t) +
                          curved.capacity() * sizeof(CurvedRec) +
                          curvedNodes.capacity() * sizeof(std::int32_t) +
                          curvedNet.capacity() * sizeof(double) +
                          boundaryFaces.capacity() * sizeof(std::int32_t) +
                          boundaryBoxes.capacity() * sizeof(float);
}

void BrickTraverser::Impl::BuildTetCodes() {
    const Mesh& mesh = *brick.mesh;
    const std::int64_t n = mesh.CellCount();
    tetCodes.assign(static_cast<std::size_t>(n), 0);
    tbb::parallel_for(
        tbb::blocked_range<std::int64_t>(0, n, 16384),
        [&](const tbb::blocked_range<std::int64_t>& range) {
            for (std::int64_t c = range.begin(); c < range.end(); ++c) {
                if (mesh.cellShape[c] != CellShape::Tet ||
                    cellFaceOffset[c + 1] - cellFaceOffset[c] != 4)
                    continue;
                const std::int32_t* cf = &cellFaces[cellFaceOffset[c]];
                bool ok = true;
                for (int k = 0; k < 4; ++k)
                    ok = ok && cf[k] >= 0 && faces[cf[k]].kind == FaceKind::Triangle;
                if (!ok) continue;
                std::int32_t corner[4] = {faces[cf[0]].v[0], faces[cf[0]].v[1],
                                          faces[cf[0]].v[2], -1};
                const auto local = [&](std::int32_t v) {
                    for (int l = 0; l < 4; ++l)
                        if (corner[l] == v) return l;
                    return -1;
                };
                std::uint32_t code = 0;
                for (int q = 0; q < 3 && ok; ++q) {
                    const std::int32_t v = faces[cf[1]].v[q];
                    if (local(v) >= 0) continue;
                    ok = corner[3] < 0;  // exactly one corner of face 1 is off face 0
                    corner[3] = v;
                }
                ok = ok && corner[3] >= 0 && corner[0] != corner[1] &&
                     corner[1] != corner[2] && corner[0] != corner[2];
                int facing[4] = {-1, -1, -1, 0};
                for (int k = 1; k < 4 && ok; ++k) {
                    int seen = 0;
                    for (int q = 0; q < 3 && ok; ++q) {
                        const int l = local(faces[cf[k]].v[q]);
                        ok = l >= 0 && !(seen >> l & 1);
                        if (!ok) break;
                        seen |= 1 << l;
                        code |= std::uint32_t(l) << (8 + 6 * (k - 1) + 2 * q);
                    }
                    const int opposite = ok ? __builtin_ctz(~seen & 15) : 0;
                    ok = ok && facing[opposite] < 0;
                    if (ok) facing[opposite] = k;
                }
                if (!ok) continue;
                for (int l = 0; l < 4; ++l) code |= std::uint32_t(facing[l]) << (2 * l);
                tetCodes[static_cast<std::size_t>(c)] = code | tetcode::kValid;
                // Each face's corner off it, on c's side (every side of a face is its
                // one cell's: no two threads write one slot).
                for (int l = 0; l < 4; ++l) {
                    FaceRec& rec = faces[cf[facing[l]]];
                    rec.SetOpposite(rec.cell[0] == c ? 0 : 1, corner[l]);
                }
            }
        });
}

void BrickTraverser::Impl::BuildTopology() {
    const Mesh& mesh = *brick.mesh;
    stats.cells = mesh.CellCount();
    stats.points = mesh.PointCount();
    TopologyBuild t;
    if (mesh.PointCount() > 0) t.diag = mesh.Bounds().Diagonal();
    MergeCellPoints(t);
    FindCellCorners(t);
    MatchFaces(t);
    NumberFaces(t);
    BuildFaceRecords(t);
    CollectBoundary(t);
}

// 1. Coincident points: one merged id per distinct position.
void BrickTraverser::Impl::MergeCellPoints(TopologyBuild& t) {
    const Mesh& mesh = *brick.mesh;
    auto& mergedOf = t.mergedOf;
    const double diag = t.diag;
    if (mesh.PointCount() >= std::numeric_limits<std::int32_t>::max())
        throw InputError(kSource, "", "more than 2^31 - 1 points in one brick");
    MergePoints(mesh.points, options.mergeTolerance * diag, diag, mergedOf, xyz);
    stats.mergedPoints = static_cast<std::int64_t>(xyz.size() / 3);
}

// 2. Each cell's corners as merged ids, and its orientation.
void BrickTraverser::Impl::FindCellCorners(TopologyBuild& t) {
    const Mesh& mesh = *brick.mesh;
    const std::int64_t nCells = mesh.CellCount();
    const auto& mergedOf = t.mergedOf;
    auto& corners = t.corners;
    auto& orient = t.orient;
    corners.assign(8 * nCells, -1);
    orient.assign(nCells, 1);
    // The internal node index of each corner, per (shape, order, family) present.
    const auto slotOf = [&](std::int64_t c) {
        return (static_cast<int>(mesh.cellShape[c]) * (kMaxOrder + 1) + mesh.cellOrder[c]) * 2 +
               static_cast<int>(mesh.cellFamily[c]);
    };
    std::vector<std::array<int, 8>> cornerLocal(kNumCellShapes * (kMaxOrder + 1) * 2);
    {
        std::vector<char> seen(cornerLocal.size(), 0);
        for (std::int64_t c = 0; c < nCells; ++c) {
            const int slot = slotOf(c);
            if (seen[slot]) continue;
            seen[slot] = 1;
            const CellTopology& s = Topology(mesh.cellShape[c]);
            const int p = mesh.cellOrder[c];
            for (int k = 0; k < s.corners; ++k) {
                const LatticeIndex ijk = {s.lattice[k][0] * p, s.lattice[k][1] * p,
                                          s.lattice[k][2] * p};
                cornerLocal[slot][k] =
                    InternalNodeIndex(mesh.cellShape[c], p, mesh.cellFamily[c], ijk);
                HPRAY_CHECK(cornerLocal[slot][k] >= 0);
            }
        }
    }
    tbb::parallel_for(
        tbb::blocked_range<std::int64_t>(0, nCells, 4096),
        [&](const tbb::blocked_range<std::int64_t>& range) {
            std::vector<double> values, dRef;
            for (std::int64_t c = range.begin(); c < range.end(); ++c) {
                const CellTopology& s = Topology(mesh.cellShape[c]);
                const int p = mesh.cellOrder[c];
                const std::int64_t* nodes = mesh.CellNodes(c);
                const std::array<int, 8>& local = cornerLocal[slotOf(c)];
                for (int k = 0; k < s.corners; ++k)
                    corners[8 * c + k] = mergedOf[nodes[local[k]]];
                // Signed volume of the corner polyhedron (faces fanned from their first
                // corner).
                const double* o = &xyz[3 * std::size_t(corners[8 * c])];
                double vol = 0;
                for (int f = 0; f < s.faces; ++f) {
                    const double* a =
                        &xyz[3 * std::size_t(corners[8 * c + s.face[f][0]])];
                    for (int k = 1; k + 1 < s.faceSize[f]; ++k) {
                        const double* b =
                            &xyz[3 * std::size_t(corners[8 * c + s.face[f][k]])];
                        const double* d =
                            &xyz[3 * std::size_t(corners[8 * c + s.face[f][k + 1]])];
                        double u[3], v[3], w[3];
                        for (int i = 0; i < 3; ++i) {
                            u[i] = a[i] - o[i];
                            v[i] = b[i] - o[i];
                            w[i] = d[i] - o[i];
                        }
                        vol += u[0] * (v[1] * w[2] - v[2] * w[1]) -
                               u[1] * (v[0] * w[2] - v[2] * w[0]) +
                               u[2] * (v[0] * w[1] - v[1] * w[0]);
                    }
                }
                orient[c] = vol < 0 ? -1 : 1;
                if (p > 1) {
                    // Strongly curved cells (MFEM's twisted order-9 spiral) can have a corner
                    // polyhedron of the opposite orientation: the map's Jacobian at the
                    // reference centre decides.
                    const BasisTable& basis =
                        GetBasis(mesh.cellShape[c], p, mesh.cellFamily[c]);
                    values.resize(basis.nodeCount);
                    dRef.resize(3 * basis.nodeCount);
                    const auto centre = RefCenter(mesh.cellShape[c]);
                    EvalBasis(basis, centre.data(), values.data(), dRef.data());
                    double J[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
                    for (int m = 0; m < basis.nodeCount; ++m)
                        for (int i = 0; i < 3; ++i)
                            for (int j = 0; j < 3; ++j)
                                J[3 * i + j] += mesh.points[3 * nodes[m] + i] * dRef[3 * m + j];
                    const double det = J[0] * (J[4] * J[8] - J[5] * J[7]) -
                                       J[1] * (J[3] * J[8] - J[5] * J[6]) +
                                       J[2] * (J[3] * J[7] - J[4] * J[6]);
                    if (det != 0 && std::isfinite(det)) orient[c] = det < 0 ? -1 : 1;
                }
            }
        });
}

// 3-4. Each cell face's neighbour, by matching corner sets.
void BrickTraverser::Impl::MatchFaces(TopologyBuild& t) {
    const Mesh& mesh = *brick.mesh;
    const std::int64_t nCells = mesh.CellCount();
    const auto& corners = t.corners;
    auto& nbCell = t.nbCell;
    auto& nbFace = t.nbFace;
    const std::int64_t nMerged = static_cast<std::int64_t>(xyz.size() / 3);
    // Faces are bucketed by their smallest merged corner (a counting sort), and the keys
    // of a bucket with the same remaining corners, found by a small hash table, are the
    // two sides of one face: linear in the faces, parallel over buckets, no per-face
    // heap.
    auto sortedKey = [&](std::int64_t c, int f, std::int32_t* key) {
        const CellTopology& s = Topology(mesh.cellShape[c]);
        const int n = s.faceSize[f];
        for (int k = 0; k < n; ++k) key[k] = corners[8 * c + s.face[f][k]];
        for (int k = 1; k < n; ++k)  // insertion sort of at most 4 ids
            for (int q = k; q > 0 && key[q] < key[q - 1]; --q)
                std::swap(key[q], key[q - 1]);
        return n;
    };
    nbCell.assign(6 * nCells, kNone);
    nbFace.assign(6 * nCells, -1);
    t.nbSameSense.assign(6 * nCells, 0);
    std::atomic<std::int64_t> badCell{std::numeric_limits<std::int64_t>::max()};
    {
        // A face after its smallest corner: the other corners (a triangle's fourth is -1,
        // so triangles and quadrilaterals never match), its cell and face, and for
        // triangles the parity of its outward corner cycle by merged id. Two layouts: 16
        // bytes while cell << 4 fits 32 bits, else 20.
        struct NarrowFaceKey {
            std::int32_t k[3];
            std::uint32_t cf;  // cell << 4 | face << 1 | parity
            void Set(const std::int32_t* key, std::int64_t c, int f, int parity) {
                k[0] = key[0], k[1] = key[1], k[2] = key[2];
                cf =
                    std::uint32_t(c) << 4 | std::uint32_t(f) << 1 | std::uint32_t(parity);
            }
            std::int32_t Cell() const { return std::int32_t(cf >> 4); }
            int Face() const { return int(cf >> 1 & 7); }
            int Parity() const { return int(cf & 1); }
            bool SameFace(const NarrowFaceKey& o) const {
                return k[0] == o.k[0] && k[1] == o.k[1] && k[2] == o.k[2];
            }
        };
        struct WideFaceKey {
            std::int32_t k[3];
            std::int32_t cell;
            std::int8_t bits;  // face | parity << 3
            void Set(const std::int32_t* key, std::int64_t c, int f, int parity) {
                k[0] = key[0], k[1] = key[1], k[2] = key[2];
                cell = std::int32_t(c);
                bits = std::int8_t(f | parity << 3);
            }
            std::int32_t Cell() const { return cell; }
            int Face() const { return bits & 7; }
            int Parity() const { return bits >> 3 & 1; }
            bool SameFace(const WideFaceKey& o) const {
                return k[0] == o.k[0] && k[1] == o.k[1] && k[2] == o.k[2];
            }
        };
        // A parallel counting sort by smallest corner: the cells in kChunks ranges, each
        // with its own histogram and its own part of every bucket (the matching below
        // does not depend on the order within a bucket).
        constexpr int kChunks = 8;
        const std::int64_t chunkCells = (nCells + kChunks - 1) / kChunks;
        std::vector<std::vector<std::int64_t>> count(kChunks);
        tbb::parallel_for(0, kChunks, [&](int k) {
            std::vector<std::int64_t>& h = count[k];
            h.assign(nMerged, 0);
            std::int32_t key[4];
            const std::int64_t end = std::min(nCells, (k + 1) * chunkCells);
            for (std::int64_t c = k * chunkCells; c < end; ++c) {
                const CellTopology& s = Topology(mesh.cellShape[c]);
                for (int f = 0; f < s.faces; ++f) {
                    // The smallest corner, and whether two corners are the same point
                    // (as sortedKey's sorted run would show, without the sort).
                    const int n = s.faceSize[f];
                    for (int a = 0; a < n; ++a) key[a] = corners[8 * c + s.face[f][a]];
                    bool repeated = false;
                    std::int32_t smallest = key[0];
                    for (int a = 1; a < n; ++a) {
                        smallest = std::min(smallest, key[a]);
                        for (int b = 0; b < a; ++b)
                            repeated = repeated || key[a] == key[b];
                    }
                    if (repeated) {
                        nbCell[6 * c + f] = kDegenerate;
                        continue;
                    }
                    ++h[smallest];
                }
            }
        });
        // bucket[v]: where corner v's keys start; count[k][v] becomes chunk k's start.
        std::vector<std::int64_t> bucket(nMerged + 1, 0);
        for (std::int64_t v = 0; v < nMerged; ++v) {
            std::int64_t at = bucket[v];
            for (int k = 0; k < kChunks; ++k) {
                const std::int64_t n = count[k][v];
                count[k][v] = at;
                at += n;
            }
            bucket[v + 1] = at;
        }
        auto fillAndMatch = [&](auto keyType) {
            using FaceKey = decltype(keyType);
            // Not value-initialised: every key is written below (in parallel, so the
            // pages are first touched by both threads).
            std::unique_ptr<FaceKey[]> keys(new FaceKey[bucket.back()]);
            tbb::parallel_for(0, kChunks, [&](int k) {
                std::vector<std::int64_t>& fill = count[k];
                std::int32_t key[4];
                const std::int64_t end = std::min(nCells, (k + 1) * chunkCells);
                for (std::int64_t c = k * chunkCells; c < end; ++c) {
                    const CellTopology& s = Topology(mesh.cellShape[c]);
                    for (int f = 0; f < s.faces; ++f) {
                        if (nbCell[6 * c + f] == kDegenerate) continue;
                        const int n = sortedKey(c, f, key);
                        if (n == 3) key[3] = -1;
                        int parity = 0;
                        if (n == 3) {
                            // The outward cycle (as BuildFaceRecords walks it): its
                            // inversions.
                            std::int32_t o[3];
                            for (int q = 0; q < 3; ++q)
                                o[q] =
                                    corners[8 * c +
                                            s.face[f][t.orient[c] > 0 ? q : (3 - q) % 3]];
                            parity = ((o[0] > o[1]) + (o[0] > o[2]) + (o[1] > o[2])) & 1;
                        }
                        keys[fill[key[0]]++].Set(key + 1, c, f, parity);
                    }
                }
            });
            count.clear();
            count.shrink_to_fit();
            tbb::parallel_for(
                tbb::blocked_range<std::int64_t>(0, nMerged, 4096),
                [&](const tbb::blocked_range<std::int64_t>& range) {
                    // Equal keys of a bucket found by a small open-addressing table
                    // instead of a sort (whose comparisons go either way, a branch
                    // mispredicted at every other one): per face (the slot of its first
                    // key), how many keys it has, its second, and its lowest cell.
                    std::vector<std::int32_t> slot, second, count, lowest;
                    for (std::int64_t v = range.begin(); v < range.end(); ++v) {
                        const FaceKey* first = keys.get() + bucket[v];
                        const int m = static_cast<int>(bucket[v + 1] - bucket[v]);
                        if (m < 2) continue;
                        int size = 8;
                        while (size < 2 * m) size *= 2;
                        const std::uint32_t mask = std::uint32_t(size) - 1;
                        slot.assign(size, -1);
                        second.resize(m);
                        count.resize(m);
                        lowest.resize(m);
                        for (int i = 0; i < m; ++i) {
                            const FaceKey& key = first[i];
                            std::uint32_t h = (std::uint32_t(key.k[0]) * 0x9e3779b1u ^
                                               std::uint32_t(key.k[1]) * 0x85ebca77u ^
                                               std::uint32_t(key.k[2]) * 0xc2b2ae3du) >>
                                              7;
                            while (true) {
                                const std::int32_t at = slot[h & mask];
                                if (at < 0) {
                                    slot[h & mask] = i;
                                    count[i] = 1;
                                    lowest[i] = key.Cell();
                                    break;
                                }
                                if (first[at].SameFace(key)) {
                                    if (count[at]++ == 1) second[at] = i;
                                    lowest[at] = std::min(lowest[at], key.Cell());
                                    break;
                                }
                                ++h;
                            }
                        }
                        for (std::uint32_t h = 0; h <= mask; ++h) {
                            const std::int32_t i = slot[h];
                            if (i < 0 || count[i] < 2) continue;
                            const FaceKey& p = first[i];
                            const FaceKey& q = first[second[i]];
                            if (count[i] == 2 && p.Cell() != q.Cell()) {
                                const std::int64_t a =
                                    6 * std::int64_t(p.Cell()) + p.Face();
                                const std::int64_t b =
                                    6 * std::int64_t(q.Cell()) + q.Face();
                                nbCell[a] = q.Cell();
                                nbFace[a] = std::int8_t(q.Face());
                                nbCell[b] = p.Cell();
                                nbFace[b] = std::int8_t(p.Face());
                                if (p.k[2] < 0) {
                                    // Two cycles of the same three corners turn the same
                                    // way exactly when their parities agree.
                                    const std::uint8_t same = p.Parity() == q.Parity();
                                    t.nbSameSense[a] = t.nbSameSense[b] = same;
                                }
                            } else if (count[i] > 2) {
                                std::int64_t cur = badCell.load();
                                while (lowest[i] < cur &&
                                       !badCell.compare_exchange_weak(cur, lowest[i])) {
                                }
                            }
                        }
                    }
                });
        };
        if (nCells < (std::int64_t(1) << 28))
            fillAndMatch(NarrowFaceKey{});
        else
            fillAndMatch(WideFaceKey{});
    }
    if (badCell.load() != std::numeric_limits<std::int64_t>::max()) {
        std::ostringstream where;
        where << "cell " << badCell.load();
        throw InputError(kSource, where.str(), "a face is shared by more than two cells");
    }
}

// 5. One id per face: a face belongs to the lower-numbered of its cells.
void BrickTraverser::Impl::NumberFaces(TopologyBuild& t) {
    const Mesh& mesh = *brick.mesh;
    const std::int64_t nCells = mesh.CellCount();
    const auto& nbCell = t.nbCell;
    const auto& nbFace = t.nbFace;
    std::int64_t& nFaces = t.nFaces;
    cellFaceOffset.assign(nCells + 1, 0);
    for (std::int64_t c = 0; c < nCells; ++c)
        cellFaceOffset[c + 1] = cellFaceOffset[c] + Topology(mesh.cellShape[c]).faces;
    cellFaces.assign(cellFaceOffset.back(), -1);
    // Ids in cell order, as one sequential pass would give them: the faces each range of
    // cells owns are counted, then numbered from the range's start.
    const std::int64_t chunkCells = 16384;
    const std::int64_t chunks = (nCells + chunkCells - 1) / chunkCells;
    std::vector<std::int64_t> chunkStart(chunks + 1, 0);
    auto owned = [&](std::int64_t c, int f) {
        const std::int32_t nb = nbCell[6 * c + f];
        return nb < 0 || c < nb;
    };
    tbb::parallel_for(std::int64_t(0), chunks, [&](std::int64_t k) {
        std::int64_t count = 0;
        const std::int64_t end = std::min(nCells, (k + 1) * chunkCells);
        for (std::int64_t c = k * chunkCells; c < end; ++c) {
            const int nf = Topology(mesh.cellShape[c]).faces;
            for (int f = 0; f < nf; ++f) count += owned(c, f);
        }
        chunkStart[k + 1] = count;
    });
    for (std::int64_t k = 0; k < chunks; ++k) chunkStart[k + 1] += chunkStart[k];
    nFaces = chunkStart[chunks];
    if (nFaces >= std::numeric_limits<std::int32_t>::max())
        throw InputError(kSource, "", "more than 2^31 - 1 faces in one brick");
    tbb::parallel_for(std::int64_t(0), chunks, [&](std::int64_t k) {
        std::int64_t next = chunkStart[k];
        const std::int64_t end = std::min(nCells, (k + 1) * chunkCells);
        for (std::int64_t c = k * chunkCells; c < end; ++c) {
            const int nf = Topology(mesh.cellShape[c]).faces;
            for (int f = 0; f < nf; ++f)
                if (owned(c, f)) cellFaces[cellFaceOffset[c] + f] = std::int32_t(next++);
        }
    });
    // A shared face's id, from the lower-numbered cell that owns it (all numbered above).
    tbb::parallel_for(
        tbb::blocked_range<std::int64_t>(0, nCells, 4096),
        [&](const tbb::blocked_range<std::int64_t>& range) {
            for (std::int64_t c = range.begin(); c < range.end(); ++c) {
                const int nf = Topology(mesh.cellShape[c]).faces;
                for (int f = 0; f < nf; ++f) {
                    const std::int32_t nb = nbCell[6 * c + f];
                    if (nb >= 0 && nb < c)
                        cellFaces[cellFaceOffset[c] + f] =
                            cellFaces[cellFaceOffset[nb] + nbFace[6 * c + f]];
                }
            }
        });
}

// 6. The canonical record of every face and its geometry.
void BrickTraverser::Impl::BuildFaceRecords(TopologyBuild& t) {
    const Mesh& mesh = *brick.mesh;
    const std::int64_t nCells = mesh.CellCount();
    const auto& corners = t.corners;
    const auto& orient = t.orient;
    const auto& nbCell = t.nbCell;
    const auto& nbFace = t.nbFace;
    const auto& nbSameSense = t.nbSameSense;
    const std::int64_t nFaces = t.nFaces;
    const auto& mergedOf = t.mergedOf;
    faces.assign(nFaces, FaceRec{});
    const auto byPosition = [this](std::int32_t a, std::int32_t b) {
        const double* x = P(a);
        const double* y = P(b);
        return x[0] != y[0] ? x[0] < y[0] : x[1] != y[1] ? x[1] < y[1] : x[2] < y[2];
    };
    // The merged points' ranks in byPosition order. Merged points have distinct
    // positions, so the order is total and comparing ranks is comparing positions, from
    // a small array instead of three coordinates of two random points.
    const std::int64_t nMerged = static_cast<std::int64_t>(xyz.size() / 3);
    std::vector<std::int32_t> rank(nMerged);
    {
        std::vector<std::int32_t> order(nMerged);
        std::iota(order.begin(), order.end(), 0);
        tbb::parallel_sort(order.begin(), order.end(), byPosition);
        tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, nMerged, 16384),
                          [&](const tbb::blocked_range<std::int64_t>& range) {
                              for (std::int64_t i = range.begin(); i < range.end(); ++i)
                                  rank[order[i]] = std::int32_t(i);
                          });
    }
    const auto byRank = [&rank](std::int32_t a, std::int32_t b) {
        return rank[a] < rank[b];
    };
    // Boundary edge e of a face lattice, as merged ids in the edge's canonical direction
    // (from its lower corner by position), so that every face holding the edge sees the
    // same sequence; returns whether that reverses the face's counter-clockwise order.
    // The inner nodes of an edge are those of the first face that registers it (keyed by
    // its end points and order): cells that disagree on them (non-conforming output, such
    // as deal.II's curved_boundary patches, where a curved boundary cell and its straight
    // interior neighbour write different edge nodes) still give every face around the
    // edge the same boundary curve, so the faces of each cell stay closed.
    struct EdgeNodes {
        int order = 0;
        bool mismatched = false;
        std::array<std::int32_t, kMaxEdgeNodes> ids{};
    };
    std::unordered_map<std::uint64_t, EdgeNodes> edgeNodes;
    auto canonicalEdge = [&](const std::vector<std::int32_t>& lattice, bool tri, int p,
                             int e, std::int32_t* ids) {
        for (int k = 0; k <= p; ++k)
            ids[k] = lattice[trace::EdgeLatticeIndex(tri, p, e, k)];
        const bool reversed = byPosition(ids[p], ids[0]);
        if (reversed) std::reverse(ids, ids + p + 1);
        if (p > 1) {
            const std::uint64_t key =
                std::uint64_t(std::uint32_t(ids[0])) << 32 | std::uint32_t(ids[p]);
            auto [it, inserted] = edgeNodes.try_emplace(key);
            EdgeNodes& known = it->second;
            if (inserted) {
                known.order = p;
                std::copy(ids, ids + p + 1, known.ids.begin());
            } else if (known.order == p) {
                for (int k = 1; k < p; ++k) {
                    if (ids[k] == known.ids[k]) continue;
                    if (!known.mismatched) ++stats.nonConformingEdges;
                    known.mismatched = true;
                    const double d = std::sqrt(Dist2(P(ids[k]), P(known.ids[k])));
                    const double len = std::sqrt(Dist2(P(ids[0]), P(ids[p])));
                    stats.nonConformity = std::max(stats.nonConformity, d / len);
                    ids[k] = known.ids[k];
                }
            }
        }
        return reversed;
    };
    // Whether an edge (canonical ids) is straight: a function of the edge alone, so that
    // all faces around it count it by the same rule (curved_face.h).
    auto edgeIsStraight = [&](const std::int32_t* ids, int p) {
        const double* a = P(ids[0]);
        const double* b = P(ids[p]);
        const double tol2 = std::pow(options.straightTolerance, 2) * Dist2(a, b);
        for (int k = 1; k < p; ++k) {
            double lin[3];
            for (int d = 0; d < 3; ++d) lin[d] = a[d] + (double(k) / p) * (b[d] - a[d]);
            if (Dist2(P(ids[k]), lin) > tol2) return false;
        }
        return true;
    };
    // Whether any cell takes seeds (none in a mesh of linear tetrahedra alone).
    bool seedCells = false;
    for (std::int64_t c = 0; c < nCells && !seedCells; ++c)
        seedCells = SeedShape(mesh.cellShape[c], mesh.cellOrder[c]);
    // Merged ids of cell c's nodes on the lattice of one of its faces, row by row from
    // the face corner at local corner canonLocal[0] (-1: a serendipity face centre).
    auto faceLattice = [&](std::int64_t c, const int* canonLocal, int n, int p,
                           std::vector<std::int32_t>& out) {
        const CellTopology& s = Topology(mesh.cellShape[c]);
        const CellFamily family = mesh.cellFamily[c];
        const int* L[4];
        for (int k = 0; k < n; ++k) L[k] = s.lattice[canonLocal[k]];
        const std::int64_t* nodes = mesh.CellNodes(c);
        out.clear();
        for (int j = 0; j <= p; ++j)
            for (int i = 0; i <= (n == 3 ? p - j : p); ++i) {
                LatticeIndex ijk;
                for (int d = 0; d < 3; ++d)
                    ijk[d] = n == 3 ? (p - i - j) * L[0][d] + i * L[1][d] + j * L[2][d]
                                    : p * L[0][d] + i * (L[1][d] - L[0][d]) +
                                          j * (L[3][d] - L[0][d]);
                const int node = InternalNodeIndex(mesh.cellShape[c], p, family, ijk);
                out.push_back(node < 0 ? -1 : mergedOf[nodes[node]]);
            }
    };
    std::vector<std::int32_t> neighbourLattice;
    auto outwardCycle = [&](std::int64_t c, int f, std::int32_t* ids, int* local) {
        const CellTopology& s = Topology(mesh.cellShape[c]);
        const int n = s.faceSize[f];
        for (int k = 0; k < n; ++k) {
            const int kk = orient[c] > 0 ? k : (k == 0 ? 0 : n - k);
            local[k] = s.face[f][kk];
            ids[k] = corners[8 * c + local[k]];
        }
        return n;
    };
    // A face is built by the lower-numbered of its cells. Faces of order-1 cells touch
    // nothing but their own record, so they are built in parallel; faces of high-order
    // cells share the edge table and the curved arrays, and are built in cell order.
    std::atomic<std::int64_t> bilinearFaces{0};
    std::atomic<std::int64_t> overlap{std::numeric_limits<std::int64_t>::max()};
    std::vector<std::int32_t> overlapNeighbour(1, -1);
    auto buildFaces = [&](std::int64_t c) {
        const CellTopology& s = Topology(mesh.cellShape[c]);
        for (int f = 0; f < s.faces; ++f) {
            const std::int32_t nb = nbCell[6 * c + f];
            if (!(nb < 0 || c < nb)) continue;
            FaceRec& rec = faces[cellFaces[cellFaceOffset[c] + f]];
            std::int32_t ids[4], canon[4];
            int local[4];
            const int n = outwardCycle(c, f, ids, local);
            if (nb == kDegenerate) {
                rec.kind = FaceKind::Degenerate;
                std::copy(ids, ids + n, rec.v);
                rec.cell[0] = std::int32_t(c);
                continue;
            }
            const bool same = Canonicalize(ids, n, canon, byRank);
            std::copy(canon, canon + n, rec.v);
            rec.cell[same ? 0 : 1] = std::int32_t(c);
            if (nb >= 0) {
                // The neighbour's canonical sense: for a triangle from the parities that
                // MatchFaces compared (no visit to the neighbour's corners); a
                // quadrilateral's cycles may differ by more than their sense.
                bool same2;
                if (n == 3) {
                    same2 = nbSameSense[6 * c + f] ? same : !same;
                } else {
                    std::int32_t ids2[4], canon2[4];
                    int local2[4];
                    outwardCycle(nb, nbFace[6 * c + f], ids2, local2);
                    same2 = Canonicalize(ids2, n, canon2, byRank);
                }
                if (same2 == same) {
                    // Reported after the loop, for the lowest cell whatever the order.
                    static std::mutex overlapMutex;
                    std::lock_guard<std::mutex> lock(overlapMutex);
                    if (c < overlap.load()) {
                        overlap.store(c);
                        overlapNeighbour[0] = nb;
                    }
                    continue;
                }
                rec.cell[same2 ? 0 : 1] = nb;
            }
            const int p = mesh.cellOrder[c];
            // The local corner of each canonical corner, in c and (once asked for) in nb
            // (-1 where the neighbour lacks one).
            int canonLocal[4], nbLocal[4];
            bool nbKnown = false;
            auto localOfCanonical = [&](const std::int32_t* cycle, const int* cycleLocal,
                                        int* out) {
                for (int k = 0; k < n; ++k) {
                    out[k] = -1;
                    for (int q = 0; q < n; ++q)
                        if (cycle[q] == canon[k]) out[k] = cycleLocal[q];
                }
            };
            auto neighbourLocal = [&]() -> const int* {
                if (!nbKnown) {
                    std::int32_t ids2[4];
                    int local2[4];
                    outwardCycle(nb, nbFace[6 * c + f], ids2, local2);
                    localOfCanonical(ids2, local2, nbLocal);
                    nbKnown = true;
                }
                return nbLocal;
            };
            const bool linearTriangle = n == 3 && p == 1;
            if (seedCells || !linearTriangle) localOfCanonical(ids, local, canonLocal);
            // Seeds: each side's local corners at the face parameters (0, 0), (1, 0) and
            // (0, 1) (canonical corners 0, 1 and the last: the lattice of faceLattice,
            // the net of FaceBernstein and the patch of IntersectBilinearPatch alike).
            // Nothing for two linear tetrahedra (most faces of a large tetrahedral mesh).
            const int last = n - 1;
            if (seedCells && SeedShape(mesh.cellShape[c], p))
                SetSeedCorners(rec, rec.cell[0] == c ? 0 : 1, canonLocal[0],
                               canonLocal[1], canonLocal[last]);
            if (seedCells && nb >= 0 &&
                SeedShape(mesh.cellShape[nb], mesh.cellOrder[nb])) {
                const int* l = neighbourLocal();
                if (l[0] >= 0 && l[1] >= 0 && l[last] >= 0)
                    SetSeedCorners(rec, rec.cell[0] == nb ? 0 : 1, l[0], l[1], l[last]);
            }
            if (linearTriangle) {
                rec.kind = FaceKind::Triangle;  // a straight triangle: nothing to measure
                continue;
            }
            const double* A = P(canon[0]);
            const double* B = P(canon[1]);
            const double* C = P(canon[2]);
            double lo[3], hi[3];
            for (int d = 0; d < 3; ++d) {
                lo[d] = hi[d] = A[d];
                for (int k = 1; k < n; ++k) {
                    lo[d] = std::min(lo[d], P(canon[k])[d]);
                    hi[d] = std::max(hi[d], P(canon[k])[d]);
                }
            }
            double size = std::sqrt(Dist2(lo, hi));
            const double tol = options.straightTolerance * size;
            // Straight? Compare every face node with the (bi)linear face of the corners.
            const CellFamily family = mesh.cellFamily[c];
            const FaceBasis basis = n == 3 ? FaceBasis::Triangle
                                    : family == CellFamily::Serendipity
                                        ? FaceBasis::QuadSerendipity
                                        : FaceBasis::Quad;
            bool straight = true;
            std::vector<std::int32_t> lattice;  // merged ids on the tessellation lattice
            if (p > 1) {
                faceLattice(c, canonLocal, n, p, lattice);
                if (nb >= 0 && mesh.cellOrder[nb] == p && mesh.cellFamily[nb] == family) {
                    // The neighbour's own nodes of the same face, in the same order.
                    faceLattice(nb, neighbourLocal(), n, p, neighbourLattice);
                    double worst = 0;
                    for (std::size_t k = 0; k < lattice.size(); ++k)
                        if (lattice[k] != neighbourLattice[k] && lattice[k] >= 0 &&
                            neighbourLattice[k] >= 0)
                            worst = std::max(
                                worst, Dist2(P(lattice[k]), P(neighbourLattice[k])));
                    if (worst > 0) {
                        ++stats.nonConformingFaces;
                        stats.nonConformity =
                            std::max(stats.nonConformity, std::sqrt(worst) / size);
                    }
                }
                for (int j = 0, at = 0; j <= p; ++j)
                    for (int i = 0; i <= (n == 3 ? p - j : p); ++i, ++at) {
                        const std::int32_t id = lattice[at];
                        if (id < 0) continue;  // serendipity face centre
                        const double u = double(i) / p, v = double(j) / p;
                        const double* X = P(id);
                        double dev2 = 0;
                        for (int d = 0; d < 3; ++d) {
                            const double lin =
                                n == 3 ? A[d] + u * (B[d] - A[d]) + v * (C[d] - A[d])
                                       : (1 - u) * (1 - v) * A[d] + u * (1 - v) * B[d] +
                                             u * v * C[d] + (1 - u) * v * P(canon[3])[d];
                            dev2 += (X[d] - lin) * (X[d] - lin);
                        }
                        if (dev2 > tol * tol) straight = false;
                    }
                // A straight face needs edges straight by the edge rule too: a curved
                // neighbour counts the shared edge by that rule.
                std::int32_t ids[kMaxEdgeNodes];
                for (int e = 0; e < n && straight; ++e) {
                    if (basis == FaceBasis::QuadSerendipity) {
                        canonicalEdge(lattice, false, 2, e, ids);
                        straight = edgeIsStraight(ids, 2);
                    } else {
                        canonicalEdge(lattice, n == 3, p, e, ids);
                        straight = edgeIsStraight(ids, p);
                    }
                }
            }
            if (straight) {
                if (n == 3) {
                    rec.kind = FaceKind::Triangle;
                } else {
                    const double* D = P(canon[3]);
                    double e1[3], e2[3], e3[3], nrm[3];
                    for (int d = 0; d < 3; ++d) {
                        e1[d] = B[d] - A[d];
                        e2[d] = C[d] - A[d];
                        e3[d] = D[d] - A[d];
                    }
                    nrm[0] = e1[1] * e2[2] - e1[2] * e2[1];
                    nrm[1] = e1[2] * e2[0] - e1[0] * e2[2];
                    nrm[2] = e1[0] * e2[1] - e1[1] * e2[0];
                    const double len =
                        std::sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
                    const double off =
                        std::fabs(nrm[0] * e3[0] + nrm[1] * e3[1] + nrm[2] * e3[2]);
                    rec.kind =
                        off <= tol * len ? FaceKind::PlanarQuad : FaceKind::BilinearQuad;
                    if (rec.kind == FaceKind::BilinearQuad)
                        bilinearFaces.fetch_add(1, std::memory_order_relaxed);
                }
                continue;
            }
            // Curved: keep its lattice (serendipity: plus its centre as a private point).
            rec.kind = FaceKind::Curved;
            CurvedRec cr;
            cr.order = std::uint8_t(basis == FaceBasis::QuadSerendipity ? 2 : p);
            cr.basis = basis;
            cr.nodeStart = static_cast<std::int64_t>(curvedNodes.size());
            if (basis == FaceBasis::QuadSerendipity) {
                HPRAY_CHECK_EQ(lattice.size(), std::size_t(9));
                double values[8], centre[3] = {0, 0, 0};
                trace::EvalFaceBasis(basis, 2, 0.5, 0.5, values, nullptr, nullptr);
                for (int m = 0, k = 0; k < 9; ++k) {
                    if (k == 4) continue;
                    for (int d = 0; d < 3; ++d) centre[d] += values[m] * P(lattice[k])[d];
                    ++m;
                }
                lattice[4] = std::int32_t(xyz.size() / 3);
                xyz.insert(xyz.end(), centre, centre + 3);
            }
            for (std::int32_t id : lattice) HPRAY_CHECK(id >= 0);
            curvedNodes.insert(curvedNodes.end(), lattice.begin(), lattice.end());
            // The canonical face: its Bernstein net, with every boundary row replaced by
            // the control points of the edge built from the edge's nodes in canonical
            // order (straight edges: points on the segment), bitwise shared with its
            // neighbours.
            {
                const bool tri = basis == FaceBasis::Triangle;
                const int q = cr.order;
                const int nNet = trace::NetSize(tri, q);
                std::vector<double> nodal(3 * nNet), net(3 * nNet);
                for (int k = 0; k < nNet; ++k)
                    for (int d = 0; d < 3; ++d) nodal[3 * k + d] = P(lattice[k])[d];
                trace::FaceBernstein(tri, q, nodal.data(), net.data());
                std::int32_t ids[kMaxEdgeNodes];
                double edgeNodal[3 * kMaxEdgeNodes], row[3 * kMaxEdgeNodes];
                for (int e = 0; e < (tri ? 3 : 4); ++e) {
                    const bool reversed = canonicalEdge(lattice, tri, q, e, ids);
                    const double* a = P(ids[0]);
                    const double* b = P(ids[q]);
                    if (edgeIsStraight(ids, q)) {
                        cr.straightEdges = std::uint8_t(cr.straightEdges | (1u << e));
                        for (int k = 0; k <= q; ++k)
                            for (int d = 0; d < 3; ++d)
                                row[3 * k + d] =
                                    k == 0   ? a[d]
                                    : k == q ? b[d]
                                             : a[d] + (double(k) / q) * (b[d] - a[d]);
                    } else {
                        for (int k = 0; k <= q; ++k)
                            for (int d = 0; d < 3; ++d)
                                edgeNodal[3 * k + d] = P(ids[k])[d];
                        trace::EdgeBernstein(q, edgeNodal, row);
                    }
                    for (int k = 0; k <= q; ++k) {
                        const int idx = trace::EdgeLatticeIndex(tri, q, e, k);
                        for (int d = 0; d < 3; ++d)
                            net[3 * idx + d] = row[3 * (reversed ? q - k : k) + d];
                    }
                }
                cr.netStart = static_cast<std::int64_t>(curvedNet.size() / 3);
                curvedNet.insert(curvedNet.end(), net.begin(), net.end());
                for (int d = 0; d < 3; ++d) {
                    lo[d] = kInf;
                    hi[d] = -kInf;
                    for (int k = 0; k < nNet; ++k) {
                        lo[d] = std::min(lo[d], net[3 * k + d]);
                        hi[d] = std::max(hi[d], net[3 * k + d]);
                    }
                }
            }
            size = std::sqrt(Dist2(lo, hi));
            cr.size = size;
            for (int d = 0; d < 3; ++d) {
                const double pad = 1e-9 * size + 1e-300;
                cr.box.lo[d] = lo[d] - pad;
                cr.box.hi[d] = hi[d] + pad;
            }
            rec.curved = static_cast<std::int32_t>(curved.size());
            curved.push_back(cr);
        }
    };
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, nCells, 2048),
                      [&](const tbb::blocked_range<std::int64_t>& range) {
                          for (std::int64_t c = range.begin(); c < range.end(); ++c)
                              if (mesh.cellOrder[c] == 1) buildFaces(c);
                      });
    for (std::int64_t c = 0; c < nCells; ++c)
        if (mesh.cellOrder[c] != 1) buildFaces(c);
    stats.bilinearFaces += bilinearFaces.load();
    if (overlap.load() != std::numeric_limits<std::int64_t>::max()) {
        std::ostringstream where;
        where << "cells " << overlap.load() << " and " << overlapNeighbour[0];
        throw InputError(kSource, where.str(),
                         "cells overlap (they lie on the same side of their shared face)");
    }
}

// 7. Boundary faces, their boxes and the padded query box of the Embree scene.
void BrickTraverser::Impl::CollectBoundary(TopologyBuild& t) {
    const Mesh& mesh = *brick.mesh;
    const std::int64_t nFaces = t.nFaces;
    const double diag = t.diag;
    const auto bounds = mesh.Bounds();
    // Grown face by face: give back the doubling slack.
    xyz.shrink_to_fit();
    curved.shrink_to_fit();
    curvedNodes.shrink_to_fit();
    curvedNet.shrink_to_fit();
    stats.faces = nFaces;
    stats.curvedFaces = static_cast<std::int64_t>(curved.size());
    for (std::int64_t f = 0; f < nFaces; ++f) {
        const FaceRec& rec = faces[f];
        if (rec.kind != FaceKind::Degenerate && (rec.cell[0] < 0 || rec.cell[1] < 0))
            boundaryFaces.push_back(std::int32_t(f));
    }
    stats.boundaryFaces = static_cast<std::int64_t>(boundaryFaces.size());

    // Mesh box for the float query ray, padded so that float rounding of the ray (about
    // 6e-8 of the coordinates) never culls a face the exact test would hit.
    double maxAbs = 0;
    for (int d = 0; d < 3; ++d)
        maxAbs = std::max({maxAbs, std::fabs(bounds.lo[d]), std::fabs(bounds.hi[d])});
    queryPad = 1e-6 * (maxAbs + diag) + 1e-30;
    for (int d = 0; d < 3; ++d) {
        queryBox.lo[d] = bounds.lo[d] - queryPad;
        queryBox.hi[d] = bounds.hi[d] + queryPad;
    }
    // Curved faces may bulge out of their node hull: they are boxed by their control net
    // (which holds the face); straight faces by their corners.
    boundaryBoxes.resize(6 * boundaryFaces.size());
    std::vector<std::array<std::int32_t, 3>> tris;
    for (std::size_t b = 0; b < boundaryFaces.size(); ++b) {
        double lo[3] = {kInf, kInf, kInf}, hi[3] = {-kInf, -kInf, -kInf};
        ExtendByFace(boundaryFaces[b], tris, lo, hi);
        FloatBox(lo, hi, &boundaryBoxes[6 * b]);
    }
}


void BrickTraverser::Impl::Tessellation(
    std::int32_t f, std::vector<std::array<std::int32_t, 3>>& tris) const {
    tris.clear();
    const FaceRec& rec = faces[f];
    switch (rec.kind) {
        case FaceKind::Degenerate:
            return;
        case FaceKind::Triangle:
            tris.push_back({rec.v[0], rec.v[1], rec.v[2]});
            return;
        case FaceKind::PlanarQuad:
        case FaceKind::BilinearQuad:
            tris.push_back({rec.v[0], rec.v[1], rec.v[2]});
            tris.push_back({rec.v[0], rec.v[2], rec.v[3]});
            return;
        case FaceKind::Curved:
            break;
    }
    const CurvedRec& cr = curved[rec.curved];
    const std::int32_t* ids = &curvedNodes[cr.nodeStart];
    const int p = cr.order;
    if (cr.basis == FaceBasis::Triangle) {
        auto idx = [p](int i, int j) { return j * (p + 1) - j * (j - 1) / 2 + i; };
        for (int j = 0; j < p; ++j)
            for (int i = 0; i < p - j; ++i) {
                tris.push_back({ids[idx(i, j)], ids[idx(i + 1, j)], ids[idx(i, j + 1)]});
                if (i + j + 2 <= p)
                    tris.push_back(
                        {ids[idx(i + 1, j)], ids[idx(i + 1, j + 1)], ids[idx(i, j + 1)]});
            }
    } else {
        auto idx = [p](int i, int j) { return j * (p + 1) + i; };
        for (int j = 0; j < p; ++j)
            for (int i = 0; i < p; ++i) {
                tris.push_back(
                    {ids[idx(i, j)], ids[idx(i + 1, j)], ids[idx(i + 1, j + 1)]});
                tris.push_back(
                    {ids[idx(i, j)], ids[idx(i + 1, j + 1)], ids[idx(i, j + 1)]});
            }
    }
}

// ---------------------------------------------------------------------------------------
// Embree: boundary faces as user geometry whose intersector records every exact crossing.

namespace {

struct QueryContext {
    RTCIntersectContext base;  // first member: Embree passes &base back to the callbacks
    const void* impl;          // the BrickTraverser::Impl
    const RayFrame* frame;
    std::vector<Crossing>* hits;
};

// Bounds of user primitive i: boxes[6 i .. 6 i + 5] (lower, upper) of the float array
// that is the geometry's user data.
void BoxBounds(const RTCBoundsFunctionArguments* args) {
    const float* b =
        static_cast<const float*>(args->geometryUserPtr) + 6 * std::size_t(args->primID);
    args->bounds_o->lower_x = b[0];
    args->bounds_o->lower_y = b[1];
    args->bounds_o->lower_z = b[2];
    args->bounds_o->upper_x = b[3];
    args->bounds_o->upper_y = b[4];
    args->bounds_o->upper_z = b[5];
}

// The float query ray over [t0 - pad, t1 + pad] of the ray (a little longer, for the
// float rounding of its length).
RTCRayHit QueryRay(const Ray& ray, double t0, double t1, double pad) {
    RTCRayHit rh;
    const double s0 = t0 - pad;
    rh.ray.org_x = float(ray.origin[0] + s0 * ray.dir[0]);
    rh.ray.org_y = float(ray.origin[1] + s0 * ray.dir[1]);
    rh.ray.org_z = float(ray.origin[2] + s0 * ray.dir[2]);
    rh.ray.dir_x = float(ray.dir[0]);
    rh.ray.dir_y = float(ray.dir[1]);
    rh.ray.dir_z = float(ray.dir[2]);
    rh.ray.tnear = 0.0f;
    rh.ray.tfar = float((t1 - t0) + 2 * pad) * (1 + 1e-6f);
    rh.ray.time = 0.0f;
    rh.ray.mask = 0xFFFFFFFFu;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    return rh;
}

// Attaches the user geometry to the scene, commits both and reports Embree's error.
void CommitUserScene(RTCDevice device, RTCScene scene, RTCGeometry geom,
                     const char* what) {
    rtcSetGeometryOccludedFunction(geom, [](const RTCOccludedFunctionNArguments*) {});
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(scene);
    const RTCError err = rtcGetDeviceError(device);
    if (err != RTC_ERROR_NONE) {
        std::ostringstream os;
        os << "Embree " << what << " build failed (error " << int(err) << ")";
        throw InternalError(os.str());
    }
}

}  // namespace

void BrickTraverser::Impl::BuildScene() {
    device = rtcNewDevice(nullptr);
    if (!device) throw InternalError("Embree device creation failed");
    rtcSetDeviceMemoryMonitorFunction(
        device,
        [](void* user, ssize_t bytes, bool) {
            static_cast<std::atomic<std::int64_t>*>(user)->fetch_add(bytes);
            return true;
        },
        &embreeBytes);
    scene = rtcNewScene(device);
    rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(geom, static_cast<unsigned>(boundaryFaces.size()));
    rtcSetGeometryUserData(geom, boundaryBoxes.data());
    rtcSetGeometryBoundsFunction(geom, BoxBounds, nullptr);
    rtcSetGeometryIntersectFunction(geom, [](const RTCIntersectFunctionNArguments* args) {
        if (!args->valid[0]) return;
        const auto* ctx = reinterpret_cast<const QueryContext*>(args->context);
        const auto* self = static_cast<const Impl*>(ctx->impl);
        self->AppendCrossings(self->boundaryFaces[args->primID], *ctx->frame, *ctx->hits);
    });
    CommitUserScene(device, scene, geom, "scene");
}

// ---------------------------------------------------------------------------------------
// Crossings

void BrickTraverser::Impl::AppendCrossings(std::int32_t f, const RayFrame& frame,
                                           std::vector<Crossing>& out) const {
    const FaceRec& rec = faces[f];
    TriangleCrossing x;
    switch (rec.kind) {
        case FaceKind::Degenerate:
            return;
        case FaceKind::Triangle:
        case FaceKind::PlanarQuad: {
            Crossing xs[2];
            const int n = PlanarCrossings(f, rec, frame, xs);
            for (int k = 0; k < n; ++k) out.push_back(xs[k]);
            return;
        }
        case FaceKind::BilinearQuad: {
            const ShearedPoint a = frame.Transform(P(rec.v[0]));
            const ShearedPoint b = frame.Transform(P(rec.v[1]));
            const ShearedPoint c = frame.Transform(P(rec.v[2]));
            const ShearedPoint d = frame.Transform(P(rec.v[3]));
            // Tessellated hits decide the count and the sides; (u, v) of each hit on the
            // patch: triangle ABC covers u >= v, ACD covers v >= u.
            double hu[2], hv[2], ht[2];
            int hs[2];
            int nh = 0;
            if (CrossTriangle(a, b, c, x)) {
                hu[nh] = x.bary[1] + x.bary[2];
                hv[nh] = x.bary[2];
                ht[nh] = x.t;
                hs[nh++] = x.side;
            }
            if (CrossTriangle(a, c, d, x)) {
                hu[nh] = x.bary[1];
                hv[nh] = x.bary[1] + x.bary[2];
                ht[nh] = x.t;
                hs[nh++] = x.side;
            }
            if (nh == 0) return;
            trace::PatchRoot roots[2];
            const int nr = trace::IntersectBilinearPatch(frame.org, frame.dir,
                                                         P(rec.v[0]), P(rec.v[1]),
                                                         P(rec.v[2]), P(rec.v[3]), roots);
            if (nh == 1) {
                // The tessellation and the patch share their boundary, so a line crossing
                // the tessellation once crosses the patch an odd number of times: once.
                // Take the root inside the patch (u, v in [0, 1]); near the patch
                // boundary, where rounding can put it just outside, the one least
                // outside, and between equals the one nearest the tessellated hit.
                int best = -1;
                double bestOut = kInf, bestD = kInf;
                for (int r = 0; r < nr; ++r) {
                    const double u = roots[r].u, v = roots[r].v;
                    const double outside = std::max({0.0, -u, u - 1, -v, v - 1});
                    const double du = u - hu[0], dv = v - hv[0];
                    const double dd = du * du + dv * dv;
                    if (outside < bestOut - 1e-12 ||
                        (outside <= bestOut + 1e-12 && dd < bestD)) {
                        bestOut = outside;
                        bestD = dd;
                        best = r;
                    }
                }
                const bool root = best >= 0 && bestOut <= 1e-6;
                out.push_back({root ? roots[best].t : ht[0], f, hs[0],
                               root ? roots[best].u : hu[0],
                               root ? roots[best].v : hv[0]});
            } else {
                if (ht[1] < ht[0]) {
                    std::swap(ht[0], ht[1]);
                    std::swap(hs[0], hs[1]);
                    std::swap(hu[0], hu[1]);
                    std::swap(hv[0], hv[1]);
                }
                // Both tessellation triangles crossed (the ray grazes the fold of the
                // face): the patch is crossed twice or not at all. Use its roots only if
                // both lie on the patch; otherwise the grazing pass stays tessellated.
                auto onPatch = [](const trace::PatchRoot& r) {
                    return std::max({-r.u, r.u - 1, -r.v, r.v - 1}) <= 1e-6;
                };
                if (nr == 2 && onPatch(roots[0]) && onPatch(roots[1])) {
                    const bool swap = roots[1].t < roots[0].t;
                    for (int k = 0; k < 2; ++k) {
                        const trace::PatchRoot& r = roots[swap ? 1 - k : k];
                        ht[k] = r.t;
                        hu[k] = r.u;
                        hv[k] = r.v;
                    }
                }
                out.push_back({ht[0], f, hs[0], hu[0], hv[0]});
                out.push_back({ht[1], f, hs[1], hu[1], hv[1]});
            }
            return;
        }
        case FaceKind::Curved:
            AppendCurvedCrossings(f, frame, out);
            return;
    }
}

int BrickTraverser::Impl::PlanarCrossings(std::int32_t f, const FaceRec& rec,
                                          const RayFrame& frame, Crossing* out) const {
    TriangleCrossing x;
    int n = 0;
    const ShearedPoint a = frame.Transform(P(rec.v[0]));
    const ShearedPoint b = frame.Transform(P(rec.v[1]));
    const ShearedPoint c = frame.Transform(P(rec.v[2]));
    if (rec.kind == FaceKind::Triangle) {
        // (u, v) at corners 0, 1, 2: the barycentric weights of corners 1 and 2.
        if (CrossTriangle(a, b, c, x)) out[n++] = {x.t, f, x.side, x.bary[1], x.bary[2]};
        return n;
    }
    const ShearedPoint d = frame.Transform(P(rec.v[3]));
    // (u, v) of the bilinear parametrisation at the triangles' corners (exact for a
    // parallelogram), as for the bilinear faces below.
    if (CrossTriangle(a, b, c, x))
        out[n++] = {x.t, f, x.side, x.bary[1] + x.bary[2], x.bary[2]};
    if (CrossTriangle(a, c, d, x))
        out[n++] = {x.t, f, x.side, x.bary[1], x.bary[1] + x.bary[2]};
    return n;
}

void BrickTraverser::Impl::AppendCurvedCrossings(std::int32_t f, const RayFrame& frame,
                                                 std::vector<Crossing>& out) const {
    const CurvedRec& cr = curved[faces[f].curved];
    // Quick rejection against the padded control net box, which holds the face: a ray
    // missing it by 1e-9 of the face size is far beyond rounding of every edge count, so
    // the face's count is exactly 0 as computed in full (curved_face.h).
    {
        double lo = -kInf, hi = kInf;
        for (int d = 0; d < 3; ++d) {
            const double o = frame.org[d], dd = frame.dir[d];
            if (dd == 0) {
                if (o < cr.box.lo[d] || o > cr.box.hi[d]) return;
                continue;
            }
            // By the reciprocal: the margin below is far above its rounding.
            double t0 = (cr.box.lo[d] - o) * frame.invDir[d],
                   t1 = (cr.box.hi[d] - o) * frame.invDir[d];
            if (t0 > t1) std::swap(t0, t1);
            lo = std::max(lo, t0);
            hi = std::min(hi, t1);
        }
        if (lo > hi + 1e-9 * cr.size) return;
    }
    Scratch& s = tScratch;
    for (const CurvedCacheEntry& e : s.cache)
        if (e.ray == s.ray && e.face == f) {
            out.insert(out.end(), e.x, e.x + e.count);
            return;
        }
    trace::CurvedFace face;
    face.net = &curvedNet[3 * static_cast<std::size_t>(cr.netStart)];
    face.triangle = cr.basis == FaceBasis::Triangle;
    face.order = cr.order;
    face.straightEdges = cr.straightEdges;
    face.size = cr.size;
    trace::CurvedFaceOptions opts;
    opts.tolerance = options.mappingTolerance * cr.size;
    opts.maxNewtonIterations = options.maxNewtonIterations;
    std::vector<trace::FaceCrossing>& xs = s.face;
    xs.clear();
    const int failures = trace::CrossCurvedFace(face, frame, opts, xs);
    if (failures > 0) newtonFailures.fetch_add(failures, std::memory_order_relaxed);
    for (const auto& x : xs) out.push_back({x.t, f, x.side, x.u, x.v});
    if (xs.size() <= 4) {
        CurvedCacheEntry& e = s.cache[s.cacheNext];
        s.cacheNext = (s.cacheNext + 1) % 8;
        e.ray = s.ray;
        e.face = f;
        e.count = static_cast<std::int32_t>(xs.size());
        for (std::size_t k = 0; k < xs.size(); ++k)
            e.x[k] = {xs[k].t, f, xs[k].side, xs[k].u, xs[k].v};
    }
}

// ---------------------------------------------------------------------------------------
// Locating a start inside the mesh

namespace {
struct CellQueryContext {
    RTCIntersectContext base;  // first member: Embree passes &base back to the callbacks
    std::vector<std::int64_t>* candidates;
};
}  // namespace

void BrickTraverser::Impl::BuildCellScene() const {
    const std::int64_t cells = static_cast<std::int64_t>(cellFaceOffset.size()) - 1;
    cellBoxes.assign(6 * static_cast<std::size_t>(std::max<std::int64_t>(cells, 0)),
                     0.0f);
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, cells, 1024),
                      [&](const tbb::blocked_range<std::int64_t>& range) {
                          std::vector<std::array<std::int32_t, 3>> tris;
                          for (std::int64_t c = range.begin(); c < range.end(); ++c)
                              CellBox(c, tris,
                                      &cellBoxes[6 * static_cast<std::size_t>(c)]);
                      });
    cellScene = MakeBoxScene(cellBoxes.data(), cellBoxes.size() / 6);
}

void BrickTraverser::Impl::CellBox(std::int64_t c,
                                   std::vector<std::array<std::int32_t, 3>>& tris,
                                   float* b) const {
    double lo[3] = {kInf, kInf, kInf}, hi[3] = {-kInf, -kInf, -kInf};
    for (std::int64_t k = cellFaceOffset[c]; k < cellFaceOffset[c + 1]; ++k)
        ExtendByFace(cellFaces[k], tris, lo, hi);
    FloatBox(lo, hi, b);
}

void BrickTraverser::Impl::ExtendByFace(std::int32_t f,
                                        std::vector<std::array<std::int32_t, 3>>& tris,
                                        double lo[3], double hi[3]) const {
    const FaceRec& rec = faces[f];
    if (rec.kind == FaceKind::Curved) {
        const CurvedRec& cr = curved[rec.curved];
        for (int d = 0; d < 3; ++d) {
            lo[d] = std::min(lo[d], cr.box.lo[d]);
            hi[d] = std::max(hi[d], cr.box.hi[d]);
        }
    }
    Tessellation(f, tris);
    for (const auto& tri : tris)
        for (std::int32_t id : tri)
            for (int d = 0; d < 3; ++d) {
                lo[d] = std::min(lo[d], P(id)[d]);
                hi[d] = std::max(hi[d], P(id)[d]);
            }
}

void BrickTraverser::Impl::FloatBox(const double lo[3], const double hi[3],
                                    float* b) const {
    for (int d = 0; d < 3; ++d) {
        const bool empty = !(lo[d] <= hi[d]);
        b[d] = empty ? INFINITY : std::nextafter(float(lo[d] - queryPad), -INFINITY);
        b[3 + d] = empty ? -INFINITY : std::nextafter(float(hi[d] + queryPad), INFINITY);
    }
}

RTCScene BrickTraverser::Impl::MakeBoxScene(const float* boxes, std::size_t count) const {
    RTCScene s = rtcNewScene(device);
    rtcSetSceneFlags(s, RTC_SCENE_FLAG_ROBUST | RTC_SCENE_FLAG_COMPACT);
    rtcSetSceneBuildQuality(s, RTC_BUILD_QUALITY_LOW);
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(geom, static_cast<unsigned>(count));
    rtcSetGeometryUserData(geom, const_cast<float*>(boxes));
    rtcSetGeometryBoundsFunction(geom, BoxBounds, nullptr);
    rtcSetGeometryIntersectFunction(geom, [](const RTCIntersectFunctionNArguments* args) {
        if (!args->valid[0]) return;
        const auto* ctx = reinterpret_cast<const CellQueryContext*>(args->context);
        ctx->candidates->push_back(args->primID);
    });
    CommitUserScene(device, s, geom, "cell scene");
    return s;
}

void BrickTraverser::Impl::BoxCandidates(RTCScene boxScene, const Ray& ray, double t0,
                                         double t1, std::vector<std::int64_t>& out,
                                         bool sorted) const {
    out.clear();
    CellQueryContext ctx;
    rtcInitIntersectContext(&ctx.base);
    ctx.candidates = &out;
    RTCRayHit rh = QueryRay(ray, t0, t1, queryPad);
    rtcIntersect1(boxScene, &ctx.base, &rh);
    if (!sorted) return;
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
}

template <typename Visit>
bool BrickTraverser::Impl::ForEachPair(std::int64_t c, const RayFrame& frame,
                                       Visit&& visit) const {
    std::vector<Crossing>& xs = tScratch.cell;
    xs.clear();
    const std::int32_t* cf = &cellFaces[cellFaceOffset[c]];
    const int nf = static_cast<int>(cellFaceOffset[c + 1] - cellFaceOffset[c]);
    // The walk is bound by memory latency: fetch the cell's face records, then their
    // curved data, in parallel rather than one chain after the other.
    for (int k = 0; k < nf; ++k) __builtin_prefetch(&faces[cf[k]]);
    for (int k = 0; k < nf; ++k) {
        const FaceRec& rec = faces[cf[k]];
        if (rec.kind != FaceKind::Curved) continue;
        const CurvedRec& cr = curved[rec.curved];
        __builtin_prefetch(&cr);
        __builtin_prefetch(&cr.box.hi[2]);
    }
    for (int k = 0; k < nf; ++k) AppendCrossings(cf[k], frame, xs);
    std::sort(xs.begin(), xs.end(), [](const Crossing& a, const Crossing& b) {
        if (a.t != b.t) return a.t < b.t;
        if (a.face != b.face) return a.face < b.face;
        return a.side < b.side;
    });
    // As FindExit: in order, a leaving crossing closes the oldest open entering one, and
    // an entering one that rounding put after its leaving one closes the oldest open
    // leaving one.
    int openIn[64], openOut[64];
    int nIn = 0, headIn = 0, nOut = 0, headOut = 0;
    for (int i = 0; i < int(xs.size()) && i < 64; ++i) {
        int in = -1, out = -1;
        if (Leaves(xs[i], c)) {
            if (headIn < nIn)
                in = openIn[headIn++], out = i;
            else
                openOut[nOut++] = i;
        } else {
            if (headOut < nOut)
                in = i, out = openOut[headOut++];
            else
                openIn[nIn++] = i;
        }
        if (in >= 0 && visit(xs[in], xs[out])) return true;
    }
    return false;
}

bool BrickTraverser::Impl::CellSegments(std::int64_t c, const RayFrame& frame, double tLo,
                                        double tHi, std::vector<Segment>& out,
                                        std::vector<SegmentSeed>* seeds) const {
    std::size_t pairs = 0;
    ForEachPair(c, frame, [&](const Crossing& in, const Crossing& exit) {
        ++pairs;
        // As the walk: the exit no earlier than the entry.
        const double tIn = in.t, tOut = std::max(exit.t, tIn);
        const double a = std::max(tIn, tLo), b = std::min(tOut, tHi);
        if (a < b) {
            out.push_back({c, a, b});
            if (seeds) {
                SegmentSeed& sd = seeds->emplace_back();
                sd.tEnter = in.t;
                sd.tExit = exit.t;
                SeedRef(in, c, sd.enter);
                SeedRef(exit, c, sd.exit);
            }
        }
        return false;
    });
    return 2 * pairs == tScratch.cell.size();
}

bool BrickTraverser::Impl::LocateStart(double t, const Ray& ray, const RayFrame& frame,
                                       std::int64_t& cell, Crossing& entry) const {
    if (!cellSceneReady.load(std::memory_order_acquire)) {
        if (walkedBefore.load(std::memory_order_relaxed) < stats.cells) return false;
        std::call_once(cellSceneOnce, [this] {
            BuildCellScene();
            cellSceneReady.store(true, std::memory_order_release);
        });
    }
    // The boxes that a short float ray about the point at t passes through (they are
    // padded by queryPad, far above the float rounding of the ray).
    std::vector<std::int64_t>& cand = tScratch.candidates;
    BoxCandidates(cellScene, ray, t, t, cand);
    for (std::int64_t c : cand) {
        // Only a cell whose crossings all pair up (one that closes; else the walk, with
        // its repairs, decides).
        bool found = false;
        std::size_t pairs = 0;
        ForEachPair(c, frame, [&](const Crossing& in, const Crossing& out) {
            ++pairs;
            if (!found && in.t <= t && t < out.t) {
                found = true;
                cell = c;
                entry = in;
            }
            return false;
        });
        if (found) return 2 * pairs == tScratch.cell.size();
    }
    return false;
}

// ---------------------------------------------------------------------------------------
// The walk

bool BrickTraverser::Impl::FindExit(std::int64_t c, std::int32_t entryFace, double entryT,
                                    double tIn, const RayFrame& frame, Crossing& exit,
                                    FacePoint* exitPoint, TetWalkFace* lastFace) const {
    if (exitPoint) exitPoint->v[0] = -1;
    // A brick of planar tets only needs none of the checks (each of them a load from
    // memory that the walk would wait for).
    const std::int32_t* cf = &cellFaces[planarTetsOnly ? 4 * c : cellFaceOffset[c]];
    if (planarTetsOnly)
        for (int k = 0; k < 4; ++k) __builtin_prefetch(&faces[cf[k]]);
    const int nf =
        planarTetsOnly ? 4 : static_cast<int>(cellFaceOffset[c + 1] - cellFaceOffset[c]);
    if (planarTetsOnly || (nf == 4 && brick.mesh->cellShape[c] == CellShape::Tet &&
                           faces[cf[0]].kind == FaceKind::Triangle &&
                           faces[cf[1]].kind == FaceKind::Triangle &&
                           faces[cf[2]].kind == FaceKind::Triangle &&
                           faces[cf[3]].kind == FaceKind::Triangle)) {
        if (PlanarTetExit(c, cf, entryFace, frame, exit, exitPoint, lastFace))
            return true;
    } else if (bool planarFound = false;
               PlanarCellExit(c, cf, nf, entryFace, entryT, frame, exit, planarFound,
                              exitPoint, lastFace)) {
        if (planarFound) return true;
    } else if (GeneralCellExit(c, entryFace, entryT, frame, exit, exitPoint)) {
        return true;
    }
    if (TolerantExit(c, tIn, frame, exit)) {
        walkRepairs.fetch_add(1, std::memory_order_relaxed);
        return true;
    }
    return false;
}

// General cells (bilinear faces can be crossed twice, curved cells left and re-entered):
// all crossings of the cell's faces along the whole line, sorted by t, paired entering ->
// leaving in order (a leaving crossing that rounding put before every open entering one
// waits for the next entering one). The pairing is a bijection computed identically on
// every visit, so a walk can neither get stuck nor loop: each crossing has one
// predecessor and one successor.
//
// Kept out of line, as PlanarCellExit is: inlined into FindExit, and so into the walk's
// loop, it made the compiler emit a slower step through planar tets (2.6% more
// instructions in the walk of a mesh of tets only, which never comes here).
[[gnu::noinline]] bool BrickTraverser::Impl::GeneralCellExit(
    std::int64_t c, std::int32_t entryFace, double entryT, const RayFrame& frame,
    Crossing& exit, FacePoint* exitPoint) const {
    const bool found =
        ForEachPair(c, frame, [&](const Crossing& in, const Crossing& out) {
            if (in.face != entryFace || in.t != entryT) return false;
            exit = out;
            return true;
        });
    if (found && exitPoint) TetEntryPoint(exit, frame, *exitPoint);
    return found;
}

// A cell with planar faces only (linear hexahedra, wedges and pyramids) is mostly
// crossed by the ray line exactly twice, once entering and once leaving. ForEachPair
// would find those two crossings (the same PlanarCrossings on the same faces, each
// computed from the same sheared corners: bitwise the same) and, whatever their order,
// pair the entering one with the leaving one. So where there are two, that pair is the
// outcome without the list, the sort and the pairing's bookkeeping; any other count
// (a ray along a fold of a quad that rounding left slightly bent) goes to ForEachPair.
//
// Here the decisions come first: for every face, which of its triangles the ray
// crosses, by CrossTriangle's rule (the three edge signs of (A, B, C), and of (A, C, D)
// for a quad, are equal and not 0); then only the crossed triangles' crossings are
// computed, by FinishCrossing on the same corners in the same order as CrossTriangle's.
// Each edge sign of a face is evaluated once (the diagonal serves both triangles,
// negated: EdgeSign is exactly antisymmetric), without branches on its value where the
// static filter decides it. A face whose sheared corners all lie on one side of the ray
// (x > 0, x < 0, y > 0 or y < 0 for all of them) needs none: the perturbed ray (eps,
// eps^2) lies outside the box of its corners as eps -> 0, so it is outside both
// triangles, which is what their exact edge signs say.
//
// Kept out of line: inlined into FindExit, and so into the walk's loop, it made the
// compiler leave PlanarTetExit out of line instead, which costs the tet steps more than
// the call costs here.
[[gnu::noinline]] bool BrickTraverser::Impl::PlanarCellExit(
    std::int64_t c, const std::int32_t* cf, int nf, std::int32_t entryFace, double entryT,
    const RayFrame& frame, Crossing& exit, bool& found, FacePoint* exitPoint,
    TetWalkFace* lastFace) const {
    constexpr int kMaxFaces = 8;
    if (nf > kMaxFaces) return false;
    for (int k = 0; k < nf; ++k) __builtin_prefetch(&faces[cf[k]]);
    // Every face's kind first: a cell with a bilinear or curved face computes nothing
    // here that ForEachPair would compute again.
    const FaceRec* recs[kMaxFaces];
    for (int k = 0; k < nf; ++k) {
        recs[k] = &faces[cf[k]];
        const FaceKind kind = recs[k]->kind;
        if (kind != FaceKind::Triangle && kind != FaceKind::PlanarQuad &&
            kind != FaceKind::Degenerate)
            return false;
    }
    // Where the previous cell of this walk found the entry face crossed exactly once, at
    // entryT (that cell's two crossings lay on two faces, or it was a tet), the same
    // computation here gives that one crossing again: it is the entering one, and the
    // other faces' count decides alone (one more crossing makes the two of the full
    // count).
    Scratch& scratch = tScratch;
    const bool entryKnown = scratch.singleRay == scratch.ray &&
                            scratch.singleFace == entryFace && scratch.singleT == entryT;
    // Face k's sheared corners in its record's order (plain doubles: ShearedPoint's
    // initialisers would zero the whole array on every call). Bit 2 k of `crossed`: its
    // triangle (A, B, C) is crossed, with side side[2 k]; bit 2 k + 1: its (A, C, D).
    struct Corner {
        double x, y, z;
    };
    Corner corner[kMaxFaces][4];
    int side[2 * kMaxFaces];
    std::uint32_t crossed = 0;
    const auto transform = [&](std::int32_t id, Corner& out) {
        const ShearedPoint q = frame.Transform(P(id));
        out = {q.x, q.y, q.z};
    };
    const auto edge = [](const Corner& p, const Corner& q) {
        const int s = trace::FilteredCrossSign(p.x, p.y, q.x, q.y);
        return s != 0 ? s : trace::EdgeSign({p.x, p.y, p.z}, {q.x, q.y, q.z});
    };
    const auto crosses = [](int sa, int sb, int sc) {
        return std::uint32_t((sa != 0) & (sa == sb) & (sa == sc));
    };
    for (int k = 0; k < nf; ++k) {
        const FaceRec& rec = *recs[k];
        if (rec.kind == FaceKind::Degenerate || (entryKnown && cf[k] == entryFace))
            continue;
        const bool quad = rec.kind == FaceKind::PlanarQuad;
        Corner* q = corner[k];
        transform(rec.v[0], q[0]);
        transform(rec.v[1], q[1]);
        transform(rec.v[2], q[2]);
        if (quad) transform(rec.v[3], q[3]);
        const Corner& d = q[quad ? 3 : 0];
        const double xMin = std::min(std::min(q[0].x, q[1].x), std::min(q[2].x, d.x));
        const double xMax = std::max(std::max(q[0].x, q[1].x), std::max(q[2].x, d.x));
        const double yMin = std::min(std::min(q[0].y, q[1].y), std::min(q[2].y, d.y));
        const double yMax = std::max(std::max(q[0].y, q[1].y), std::max(q[2].y, d.y));
        if ((xMin > 0) | (xMax < 0) | (yMin > 0) | (yMax < 0)) continue;
        const int sab = edge(q[0], q[1]), sbc = edge(q[1], q[2]), sca = edge(q[2], q[0]);
        crossed |= crosses(sbc, sca, sab) << 2 * k;
        side[2 * k] = sbc;
        if (quad) {
            const int scd = edge(q[2], q[3]), sda = edge(q[3], q[0]);
            crossed |= crosses(scd, sda, -sca) << (2 * k + 1);
            side[2 * k + 1] = scd;
        }
    }
    found = false;
    if (__builtin_popcount(crossed) != (entryKnown ? 1 : 2)) return false;
    // The crossings in PlanarCrossings' order (faces in cf's order, (A, B, C) before
    // (A, C, D)), with their triangles (bit index into `crossed`).
    Crossing xs[2];
    TriangleCrossing txs[2];
    int tri[2] = {0, 0};
    int n = 0;
    for (int b = 0; b < 2 * nf; ++b) {
        if (!(crossed >> b & 1)) continue;
        const int k = b >> 1;
        const Corner& a = corner[k][0];
        const Corner& p = corner[k][(b & 1) + 1];
        const Corner& q = corner[k][(b & 1) + 2];
        TriangleCrossing& x = txs[n];
        trace::FinishCrossing({a.x, a.y, a.z}, {p.x, p.y, p.z}, {q.x, q.y, q.z}, side[b],
                              x);
        // (u, v) as PlanarCrossings gives them.
        double u = x.bary[1], v = x.bary[2];
        if (recs[k]->kind == FaceKind::PlanarQuad) {
            if (b & 1)
                v = x.bary[1] + x.bary[2];
            else
                u = x.bary[1] + x.bary[2];
        }
        tri[n] = b;
        xs[n++] = {x.t, cf[k], x.side, u, v};
    }
    int e = 0;  // the exit's index in xs
    if (entryKnown) {
        // The entry crossing leaves the previous cell, so it enters this one: a pair
        // exactly when the other crossing leaves.
        if (!Leaves(xs[0], c)) return true;
    } else {
        const bool leaves0 = Leaves(xs[0], c), leaves1 = Leaves(xs[1], c);
        if (leaves0 == leaves1) return true;  // no pair: as ForEachPair
        const Crossing& in = leaves0 ? xs[1] : xs[0];
        if (in.face != entryFace || in.t != entryT) return true;
        e = leaves0 ? 0 : 1;
    }
    exit = xs[e];
    found = true;
    // Left through a triangle: the next cell, if a planar tet, is entered by it with its
    // corners in the ray frame already (see TetWalkFace), and its entry face point is
    // made from them and this crossing, as TetEntryPoint would make it (EntryPoint's
    // CrossTriangle on these corners is the test that found the crossing).
    const int k = tri[e] >> 1;
    if (recs[k]->kind == FaceKind::Triangle) {
        const Corner* q = corner[k];
        const ShearedPoint a{q[0].x, q[0].y, q[0].z}, b{q[1].x, q[1].y, q[1].z},
            d{q[2].x, q[2].y, q[2].z};
        if (lastFace) *lastFace = {exit.face, exit.side, {a, b, d}};
        if (exitPoint && meshPointIds) {
            const std::int64_t next = recs[k]->cell[exit.side > 0 ? 1 : 0];
            if (next >= 0 && (tetCodes[next] & tetcode::kValid))
                MakeFacePoint(recs[k]->v, a, b, d, txs[e], std::abs(frame.dir[frame.kz]),
                              *exitPoint);
        }
    }
    if (exit.face != entryFace) {
        scratch.singleRay = scratch.ray;
        scratch.singleFace = exit.face;
        scratch.singleT = exit.t;
    }
    return true;
}

// A planar tet seen along the (perturbed) ray covers the ray with exactly one entering
// and one leaving face (exact predicates on the projected corners), so the first face in
// the order of cf that the ray crosses leaving c is the exit: CrossTriangle decides each
// face, in its record's corner order.
//
// Where the walk entered c by the face it left the previous tet by (lastFace), that
// face's corners A, B, C are in the ray frame already and the signs of its edges (A, B),
// (B, C), (C, A) are all that crossing's side s (CrossTriangle found them equal). Only
// the corner D off it is new, with the signs m_X = EdgeSign(X, D) of the three edges
// through it. The face opposite A, cyclically (B, C, D), has edge signs s, m_C, -m_B
// (EdgeSign is exactly antisymmetric), so CrossTriangle crosses it exactly when m_C = s
// and m_B = -s; the other order negates all three signs, with the same outcome. Likewise
// the face opposite B when m_A = s and m_C = -s, the face opposite C when m_B = s and m_A
// = -s. So one transform and three signs decide the step, with the same outcome as
// CrossTriangle on every face, and the crossing is computed from the same sheared
// corners in the same order: bitwise the same exit. Which face is opposite which corner,
// and where each record corner sits among A, B, C and D, come from the cell's tet code
// (built once, see BuildTetCodes), not from comparing vertex ids, whose branches the
// processor cannot predict.
bool BrickTraverser::Impl::PlanarTetExit(std::int64_t c, const std::int32_t* cf,
                                         std::int32_t entryFace, const RayFrame& frame,
                                         Crossing& exit, FacePoint* exitPoint,
                                         TetWalkFace* lastFace) const {
    TriangleCrossing x;
    // The exit through face f crossed as x at the sheared corners a, b, d (f's order).
    const auto found = [&](std::int32_t f, const FaceRec& rec, const ShearedPoint& a,
                           const ShearedPoint& b, const ShearedPoint& d) {
        const Crossing cand{x.t, f, x.side, x.bary[1], x.bary[2]};
        if (!Leaves(cand, c)) return false;
        exit = cand;
        // A triangle is crossed at most once: the next cell, if it has other shapes,
        // knows its entering crossing (see PlanarCellExit). A brick of planar tets has
        // none.
        if (!planarTetsOnly) {
            Scratch& scratch = tScratch;
            scratch.singleRay = scratch.ray;
            scratch.singleFace = f;
            scratch.singleT = x.t;
        }
        if (exitPoint && meshPointIds)
            MakeFacePoint(rec.v, a, b, d, x, std::abs(frame.dir[frame.kz]), *exitPoint);
        if (lastFace) *lastFace = {f, x.side, {a, b, d}};
        return true;
    };
    // Which corners of the record lie where (see tetcode): the exit face and its
    // corners' places among the entry corners and d by table, not by vertex ids.
    const std::uint32_t code = tetCodes[c];
    const int kin = cf[0] == entryFace   ? 0
                    : cf[1] == entryFace ? 1
                    : cf[2] == entryFace ? 2
                    : cf[3] == entryFace ? 3
                                         : -1;
    if (lastFace && lastFace->face == entryFace && (code & tetcode::kValid) && kin >= 0) {
        using tetcode::LocalCorner;
        // Local corners of the entry record's corners (lastFace->p's order), and d.
        const std::uint32_t corners = tetcode::Corners(code);
        const int in[3] = {LocalCorner(corners, kin, 0), LocalCorner(corners, kin, 1),
                           LocalCorner(corners, kin, 2)};
        const int dl = kin == 0 ? 3 : 6 - in[0] - in[1] - in[2];
        // d from the entry face's record (see FaceRec::Opposite; BuildTetCodes sets it
        // on every face of a cell with a tet code), the corner the cell's other faces'
        // records give.
        const FaceRec& entryRec = faces[entryFace];
        const std::int32_t d = entryRec.Opposite(entryRec.cell[0] == c ? 0 : 1);
        const int s = lastFace->side;
        const ShearedPoint pd = frame.Transform(P(d));
        const int m[3] = {EdgeSign(lastFace->p[0], pd), EdgeSign(lastFace->p[1], pd),
                          EdgeSign(lastFace->p[2], pd)};
        // The entry corner opposite the crossed face (at most one is: each pair of these
        // conditions asks opposite signs of one m), or none.
        const int o = m[2] == s && m[1] == -s   ? 0
                      : m[0] == s && m[2] == -s ? 1
                      : m[1] == s && m[0] == -s ? 2
                                                : -1;
        if (o < 0) return false;
        // Corner index: 0, 1, 2 on the entry face, 3 for d.
        int at[4];
        at[in[0]] = 0;
        at[in[1]] = 1;
        at[in[2]] = 2;
        at[dl] = 3;
        const int kout = tetcode::FaceOpposite(code, in[o]);
        const std::int32_t f = cf[kout];
        const FaceRec& rec = faces[f];
        const int l[3] = {at[LocalCorner(corners, kout, 0)],
                          at[LocalCorner(corners, kout, 1)],
                          at[LocalCorner(corners, kout, 2)]};
        // EdgeSign of the face's edge (corner l[1], corner l[2]), from s and m.
        const int sa = l[2] == 3                            ? m[l[1]]
                       : l[1] == 3                          ? -m[l[2]]
                       : l[2] == (l[1] == 2 ? 0 : l[1] + 1) ? s
                                                            : -s;
        const ShearedPoint& a = l[0] == 3 ? pd : lastFace->p[l[0]];
        const ShearedPoint& b = l[1] == 3 ? pd : lastFace->p[l[1]];
        const ShearedPoint& dd = l[2] == 3 ? pd : lastFace->p[l[2]];
        trace::FinishCrossing(a, b, dd, sa, x);
        return found(f, rec, a, b, dd);
    }
    // Face by face: the walk's first cell, or a cell without a tet code (corners that
    // are not those of one tetrahedron).
    for (int k = 0; k < 4; ++k) {
        const std::int32_t f = cf[k];
        if (f == entryFace) continue;
        const FaceRec& rec = faces[f];
        const ShearedPoint a = frame.Transform(P(rec.v[0]));
        const ShearedPoint b = frame.Transform(P(rec.v[1]));
        const ShearedPoint d = frame.Transform(P(rec.v[2]));
        if (CrossTriangle(a, b, d, x) && found(f, rec, a, b, d)) return true;
    }
    return false;
}

void BrickTraverser::Impl::TetEntryPoint(const Crossing& x, const RayFrame& frame,
                                         FacePoint& fp) const {
    const FaceRec& rec = faces[x.face];
    if (rec.kind != FaceKind::Triangle) return;
    const std::int64_t next = rec.cell[x.side > 0 ? 1 : 0];
    if (next >= 0 && (tetCodes[next] & tetcode::kValid)) EntryPoint(x, frame, fp);
}

void BrickTraverser::Impl::EntryPoint(const Crossing& x, const RayFrame& frame,
                                      FacePoint& fp) const {
    fp.v[0] = -1;
    const FaceRec& rec = faces[x.face];
    if (!meshPointIds || rec.kind != FaceKind::Triangle) return;
    const ShearedPoint a = frame.Transform(P(rec.v[0]));
    const ShearedPoint b = frame.Transform(P(rec.v[1]));
    const ShearedPoint c = frame.Transform(P(rec.v[2]));
    TriangleCrossing tx;
    // The same test as the one that found x, so bitwise the same crossing.
    if (!CrossTriangle(a, b, c, tx) || tx.t != x.t || tx.side != x.side) return;
    MakeFacePoint(rec.v, a, b, c, tx, std::abs(frame.dir[frame.kz]), fp);
}

// Exit search when the exact one found none: this happens only where two cells represent
// a shared edge differently (non-conforming meshes: an edge with nodes on one side only).
// Takes the leaving tessellation triangle the ray misses by the least, if it misses by a
// relative 1e-6 at most.
bool BrickTraverser::Impl::TolerantExit(std::int64_t c, double tIn, const RayFrame& frame,
                                        Crossing& exit) const {
    std::vector<std::array<std::int32_t, 3>> tris;
    double bestScore = -1e-6;
    bool found = false;
    for (std::int64_t k = cellFaceOffset[c]; k < cellFaceOffset[c + 1]; ++k) {
        const std::int32_t f = cellFaces[k];
        Tessellation(f, tris);
        for (const auto& tri : tris) {
            const ShearedPoint a = frame.Transform(P(tri[0]));
            const ShearedPoint b = frame.Transform(P(tri[1]));
            const ShearedPoint d = frame.Transform(P(tri[2]));
            double w[3] = {b.x * d.y - b.y * d.x, d.x * a.y - d.y * a.x,
                           a.x * b.y - a.y * b.x};
            const double sum = w[0] + w[1] + w[2];
            if (sum == 0 || !std::isfinite(sum)) continue;
            const Crossing cand{0, f, sum > 0 ? 1 : -1};
            if (!Leaves(cand, c)) continue;
            const double score = std::min({w[0], w[1], w[2]}) / sum;
            if (score <= bestScore) continue;
            const double t = (w[0] * a.z + w[1] * b.z + w[2] * d.z) / sum;
            bestScore = score;
            exit = {std::max(t, tIn), f, cand.side};
            found = true;
        }
    }
    return found;
}

BrickTraverser::BrickTraverser(const Brick& brick, const TraceOptions& options)
    : impl_(std::make_unique<Impl>()) {
    HPRAY_CHECK(brick.mesh != nullptr);
    impl_->brick = brick;
    impl_->options = options;
    impl_->Build();
}

BrickTraverser::~BrickTraverser() = default;

const TraverserStats& BrickTraverser::Stats() const { return impl_->stats; }

const Brick& BrickTraverser::GetBrick() const { return impl_->brick; }

TraceCounters BrickTraverser::Counters() const {
    TraceCounters c;
    c.newtonFailures = impl_->newtonFailures.load();
    c.walkRepairs = impl_->walkRepairs.load();
    c.walkFailures = impl_->walkFailures.load();
    c.locatedStarts = impl_->locatedStarts.load();
    c.unpairedRays = impl_->unpairedRays.load();
    return c;
}

bool BrickTraverser::FacePoints() const { return impl_->meshPointIds; }

void BrickTraverser::Trace(const Ray& ray, double tMin, double tMax,
                           std::vector<Segment>& out) const {
    Trace(ray, tMin, tMax, out, nullptr);
}

bool BrickTraverser::HasSeeds() const {
    return impl_->stats.bilinearFaces + impl_->stats.curvedFaces > 0;
}

void BrickTraverser::Trace(const Ray& ray, double tMin, double tMax,
                           std::vector<Segment>& out, std::vector<SegmentEnds>* ends,
                           std::vector<SegmentSeed>* seeds, SegmentSink* sink) const {
    // (The face points' last entry is pending while the walk goes on: a sink would see
    // segments without theirs.)
    HPRAY_CHECK(!(sink && ends));
    out.clear();
    if (ends) ends->clear();
    if (seeds) seeds->clear();
    const Impl& im = *impl_;
    RaySpan span{tMin, tMax};
    if (!(tMin <= tMax) || !ClipRayToBox(ray, im.brick.box, span)) return;
    const double tLo = span.t0, tHi = span.t1;
    if (im.boundaryFaces.empty()) return;
    RaySpan query{-kInf, tHi};
    if (!ClipRayToBox(ray, im.queryBox, query)) return;
    const double q0 = query.t0, q1 = query.t1;
    const RayFrame frame(ray);
    ++tScratch.ray;  // a new ray for the curved-face cache

    // 1. Every crossing of the mesh boundary up to tHi.
    std::vector<Crossing>& hits = tScratch.boundary;
    hits.clear();
    QueryContext ctx;
    rtcInitIntersectContext(&ctx.base);
    ctx.impl = &im;
    ctx.frame = &frame;
    ctx.hits = &hits;
    RTCRayHit rh = QueryRay(ray, q0, q1, im.queryPad);
    rtcIntersect1(im.scene, &ctx.base, &rh);
    if (hits.empty()) return;
    std::sort(hits.begin(), hits.end(), [](const Crossing& a, const Crossing& b) {
        if (a.t != b.t) return a.t < b.t;
        if (a.face != b.face) return a.face < b.face;
        return a.side < b.side;
    });
    hits.erase(std::unique(hits.begin(), hits.end(),
                           [](const Crossing& a, const Crossing& b) {
                               return a.t == b.t && a.face == b.face && a.side == b.side;
                           }),
               hits.end());
    auto entered = [&](const Crossing& x) {
        return im.faces[x.face].cell[x.side > 0 ? 1 : 0];
    };
    // With strictly alternating entries and exits, the k-th walk leaves at the k-th exit,
    // so walks that end before tLo can be skipped unwalked.
    bool alternating = hits.size() % 2 == 0;
    for (std::size_t i = 0; i < hits.size() && alternating; ++i)
        alternating = (entered(hits[i]) >= 0) == (i % 2 == 0);

    // 2. Walk from each entry through neighbouring cells until the ray leaves the mesh.
    double tCur = -kInf;
    constexpr int kMaxZeroSteps = 4096;
    std::int64_t before = 0;  // cells walked before tLo
    // One walk from cell c, entered by the crossing of entryFace at entryT, at tIn (>=
    // entryT). True when the span is done.
    // With ends: the face points go straight into a pending last element of *ends (its
    // exit written by FindExit, its entry the last exit), which becomes the segment's
    // when the segment is kept; `trim` drops it when the walk ends.
    auto walkOnce = [&](std::int64_t c, std::int32_t entryFace, double entryT, double tIn,
                        const Crossing& entry) {
        int zeroSteps = 0;
        Crossing in = entry;  // the crossing the walk entered c by
        TetWalkFace lastFace;
        if (ends) {
            ends->emplace_back();
            im.EntryPoint(entry, frame, ends->back().enter);
        }
        while (true) {
            Crossing ex;
            SegmentEnds* pending = ends ? &ends->back() : nullptr;
            if (!im.FindExit(c, entryFace, entryT, tIn, frame, ex,
                             pending ? &pending->exit : nullptr, &lastFace)) {
                im.walkFailures.fetch_add(1, std::memory_order_relaxed);
                return false;
            }
            const double tOut = std::max(ex.t, tIn);
            const double a = std::max(tIn, tLo), b = std::min(tOut, tHi);
            before += tOut <= tLo;
            if (a < b) {
                Segment& g = out.emplace_back();
                g.cell = c;
                g.tEnter = a;
                g.tExit = b;
                if (seeds) {
                    SegmentSeed& sd = seeds->emplace_back();
                    sd.tEnter = in.t;
                    sd.tExit = ex.t;
                    im.SeedRef(in, c, sd.enter);
                    im.SeedRef(ex, c, sd.exit);
                }
                if (pending) {
                    // The kept segment's ends (an entry is only valid with its exit),
                    // and the next pending one entered where this one leaves.
                    if (!pending->exit.Valid()) pending->enter.v[0] = -1;
                    ends->emplace_back();
                    ends->back().enter.SetFrom((ends->end() - 2)->exit);
                }
                if (sink && !sink->Take(out.size() - 1)) return true;
            } else if (pending) {
                pending->enter.SetFrom(pending->exit);
            }
            tCur = tOut;
            if (tOut >= tHi) return true;
            const std::int64_t next = im.faces[ex.face].cell[ex.side > 0 ? 1 : 0];
            if (next < 0) return false;
            if (tOut == tIn) {
                if (++zeroSteps > kMaxZeroSteps) {
                    im.walkFailures.fetch_add(1, std::memory_order_relaxed);
                    return false;
                }
            } else {
                zeroSteps = 0;
            }
            c = next;
            entryFace = ex.face;
            entryT = ex.t;
            in = ex;
            tIn = tOut;
        }
    };
    auto walk = [&](std::int64_t c, std::int32_t entryFace, double entryT, double tIn,
                    const Crossing& entry) {
        const bool done = walkOnce(c, entryFace, entryT, tIn, entry);
        if (ends) ends->pop_back();
        return done;
    };
    // A span cut by the caller (a clip box) that starts inside the mesh: start at the
    // cell holding its start instead of walking the cells before it from the boundary.
    // Only where the caller's tMin, not the brick's box, starts the span, so that every
    // brick decomposition starts such a span the same way.
    bool located = false;
    if (tLo == tMin && tLo > hits.front().t) {
        std::int64_t c0 = -1;
        Crossing e0;
        if (im.LocateStart(tLo, ray, frame, c0, e0)) {
            located = true;
            im.locatedStarts.fetch_add(1, std::memory_order_relaxed);
            if (walk(c0, e0.face, e0.t, e0.t, e0)) return;
        }
    }
    // Cells walked before the span, counted once the ray is done.
    struct CountBefore {
        const Impl& im;
        const std::int64_t& before;
        ~CountBefore() {
            if (before) im.walkedBefore.fetch_add(before, std::memory_order_relaxed);
        }
    } countBefore{im, before};
    for (std::size_t i = 0; i < hits.size(); ++i) {
        const Crossing& entry = hits[i];
        // After a located walk, the boundary's entries up to where it left the mesh are
        // those of walks before the span or of the located one.
        if (located && entry.t < tCur) continue;
        std::int64_t c = entered(entry);
        if (c < 0) continue;
        if (alternating && hits[i + 1].t <= tLo) {
            tCur = std::max(tCur, hits[i + 1].t);
            continue;
        }
        const double tIn = std::max(entry.t, tCur);
        if (tIn >= tHi) return;
        if (walk(c, entry.face, entry.t, tIn, entry)) return;
    }
}

// ---------------------------------------------------------------------------------------
// Cell filters

class CellFilter {
  public:
    ~CellFilter() {
        if (scene) rtcReleaseScene(scene);
    }
    const void* owner = nullptr;      // the traverser's Impl
    std::vector<std::uint8_t> keep;   // per cell of the brick
    std::vector<std::int64_t> cells;  // primitive index -> cell (a cell's consecutive)
    std::vector<float> boxes;         // 6 per primitive
    std::vector<float> cellBoxes;     // 6 per primitive: its cell's own box
    RTCScene scene = nullptr;
};

std::shared_ptr<const CellFilter> BrickTraverser::MakeCellFilter(
    const std::vector<std::uint8_t>& keep, const std::vector<std::int64_t>* boxStart,
    const std::vector<float>* boxes) const {
    const Impl& im = *impl_;
    auto filter = std::make_shared<CellFilter>();
    filter->owner = &im;
    const std::int64_t cells = static_cast<std::int64_t>(im.cellFaceOffset.size()) - 1;
    HPRAY_CHECK(static_cast<std::int64_t>(keep.size()) == cells);
    HPRAY_CHECK(!boxStart ||
                (boxes && static_cast<std::int64_t>(boxStart->size()) == cells + 1));
    filter->keep = keep;
    // One primitive per given box of a kept cell, or its own box where it has none; a
    // cell's primitives are consecutive.
    std::vector<std::int64_t> own;  // primitive -> index of its own box, or -1
    for (std::int64_t c = 0; c < cells; ++c) {
        if (!keep[c]) continue;
        const std::int64_t b0 = boxStart ? (*boxStart)[c] : 0,
                           b1 = boxStart ? (*boxStart)[c + 1] : 0;
        if (b1 == b0) {
            filter->cells.push_back(c);
            own.push_back(-1);
        }
        for (std::int64_t b = b0; b < b1; ++b) {
            filter->cells.push_back(c);
            own.push_back(b);
        }
    }
    filter->boxes.resize(6 * filter->cells.size());
    filter->cellBoxes.resize(6 * filter->cells.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, filter->cells.size(), 1024),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                          std::vector<std::array<std::int32_t, 3>> tris;
                          for (std::size_t i = range.begin(); i < range.end(); ++i) {
                              float* out = &filter->boxes[6 * i];
                              float* cell = &filter->cellBoxes[6 * i];
                              // A cell's primitives are consecutive: its own box once.
                              if (i > range.begin() &&
                                  filter->cells[i] == filter->cells[i - 1])
                                  std::copy_n(cell - 6, 6, cell);
                              else
                                  im.CellBox(filter->cells[i], tris, cell);
                              if (own[i] < 0)
                                  std::copy_n(cell, 6, out);
                              else
                                  std::copy_n(&(*boxes)[6 * own[i]], 6, out);
                          }
                      });
    filter->scene = im.MakeBoxScene(filter->boxes.data(), filter->cells.size());
    return filter;
}

namespace {
/// Where the ray enters a box (6 floats: lo, hi) in [t0, inf), or t0 where the box holds
/// the ray's point there. The box is padded and rounded outwards (FloatBox), far more
/// than this arithmetic's rounding: no point of the box's contents lies on the ray
/// before it.
double BoxEntry(const Ray& ray, const float* box, double t0) {
    double t = t0;
    for (int d = 0; d < 3; ++d) {
        if (ray.dir[d] == 0) continue;
        const double a = (double(box[d]) - ray.origin[d]) / ray.dir[d];
        const double b = (double(box[3 + d]) - ray.origin[d]) / ray.dir[d];
        t = std::max(t, std::min(a, b));
    }
    return t;
}
}  // namespace

void BrickTraverser::Trace(const Ray& ray, double tMin, double tMax,
                           std::vector<Segment>& out, const CellFilter& filter,
                           std::vector<SegmentSeed>* seeds, SegmentSink* sink) const {
    out.clear();
    if (seeds) seeds->clear();
    const Impl& im = *impl_;
    HPRAY_CHECK(filter.owner == &im);
    RaySpan span{tMin, tMax};
    if (!(tMin <= tMax) || !ClipRayToBox(ray, im.brick.box, span)) return;
    const double tLo = span.t0, tHi = span.t1;
    if (filter.cells.empty()) return;
    const RayFrame frame(ray);
    ++tScratch.ray;  // a new ray for the curved-face cache
    std::vector<std::int64_t>& cand = tScratch.candidates;
    // (Sorted for the search below, which visits a cell's primitives together; the
    // incremental search orders the cells itself.)
    im.BoxCandidates(filter.scene, ray, tLo, tHi, cand, !sink);
    auto before = [](const Segment& a, const Segment& b) {
        if (a.tEnter != b.tEnter) return a.tEnter < b.tEnter;
        return a.cell < b.cell;
    };
    if (sink) {
        // The cells in the order of their own boxes' entries, each once (marked with this
        // Trace's number as it is taken): a cell's segments start no earlier than its
        // box, so a segment found can be passed on once every cell still to visit enters
        // its box after the segment's start. That gives the sorted order of the search
        // below (segments of different cells overlap in no more than an end).
        std::vector<std::pair<double, std::int64_t>>& order = tScratch.order;
        std::vector<std::uint64_t>& mark = tScratch.cellMark;
        if (mark.size() < filter.keep.size()) mark.assign(filter.keep.size(), 0);
        const std::uint64_t stamp = tScratch.ray;
        order.clear();
        for (std::int64_t i : cand) {
            const std::int64_t c = filter.cells[i];
            if (mark[c] == stamp) continue;
            mark[c] = stamp;
            order.push_back({BoxEntry(ray, &filter.cellBoxes[6 * i], tLo), c});
        }
        std::sort(order.begin(), order.end());
        auto& waiting = tScratch.waiting;  // sorted by `before`
        waiting.clear();
        std::vector<Segment>& found = tScratch.cellSegments;
        std::vector<SegmentSeed>& foundSeeds = tScratch.cellSeeds;
        auto pass = [&](const Segment& g, const SegmentSeed* sd) {
            out.push_back(g);
            if (seeds) seeds->push_back(*sd);
            return sink->Take(out.size() - 1);
        };
        for (std::size_t k = 0; k < order.size(); ++k) {
            found.clear();
            foundSeeds.clear();
            if (!im.CellSegments(order[k].second, frame, tLo, tHi, found,
                                 seeds ? &foundSeeds : nullptr)) {
                // As below: the walk decides the ray. Its segments of the kept cells
                // after those already passed on follow them.
                im.unpairedRays.fetch_add(1, std::memory_order_relaxed);
                std::vector<Segment> all;
                std::vector<SegmentSeed> allSeeds;
                Trace(ray, tMin, tMax, all, nullptr, seeds ? &allSeeds : nullptr);
                const bool any = !out.empty();
                const Segment last = any ? out.back() : Segment{};
                for (std::size_t j = 0; j < all.size(); ++j)
                    if (filter.keep[all[j].cell] && (!any || before(last, all[j])) &&
                        !pass(all[j], seeds ? &allSeeds[j] : nullptr))
                        return;
                return;
            }
            for (std::size_t j = 0; j < found.size(); ++j) {
                std::pair<Segment, SegmentSeed> w{found[j],
                                                  seeds ? foundSeeds[j] : SegmentSeed{}};
                auto at = std::upper_bound(waiting.begin(), waiting.end(), w,
                                           [&](const auto& a, const auto& b) {
                                               return before(a.first, b.first);
                                           });
                waiting.insert(at, w);
            }
            const double next = k + 1 < order.size()
                                    ? order[k + 1].first
                                    : std::numeric_limits<double>::infinity();
            std::size_t passed = 0;
            while (passed < waiting.size() && waiting[passed].first.tEnter < next) {
                if (!pass(waiting[passed].first, &waiting[passed].second)) return;
                ++passed;
            }
            waiting.erase(waiting.begin(), waiting.begin() + std::ptrdiff_t(passed));
        }
        return;
    }
    bool closed = true;
    std::int64_t last = -1;
    for (std::int64_t i : cand) {
        // A cell's primitives are consecutive, so its repeats are adjacent here.
        const std::int64_t c = filter.cells[i];
        if (c == last) continue;
        last = c;
        closed = im.CellSegments(c, frame, tLo, tHi, out, seeds) && closed;
    }
    if (!closed) {
        // A kept cell whose crossings do not pair up: the walk (with its repairs) decides
        // this ray, and its segments of the kept cells are the answer.
        im.unpairedRays.fetch_add(1, std::memory_order_relaxed);
        std::vector<Segment> all;
        std::vector<SegmentSeed> allSeeds;
        Trace(ray, tMin, tMax, all, nullptr, seeds ? &allSeeds : nullptr);
        out.clear();
        if (seeds) seeds->clear();
        for (std::size_t k = 0; k < all.size(); ++k)
            if (filter.keep[all[k].cell]) {
                out.push_back(all[k]);
                if (seeds) seeds->push_back(allSeeds[k]);
            }
        return;
    }
    if (!seeds) {
        std::sort(out.begin(), out.end(), before);
        return;
    }
    // The seeds in the segments' order.
    std::vector<std::pair<Segment, SegmentSeed>>& both = tScratch.seeded;
    both.clear();
    for (std::size_t k = 0; k < out.size(); ++k) both.push_back({out[k], (*seeds)[k]});
    std::sort(both.begin(), both.end(),
              [&](const auto& a, const auto& b) { return before(a.first, b.first); });
    for (std::size_t k = 0; k < out.size(); ++k) {
        out[k] = both[k].first;
        (*seeds)[k] = both[k].second;
    }
}

}  // namespace hpray
