// Ray casting one brick: segments from the traverser, isosurfaces by root finding on the
// true field, slice planes, and the volume integral, composited front to back into a
// partial image.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include "elements/bounds.h"
#include "elements/mesh_geometry.h"
#include "image/image.h"
#include "render/field_cache.h"
#include "render/ray_field.h"
#include "render/ray_roots.h"
#include "render/stats.h"
#include "render/volume.h"
#include "render/volume_ray.h"
#include "scene/camera.h"
#include "scene/scene.h"
#include "trace/brick_traverser.h"

namespace hpray {

/// Everything the per-ray work of one brick needs, built once and shared read-only by all
/// threads.
struct BrickSetup {
    const Mesh* mesh = nullptr;
    const MeshGeometry* geometry = nullptr;
    const BrickTraverser* traverser = nullptr;

    /// The distinct scalar fields the isosurfaces use, and per field and cell a
    /// guaranteed range (Bernstein hull), so a cell is skipped when no isovalue lies in
    /// it.
    std::vector<ScalarSelector> fields;
    /// Per field, per cell (shared with the FieldCache and other scenes' setups).
    std::vector<std::shared_ptr<const std::vector<Interval>>> cellRanges;
    std::vector<double> fieldScale;  ///< max |value| of each field over the mesh
    /// Per field: nodal values gathered per cell and derivative bounds (ray_field.h).
    std::vector<std::shared_ptr<const FieldCellData>> fieldData;
    /// Per field, its sub-cell bounds where an isosurface uses it, and per cell the boxes
    /// that may hold one of the field's isovalues (SubCellBounds::HoldingMasks); null and
    /// empty without them. Isosurfaces project a segment only where these allow an
    /// isovalue (SubCellBounds::Clip), and the cell filter finds a cell only through
    /// those boxes.
    std::vector<std::shared_ptr<const SubCellBounds>> subBounds;
    std::vector<std::vector<std::uint64_t>> subHolding;

    struct Iso {
        int field = 0;
        double value = 0;
        std::array<double, 3> color{};
        double opacity = 1;
        /// Colour by this field's true value at the hit through colorTf, when set.
        std::optional<ScalarSelector> colorField;
        PiecewiseLinearTf colorTf;
        /// Absolute residual at which a root is accepted (accuracy.target_residual times
        /// the field's range); 0: polish to the root tolerance.
        double residualTarget = 0;
    };
    std::vector<Iso> isos;
    SceneLighting lighting;

    ProjectionOptions projection;
    RootOptions roots;
    InversionOptions inversion;
    /// Two hits of one isosurface closer than this (world units) are one hit: the same
    /// root seen from the two cells of a face it lies on.
    double duplicateDistance = 0;
    /// Segments at most this long (world units) that start or end at a clip plane are
    /// skipped: slivers left by clip planes through faces.
    double sliverLength = 0;

    double tNear = 0;
    double tFar = std::numeric_limits<double>::infinity();
    std::optional<Box> clipBox;

    /// The volume integral (docs/contracts.md, Volume), when the scene has a volume.
    std::optional<VolumeSetup> volume;

    /// A cut plane {x : normal . x = offset} showing the true field through `colorTf`.
    struct Slice {
        double normal[3] = {0, 0, 1};  ///< unit, world
        double offset = 0;             ///< world units
        ScalarSelector field;
        PiecewiseLinearTf colorTf;
        double opacity = 1;
    };
    /// Scenes of isosurfaces alone, where few cells hold an isovalue: those cells (rays
    /// visit only them, see BrickTraverser::MakeCellFilter); null otherwise.
    std::shared_ptr<const CellFilter> isoCells;
    std::vector<Slice> slices;

    /// Cooperative cancellation: when set, asked before each tile (from any rendering
    /// thread); once it answers true, the remaining tiles are skipped and left empty. The
    /// image is then incomplete and must be discarded by whoever asked.
    std::function<bool()> cancelled;
    /// Progress on long renders: when > 0, a line (log::Info) every this many seconds
    /// with the share of tiles done and an estimate of the time left.
    double progressSeconds = 0;
};

/// Builds the setup of a brick for a scene: resolves the isosurface, slice and volume
/// fields (InputError naming the scene and the key if one is missing, or an isosurface
/// field is not a point field), computes the per-cell guaranteed ranges (parallel), and
/// the numerical options from scene.accuracy. Per-field ranges and cell data come from
/// `cache` (render/field_cache.h; a private one when null), so a setup for a scene that
/// changes only values, transfer functions or the camera recomputes no per-cell data.
/// `subCellBounds` false leaves the sub-cell bounds out (always on in rendering; tests
/// turn them off to compare).
BrickSetup MakeBrickSetup(const Mesh& mesh, const MeshGeometry& geometry,
                          const BrickTraverser& traverser, const Scene& scene,
                          FieldCache* cache = nullptr, bool subCellBounds = true);

/// The measured cost of one ray segment: where its work was done and how long it took.
/// Sampled on request (a steady-clock read per segment) to calibrate the partitioner's
/// cost model and to balance in-memory splits by measured cost.
struct SegmentCostSample {
    std::int64_t cell = -1;
    double enter[3] = {0, 0, 0};  ///< world points where the segment enters and leaves
    double exit[3] = {0, 0, 0};
    /// Wall time of the segment's work (ranges, projection, roots, shading, volume) plus
    /// an equal share of the ray's traversal.
    float seconds = 0;
    /// Whether an earlier point of the ray stopped it (an opaque isosurface hit, or the
    /// volume's transmittance falling below its tolerance), and the last such point:
    /// a brick holding that point would not render this segment; one that does not hold
    /// it would.
    bool occluded = false;
    double occluder[3] = {0, 0, 0};
};

/// Renders the whole brick for `camera` into `image` (resized), using `threads` threads
/// (0: all). Each pixel depends only on its own ray, so the image is bitwise identical
/// for any thread count. Counters of all rays are merged into `counters`. When
/// `costSamples` is given, the brick is rendered to measure cost, not to be seen: rays do
/// not stop where they become opaque (their transmittance restarts at 1 and the stop is
/// recorded), and one SegmentCostSample per traversed segment is appended to it (in no
/// particular order). `front`: what lies in front of this brick, composited (same size);
/// its fully opaque pixels (alpha 1) hide the brick there, so they are left empty and not
/// traced — exactly what Over would keep of them.
void RenderBrick(const BrickSetup& setup, const Camera& camera, int threads, Image& image,
                 RenderCounters& counters,
                 std::vector<SegmentCostSample>* costSamples = nullptr,
                 const Image* front = nullptr);

/// The image is rendered in square tiles of kRenderTile pixels, numbered row by row.
constexpr int kRenderTile = 16;
/// How many tiles a camera's image has.
int RenderTileCount(const Camera& camera);
/// Renders only tiles [begin, end) into `image`, which must already have the camera's
/// size; other pixels are left as they are. Each pixel is computed exactly as by
/// RenderBrick, so rendering all tiles in any grouping gives the same image bit for bit.
void RenderBrickTiles(const BrickSetup& setup, const Camera& camera, int threads, int begin,
                      int end, Image& image, RenderCounters& counters);

/// One ray (exposed for tests): fills `sample` and adds to `counters`.
class RayIntegrator;
void IntegrateRay(const BrickSetup& setup, const Ray& ray, Pixel& sample,
                  RenderCounters& counters);

}  // namespace hpray
