// The scene of a render: plain structs parsed and validated from the YAML scene file.
#pragma once

#include <array>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "geom/box.h"

namespace hpray {

// Every struct below is plain data with the documented default of each key. LoadScene
// fills them from a scene file (schema: docs/contracts.md "Scene file") and guarantees the
// documented ranges, so consumers need not re-validate. World units are the mesh's.

/// `data:` what to render.
struct SceneData {
    /// `data.mesh` (required): an absolute path to a mesh file or partition directory
    /// (relative paths in the file are resolved against the scene file's folder), or
    /// "builtin:NAME[?k=v...]" unchanged.
    std::string mesh;

    /// `data.time` (a .pvd collection only): which time step. An integer is the step's
    /// index (0: the first, the default); `{value: T}` or a number written with a
    /// fraction or exponent (0.5, 2.0, 1e-3) is the step whose time is T (equal to within
    /// 1e-9 of the times' scale; another value is an error listing the times).
    struct Time {
        bool byValue = false;
        long long index = 0;  ///< >= 0; checked against the collection when it is read
        double value = 0.0;   ///< finite
    };
    std::optional<Time> time;
};

/// `frames:` several frames in one run (hpray render), each the scene with some keys
/// changed; outputs are numbered (output.png: x.png -> x_0000.png, x_0001.png, ...).
/// Either a path (`count`, `azimuth`, `elevation`, `zoom`, `time`) or a `list` of
/// per-frame overrides.
struct SceneFrames {
    int count = 0;  ///< `count`: frames of the path; 0 = not given
    /// `azimuth`, `elevation`, `zoom`: [first, last], interpolated linearly over the
    /// frames, both ends included (frame k of n: first + (last - first) * k / (n - 1)).
    std::optional<std::array<double, 2>> azimuth, elevation, zoom;
    /// `time`: `all` or [first, last] step indices (inclusive), one frame per step.
    bool timeAll = false;
    std::optional<std::array<long long, 2>> timeRange;
    /// `list`: per frame, its overrides as "key.path=value" (as --set), each applied to
    /// the scene (not to the previous frame).
    std::vector<std::vector<std::string>> list;
    bool HasTime() const { return timeAll || timeRange.has_value(); }
};

/// `camera:` a pinhole (fov_y) or orthographic (ortho_height) camera; see camera.h for
/// the rays. Defaults view the unit cube: position [3, 2, 4], look_at [0.5, 0.5, 0.5], up
/// [0, 1, 0], fov_y 30, 512 x 512. Exactly one of fov_y / ortho_height may be given.
struct SceneCamera {
    std::array<double, 3> position{3.0, 2.0, 4.0};  ///< world
    std::array<double, 3> lookAt{0.5, 0.5, 0.5};    ///< world; != position
    std::array<double, 3> up{0.0, 1.0, 0.0};  ///< not parallel to the view direction
    bool orthographic = false;                ///< true iff ortho_height was given
    double fovYDegrees = 30.0;  ///< vertical field of view, in (0, 180); perspective only
    double orthoHeight = 0.0;   ///< world height of the view, > 0; orthographic only
    int width = 512;            ///< pixels, in [1, 32768]
    int height = 512;           ///< pixels, in [1, 32768]

    /// `camera: auto`, or a camera without `position`: FitCamera sets position and
    /// look_at (and up, unless given) from the data's bounds before rendering.
    bool autoFit = false;
    std::string view = "iso";  ///< the side the eye is on: iso, +x, -x, +y, -y, +z, -z
    double zoom = 1.0;         ///< > 0; 2 halves the distance (or the ortho height)
    double azimuthDegrees = 0.0;    ///< turns the eye about `up` through look_at
    double elevationDegrees = 0.0;  ///< raises the eye toward `up`, in (-90, 90)
    bool lookAtGiven = false;       ///< auto: look at this point instead of the centre
    bool upGiven = false;
};


/// A control point of a colour transfer function: scalar -> linear RGB.
struct ColorControlPoint {
    double scalar = 0.0;
    std::array<double, 3> rgb{0.0, 0.0, 0.0};
};

/// A control point of an extinction transfer function: scalar -> sigma (per world unit).
struct ExtinctionControlPoint {
    double scalar = 0.0;
    double extinction = 0.0;  ///< >= 0
};

/// `color_tf: {map: NAME, range: auto | [lo, hi]}`: a named colour map (scene/colormaps.h)
/// over a range of its field; `auto` is the field's range over the data, known once the
/// data is loaded (ResolveColorMaps).
struct ColorMapRequest {
    std::string name;
    bool autoRange = true;
    double lo = 0.0, hi = 1.0;
};

/// One entry of `isosurfaces:`. `value` is required.
struct SceneIsosurface {
    std::string field = "u";  ///< point field name (builtins name it u)
    double value = 0.0;       ///< the isovalue C, finite
    std::array<double, 3> color{0.9, 0.5, 0.2};  ///< linear RGB in [0, 1]
    double opacity = 1.0;                        ///< in [0, 1]
    /// `color_field`: colour the surface by this field's value at each hit (evaluated on
    /// the true field there) through `color_tf` (default: viridis over its range) instead
    /// of `color`. Empty: `color`.
    std::string colorField;
    std::vector<ColorControlPoint> colorTf;
    std::optional<ColorMapRequest> colorMap;
};

/// One entry of `slices:` a cut plane showing `field` through `color_tf`. `point`,
/// `normal` and `color_tf` are required.
struct SceneSlice {
    std::array<double, 3> point{0.0, 0.0, 0.0};   ///< world point on the plane
    std::array<double, 3> normal{0.0, 0.0, 1.0};  ///< world, non-zero (not normalised)
    std::string field = "u";
    /// [[s, r, g, b], ...], >= 1 point, s strictly increasing, rgb in [0, 1]; piecewise
    /// linear, clamped outside the first and last scalar.
    std::vector<ColorControlPoint> colorTf;
    /// Set when color_tf names a map; colorTf is filled from it (at parse time for an
    /// explicit range, by ResolveColorMaps for `auto`).
    std::optional<ColorMapRequest> colorMap;
    double opacity = 1.0;  ///< in [0, 1]
};

/// `volume.glow`: how color_tf enters the emission.
enum class GlowModel {
    WilliamsMax,  ///< "williams-max": colour is chromaticity kappa, emission kappa*tau
    WilhelmsVanGelder  ///< "wilhelms-van-gelder": colour is the glow g, emission g
};

/// `volume:` (optional section) absorption + emission volume rendering.
struct SceneVolume {
    std::string colorField = "u";
    std::string extinctionField;  ///< defaults to colorField when absent
    GlowModel glow = GlowModel::WilliamsMax;
    /// [[s, r, g, b], ...] (required), >= 1 point, s strictly increasing. Williams-Max:
    /// rgb in [0, 1]; Wilhelms-Van Gelder: glow per world unit, >= 0.
    std::vector<ColorControlPoint> colorTf;
    std::optional<ColorMapRequest> colorMap;  ///< as SceneSlice::colorMap
    /// [[s, sigma], ...], >= 1 point, s strictly increasing, sigma >= 0. Without
    /// extinction_tf (defaultExtinction): a ramp from 0 at the field's minimum over the
    /// data to 10 / (the data's diagonal) at its maximum, so that rays through the data
    /// meet an optical depth of about 1 to 3 where the field is high (ResolveColorMaps).
    /// Without color_tf: viridis over the field's range.
    std::vector<ExtinctionControlPoint> extinctionTf;
    bool defaultExtinction = false;
};

/// `lighting:` headlight Blinn-Phong shading of isosurfaces. All >= 0.
struct SceneLighting {
    double ambient = 0.1;
    double diffuse = 0.8;
    double specular = 0.3;
    double shininess = 32.0;
};

/// `accuracy:` the error budget of docs/contracts.md (all tolerances > 0, absolute).
struct SceneAccuracy {
    double mappingTolerance = 1e-12;  ///< eps_M: reference-coordinate inversion
    /// Order of the polynomial projection along a ray; 0 = `auto` (chosen per segment),
    /// otherwise an explicit order in [1, 64].
    int projectionOrder = 0;
    double projectionTolerance = 1e-12;  ///< eps_P
    double rootTolerance = 1e-14;        ///< eps_R: in the ray parameter t
    double volumeTolerance = 1e-10;      ///< eps_V: absolute error of pixel RGB
    /// Polish every isosurface root on the true field (default). false reports the root
    /// of the Legendre projection itself, as Nelson & Kirby did: for order studies only.
    bool polish = true;
    /// The isosurface residual |f - C| asked for, as a fraction of the field's range over
    /// the data; 0: as small as the tolerances above make it (about 1e-15). A looser
    /// target buys speed: roots are accepted once their measured residual is within it and
    /// the projection tolerance follows it (target / 4 unless given). Every reported
    /// residual is still measured on the true field at the reported point.
    double targetResidual = 0;
};

/// `clip:` ray parameter range and optional world box. near >= 0, far > near (may be
/// inf).
struct SceneClip {
    double near = 0.0;
    double far = std::numeric_limits<double>::infinity();
    /// `clip.box: [[x0, y0, z0], [x1, y1, z1]]` with x0 < x1, y0 < y1, z0 < z1.
    std::optional<Box> box;  ///< closed
};

/// `output:` absolute paths (relative ones resolved against the working directory);
/// an empty string means "not written". Every output is optional.
struct SceneOutput {
    std::string exr;    ///< OpenEXR channels of docs/contracts.md
    std::string png;    ///< RGB over the background, sRGB, 8 bit
    std::string stats;  ///< JSON statistics
    std::string hits;   ///< float64 .npy (H, W, 5): t, N.X, N.Y, N.Z, residual
    std::string rgba;   ///< float64 .npy (H, W, 4): premultiplied R, G, B, A
    std::string errors; ///< float32 .npy (H, W, 2): iso.residual, vol.error
};

/// `outline:` the twelve edges of the data's bounding box drawn into the PNG (only: the
/// EXR and the arrays stay data). `outline: true` draws it with the defaults, a mapping
/// sets them; absent or `false`: none.
struct SceneOutline {
    bool enabled = false;
    /// Linear RGB in [0, 1]; none: black over a light background, white over a dark one.
    std::optional<std::array<double, 3>> color;
    double width = 1.5;  ///< line width in pixels, in (0, 16]
};

/// How several MPI ranks share a job (top-level key `distribute`).
enum class Distribution {
    /// `auto` (default): `image` for a mesh given directly, `space` for a partition.
    Auto,
    /// `space`: each rank renders its k-d box of the data (a partition's bricks, or an
    /// in-memory split of the mesh); the binary-swap compositor orders the boxes.
    Space,
    /// `image`: every rank holds the whole mesh and renders a share of the pixels, dealt
    /// out in tiles as ranks become free (a mesh given directly only).
    Image,
};

/// A whole scene. Top-level keys besides the stable ones (docs/contracts.md): `threads`
/// (worker threads per rank, 0 = all hardware threads; default 0) and `distribute` (see
/// Distribution).
struct Scene {
    std::string sourcePath;  ///< the scene file as given (for messages); empty if parsed
    SceneData data;
    SceneCamera camera;
    std::vector<SceneIsosurface> isosurfaces;  ///< default none
    std::vector<SceneSlice> slices;            ///< default none
    std::optional<SceneVolume> volume;         ///< default none
    SceneLighting lighting;
    std::array<double, 3> background{1.0, 1.0, 1.0};  ///< linear RGB in [0, 1]
    SceneAccuracy accuracy;
    SceneClip clip;
    SceneOutput output;
    SceneOutline outline;
    /// `legend`: a colour bar with ticks in the PNG for each colour transfer function the
    /// scene uses (render/annotate.h); default false.
    bool legend = false;
    int threads = 0;                  ///< >= 0; 0 = all hardware threads
    Distribution distribute = Distribution::Auto;
    std::optional<SceneFrames> frames;  ///< `frames:` (hpray render only)

    /// Names of the fields the scene uses (isosurfaces, slices, volume), each once, in
    /// first-use order: the only fields a renderer needs to load.
    std::vector<std::string> FieldNames() const;
};

/// The text of the scene file `path` (checked: it exists, is a file, is at most 16 MB).
/// Throws InputError naming it.
std::string ReadSceneText(const std::string& path);

/// The overrides ("key.path=value", as --set) of each frame that `scene.frames` asks
/// for, in order: the camera keys of a path and `data.time` for its time steps, or the
/// items of `list`. `timeSteps` is the number of steps of the scene's collection (0 when
/// data.mesh is not a .pvd). Throws InputError (the scene file, the key under `frames`)
/// when a time range lies outside the steps or `count` disagrees with them.
std::vector<std::vector<std::string>> FrameOverrides(const Scene& scene, int timeSteps);

/// Reads and validates the scene file `path`, after applying `overrides`
/// ("key.path=value", as `hpray render --set`). Throws InputError naming the file, the
/// key path and the line.
Scene LoadScene(const std::string& path, const std::vector<std::string>& overrides = {});

/// Parses scene text. `sourceName` names it in messages; relative input paths resolve
/// against `baseDir` (empty: the working directory). Overrides: each "a.b.0.c=VALUE" sets
/// that key path (list indices are numbers; the index one past the end appends) to VALUE
/// parsed as YAML; the value `null` (or `~`) removes the key. A path outside the schema
/// is an error that suggests the nearest valid key.
Scene ParseScene(const std::string& yamlText, const std::string& sourceName,
                 const std::vector<std::string>& overrides = {},
                 const std::string& baseDir = "");

/// The scene text with `overrides` applied (as ParseScene applies them), emitted as YAML:
/// what a scene file holding the merged scene would say. Throws InputError as ParseScene.
std::string MergeSceneOverrides(const std::string& yamlText, const std::string& sourceName,
                                const std::vector<std::string>& overrides);

/// Every key path of the schema, e.g. "camera.fov_y", "isosurfaces.#.value" (# = any
/// index); for help texts and tests.
std::vector<std::string> SceneKeyPaths();

/// Fills what a scene takes from its data: colour transfer functions that name a colour
/// map with `range: auto` (over the range of their field) and the default extinction of
/// a volume (SceneVolume::defaultExtinction, scaled by `dataSize`, the diagonal of the
/// data's bounds). `fieldRange(name)` gives [min, max] or nothing (then [0, 1] is used);
/// a constant field gets a range as wide as its magnitude (at least 1) around its value.
void ResolveColorMaps(
    Scene& scene,
    const std::function<std::optional<std::array<double, 2>>(const std::string&)>& fieldRange,
    double dataSize = 1.0);

}  // namespace hpray
