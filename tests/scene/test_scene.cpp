// Tests of scene parsing (schema, defaults, checks, overrides, paths) and camera rays.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <string>

#include "scene/camera.h"
#include "scene/colormaps.h"
#include "scene/scene.h"
#include "util/error.h"

namespace hpray {
namespace {

namespace fs = std::filesystem;
using Vec3 = std::array<double, 3>;

const double kInf = std::numeric_limits<double>::infinity();

/// A scene with every stable key (docs/contracts.md "Scene file").
const char* kDesignExample = R"(
data: {mesh: path/to/mesh.vtu}        # a mesh file, builtin:NAME, or a partition dir
camera: {position: [3, 2, 4], look_at: [0.5, 0.5, 0.5], up: [0, 1, 0],
         fov_y: 30, width: 512, height: 512}   # or ortho_height: 2.0 instead of fov_y
isosurfaces:                           # any number, any fields
  - {field: u, value: 0.0, color: [0.9, 0.5, 0.2], opacity: 1.0}
slices:                                # optional cut planes, true field colour-mapped
  - {point: [0.5, 0.5, 0.5], normal: [0, 0, 1], field: u,
     color_tf: [[-1.0, 0, 0, 1], [1.0, 1, 0, 0]], opacity: 1.0}
volume:                                # optional
  color_field: u                       # chromaticity (Williams-Max) or glow
  extinction_field: u                  # defaults to color_field
  glow: williams-max                   # or wilhelms-van-gelder
  color_tf: [[-1.0, 0, 0, 1], [1.0, 1, 0, 0]]  # [scalar, r, g, b], piecewise linear
  extinction_tf: [[-1.0, 0.0], [1.0, 4.0]]    # [scalar, extinction per world unit]
lighting: {ambient: 0.1, diffuse: 0.8, specular: 0.3, shininess: 32}   # headlight
background: [1, 1, 1]
accuracy: {mapping_tolerance: 1e-12, projection_order: auto, projection_tolerance: 1e-12,
           root_tolerance: 1e-14, volume_tolerance: 1e-10}
clip: {near: 0.0, far: .inf}           # along the ray, world units; optional box
output: {exr: out/frame.exr, png: out/frame.png, stats: out/frame.json,
         hits: out/frame.hits.npy, rgba: out/frame.rgba.npy}   # every output optional
)";

const char* kMinimal = "data: {mesh: builtin:nk-sinc}\n";

std::string Cwd(const std::string& relative) {
    return (fs::current_path() / relative).lexically_normal().string();
}

/// Parses `yaml` (with overrides) expecting an InputError; returns its message.
std::string ErrorOf(const std::string& yaml,
                    const std::vector<std::string>& overrides = {}) {
    try {
        ParseScene(yaml, "test.yaml", overrides, "/base");
    } catch (const InputError& e) {
        return e.what();
    } catch (const std::exception& e) {
        return std::string("WRONG EXCEPTION TYPE: ") + e.what();
    }
    return "NO ERROR";
}

bool Contains(const std::string& text, const std::string& fragment) {
    return text.find(fragment) != std::string::npos;
}

// ---------------------------------------------------------------------------------------
// Defaults and the design example
// ---------------------------------------------------------------------------------------

TEST(SceneTest, DefaultsOfAMinimalScene) {
    const Scene s = ParseScene(kMinimal, "minimal.yaml", {}, "/base");
    EXPECT_EQ(s.sourcePath, "minimal.yaml");
    EXPECT_EQ(s.data.mesh, "builtin:nk-sinc");
    EXPECT_EQ(s.camera.position, (Vec3{3, 2, 4}));
    EXPECT_EQ(s.camera.lookAt, (Vec3{0.5, 0.5, 0.5}));
    EXPECT_EQ(s.camera.up, (Vec3{0, 1, 0}));
    EXPECT_FALSE(s.camera.orthographic);
    EXPECT_EQ(s.camera.fovYDegrees, 30.0);
    EXPECT_EQ(s.camera.width, 512);
    EXPECT_EQ(s.camera.height, 512);
    EXPECT_TRUE(s.isosurfaces.empty());
    EXPECT_TRUE(s.slices.empty());
    EXPECT_FALSE(s.volume.has_value());
    EXPECT_EQ(s.lighting.ambient, 0.1);
    EXPECT_EQ(s.lighting.diffuse, 0.8);
    EXPECT_EQ(s.lighting.specular, 0.3);
    EXPECT_EQ(s.lighting.shininess, 32.0);
    EXPECT_EQ(s.background, (Vec3{1, 1, 1}));
    EXPECT_EQ(s.accuracy.mappingTolerance, 1e-12);
    EXPECT_EQ(s.accuracy.projectionOrder, 0);  // auto
    EXPECT_EQ(s.accuracy.projectionTolerance, 1e-12);
    EXPECT_EQ(s.accuracy.rootTolerance, 1e-14);
    EXPECT_EQ(s.accuracy.volumeTolerance, 1e-10);
    EXPECT_EQ(s.clip.near, 0.0);
    EXPECT_EQ(s.clip.far, kInf);
    EXPECT_FALSE(s.clip.box.has_value());
    EXPECT_TRUE(s.output.exr.empty());
    EXPECT_TRUE(s.output.png.empty());
    EXPECT_TRUE(s.output.stats.empty());
    EXPECT_TRUE(s.output.hits.empty());
    EXPECT_TRUE(s.output.rgba.empty());
    EXPECT_EQ(s.threads, 0);
    EXPECT_EQ(s.distribute, Distribution::Auto);
    EXPECT_TRUE(s.FieldNames().empty());
}

TEST(SceneTest, ItemDefaults) {
    const Scene s = ParseScene(std::string(kMinimal) +
                                   "isosurfaces: [{value: 0.25}]\n"
                                   "slices: [{point: [0, 0, 0], normal: [1, 0, 0], "
                                   "color_tf: [[0, 1, 1, 1]]}]\n"
                                   "volume: {color_field: v, color_tf: [[0, 1, 0, 0]], "
                                   "extinction_tf: [[0, 1]]}\n",
                               "t.yaml");
    ASSERT_EQ(s.isosurfaces.size(), 1u);
    EXPECT_EQ(s.isosurfaces[0].field, "u");
    EXPECT_EQ(s.isosurfaces[0].value, 0.25);
    EXPECT_EQ(s.isosurfaces[0].color, (Vec3{0.9, 0.5, 0.2}));
    EXPECT_EQ(s.isosurfaces[0].opacity, 1.0);
    ASSERT_EQ(s.slices.size(), 1u);
    EXPECT_EQ(s.slices[0].field, "u");
    EXPECT_EQ(s.slices[0].opacity, 1.0);
    ASSERT_TRUE(s.volume.has_value());
    EXPECT_EQ(s.volume->colorField, "v");
    EXPECT_EQ(s.volume->extinctionField, "v");  // defaults to color_field
    EXPECT_EQ(s.volume->glow, GlowModel::WilliamsMax);
    EXPECT_EQ(s.FieldNames(), (std::vector<std::string>{"u", "v"}));
}

TEST(SceneTest, EveryKeyOfTheDesignExample) {
    const Scene s = ParseScene(kDesignExample, "design.yaml", {}, "/scenes/here");
    EXPECT_EQ(s.data.mesh, "/scenes/here/path/to/mesh.vtu");
    EXPECT_EQ(s.camera.position, (Vec3{3, 2, 4}));
    EXPECT_EQ(s.camera.lookAt, (Vec3{0.5, 0.5, 0.5}));
    EXPECT_EQ(s.camera.up, (Vec3{0, 1, 0}));
    EXPECT_FALSE(s.camera.orthographic);
    EXPECT_EQ(s.camera.fovYDegrees, 30.0);
    EXPECT_EQ(s.camera.width, 512);
    EXPECT_EQ(s.camera.height, 512);

    ASSERT_EQ(s.isosurfaces.size(), 1u);
    EXPECT_EQ(s.isosurfaces[0].field, "u");
    EXPECT_EQ(s.isosurfaces[0].value, 0.0);
    EXPECT_EQ(s.isosurfaces[0].color, (Vec3{0.9, 0.5, 0.2}));
    EXPECT_EQ(s.isosurfaces[0].opacity, 1.0);

    ASSERT_EQ(s.slices.size(), 1u);
    EXPECT_EQ(s.slices[0].point, (Vec3{0.5, 0.5, 0.5}));
    EXPECT_EQ(s.slices[0].normal, (Vec3{0, 0, 1}));
    EXPECT_EQ(s.slices[0].field, "u");
    ASSERT_EQ(s.slices[0].colorTf.size(), 2u);
    EXPECT_EQ(s.slices[0].colorTf[0].scalar, -1.0);
    EXPECT_EQ(s.slices[0].colorTf[0].rgb, (Vec3{0, 0, 1}));
    EXPECT_EQ(s.slices[0].colorTf[1].scalar, 1.0);
    EXPECT_EQ(s.slices[0].colorTf[1].rgb, (Vec3{1, 0, 0}));
    EXPECT_EQ(s.slices[0].opacity, 1.0);

    ASSERT_TRUE(s.volume.has_value());
    EXPECT_EQ(s.volume->colorField, "u");
    EXPECT_EQ(s.volume->extinctionField, "u");
    EXPECT_EQ(s.volume->glow, GlowModel::WilliamsMax);
    ASSERT_EQ(s.volume->colorTf.size(), 2u);
    EXPECT_EQ(s.volume->colorTf[0].scalar, -1.0);
    EXPECT_EQ(s.volume->colorTf[0].rgb, (Vec3{0, 0, 1}));
    EXPECT_EQ(s.volume->colorTf[1].scalar, 1.0);
    EXPECT_EQ(s.volume->colorTf[1].rgb, (Vec3{1, 0, 0}));
    ASSERT_EQ(s.volume->extinctionTf.size(), 2u);
    EXPECT_EQ(s.volume->extinctionTf[0].scalar, -1.0);
    EXPECT_EQ(s.volume->extinctionTf[0].extinction, 0.0);
    EXPECT_EQ(s.volume->extinctionTf[1].scalar, 1.0);
    EXPECT_EQ(s.volume->extinctionTf[1].extinction, 4.0);

    EXPECT_EQ(s.lighting.ambient, 0.1);
    EXPECT_EQ(s.lighting.diffuse, 0.8);
    EXPECT_EQ(s.lighting.specular, 0.3);
    EXPECT_EQ(s.lighting.shininess, 32.0);
    EXPECT_EQ(s.background, (Vec3{1, 1, 1}));
    EXPECT_EQ(s.accuracy.mappingTolerance, 1e-12);
    EXPECT_EQ(s.accuracy.projectionOrder, 0);
    EXPECT_EQ(s.accuracy.projectionTolerance, 1e-12);
    EXPECT_EQ(s.accuracy.rootTolerance, 1e-14);
    EXPECT_EQ(s.accuracy.volumeTolerance, 1e-10);
    EXPECT_EQ(s.clip.near, 0.0);
    EXPECT_EQ(s.clip.far, kInf);
    EXPECT_EQ(s.output.exr, Cwd("out/frame.exr"));
    EXPECT_EQ(s.output.png, Cwd("out/frame.png"));
    EXPECT_EQ(s.output.stats, Cwd("out/frame.json"));
    EXPECT_EQ(s.output.hits, Cwd("out/frame.hits.npy"));
    EXPECT_EQ(s.output.rgba, Cwd("out/frame.rgba.npy"));
}

TEST(SceneTest, OptionalKeysAndAlternatives) {
    const Scene s = ParseScene(std::string(kMinimal) + R"(
camera: {ortho_height: 2.5, width: 64, height: 1e2}
volume: {color_field: a, extinction_field: b, glow: wilhelms-van-gelder,
         color_tf: [[0, 0, 0, 0], [1, 7.5, 2, 0]], extinction_tf: [[0, 0]]}
accuracy: {projection_order: 12}
clip: {near: 0.5, far: 10, box: [[0, 0, 0], [1, 2, 3]]}
threads: 3
distribute: space
)",
                               "t.yaml");
    EXPECT_TRUE(s.camera.orthographic);
    EXPECT_EQ(s.camera.orthoHeight, 2.5);
    EXPECT_EQ(s.camera.width, 64);
    EXPECT_EQ(s.camera.height, 100);
    EXPECT_EQ(s.volume->glow, GlowModel::WilhelmsVanGelder);
    EXPECT_EQ(s.volume->colorTf[1].rgb[0], 7.5);  // glow may exceed 1
    EXPECT_EQ(s.volume->extinctionField, "b");
    EXPECT_EQ(s.FieldNames(), (std::vector<std::string>{"a", "b"}));
    EXPECT_EQ(s.accuracy.projectionOrder, 12);
    EXPECT_EQ(s.clip.near, 0.5);
    EXPECT_EQ(s.clip.far, 10.0);
    ASSERT_TRUE(s.clip.box.has_value());
    EXPECT_EQ(s.clip.box->lo, (Vec3{0, 0, 0}));
    EXPECT_EQ(s.clip.box->hi, (Vec3{1, 2, 3}));
    EXPECT_EQ(s.threads, 3);
    EXPECT_EQ(s.distribute, Distribution::Space);
    // `edges` drew nothing and is no longer accepted.
    EXPECT_TRUE(Contains(ErrorOf(std::string(kMinimal) + "edges: {}\n"), "unknown key 'edges'"));
}

TEST(SceneTest, KeyPathsCoverTheDesignSchema) {
    const std::vector<std::string> paths = SceneKeyPaths();
    for (const char* key : {"data.mesh",
                            "camera.position",
                            "camera.look_at",
                            "camera.up",
                            "camera.fov_y",
                            "camera.ortho_height",
                            "camera.width",
                            "camera.height",
                            "isosurfaces.#.field",
                            "isosurfaces.#.value",
                            "isosurfaces.#.color",
                            "isosurfaces.#.opacity",
                            "slices.#.point",
                            "slices.#.normal",
                            "slices.#.field",
                            "slices.#.color_tf",
                            "slices.#.opacity",
                            "volume.color_field",
                            "volume.extinction_field",
                            "volume.glow",
                            "volume.color_tf",
                            "volume.extinction_tf",
                            "lighting.ambient",
                            "lighting.diffuse",
                            "lighting.specular",
                            "lighting.shininess",
                            "background",
                            "accuracy.mapping_tolerance",
                            "accuracy.projection_order",
                            "accuracy.projection_tolerance",
                            "accuracy.root_tolerance",
                            "accuracy.volume_tolerance",
                            "clip.near",
                            "clip.far",
                            "clip.box",
                            "output.exr",
                            "output.png",
                            "output.stats",
                            "output.hits",
                            "output.rgba",
                            "output.errors"}) {
        EXPECT_NE(std::find(paths.begin(), paths.end(), key), paths.end()) << key;
    }
}

// ---------------------------------------------------------------------------------------
// Validation
// ---------------------------------------------------------------------------------------

TEST(SceneValidationTest, UnknownKeysNameThePathAndSuggest) {
    std::string e = ErrorOf(std::string(kMinimal) + "camra: {fov_y: 20}\n");
    EXPECT_TRUE(Contains(e, "test.yaml")) << e;
    EXPECT_TRUE(Contains(e, "line 2")) << e;
    EXPECT_TRUE(Contains(e, "unknown key 'camra'")) << e;
    EXPECT_TRUE(Contains(e, "did you mean 'camera'?")) << e;

    e = ErrorOf(std::string(kMinimal) + "camera:\n  width: 10\n  fovy: 20\n");
    EXPECT_TRUE(Contains(e, "line 4, camera.fovy")) << e;
    EXPECT_TRUE(Contains(e, "did you mean 'fov_y'?")) << e;

    e = ErrorOf(std::string(kMinimal) +
                "isosurfaces:\n  - {value: 0}\n  - {value: 1, colour: "
                "[1, 0, 0]}\n");
    EXPECT_TRUE(Contains(e, "line 4, isosurfaces.1.colour")) << e;
    EXPECT_TRUE(Contains(e, "did you mean 'color'?")) << e;

    e = ErrorOf(std::string(kMinimal) + "isosurface: []\n");
    EXPECT_TRUE(Contains(e, "did you mean 'isosurfaces'?")) << e;
    e = ErrorOf(std::string(kMinimal) + "accuracy: {root_tol: 1e-3}\n");
    EXPECT_TRUE(Contains(e, "accuracy.root_tol")) << e;
    EXPECT_TRUE(Contains(e, "did you mean 'root_tolerance'?")) << e;
    e = ErrorOf(std::string(kMinimal) + "output: {EXR: a.exr}\n");
    EXPECT_TRUE(Contains(e, "did you mean 'exr'?")) << e;

    // Nothing close: list the valid keys instead of a far-fetched guess.
    e = ErrorOf(std::string(kMinimal) + "lighting: {xyzzyplugh: 1}\n");
    EXPECT_TRUE(Contains(e, "lighting.xyzzyplugh")) << e;
    EXPECT_TRUE(Contains(e, "valid keys here: ambient, diffuse, specular, shininess"))
        << e;
    EXPECT_FALSE(Contains(e, "did you mean")) << e;
}

struct BadCase {
    const char* yaml;  // appended to a valid minimal scene (line 1)
    const char* keyPath;
    const char* message;
    int line;  // 0: do not check
};

TEST(SceneValidationTest, EachRuleNamesKeyAndLine) {
    const BadCase cases[] = {
        // types
        {"camera: {width: abc}\n", "camera.width", "expected an integer, got 'abc'", 2},
        {"camera: {width: 12.5}\n", "camera.width", "expected an integer", 2},
        {"camera: {fov_y: [1]}\n", "camera.fov_y", "expected a number, got a list", 2},
        {"camera: {position: [1, 2]}\n", "camera.position", "list of 3 numbers", 2},
        {"camera: {position: [1, x, 2]}\n", "camera.position.1", "expected a number", 2},
        {"camera: 5\n", "camera", "expected a mapping", 2},
        {"isosurfaces: {value: 1}\n", "isosurfaces", "expected a list", 2},
        {"isosurfaces: [{value: }]\n", "isosurfaces.0.value", "has no value", 2},
        {"isosurfaces: [{field: u}]\n", "isosurfaces.0.value", "required key is missing",
         2},
        {"isosurfaces: [{value: .nan}]\n", "isosurfaces.0.value", "NaN", 2},
        {"isosurfaces: [{value: .inf}]\n", "isosurfaces.0.value", "finite", 2},
        {"isosurfaces: [{value: 0, field: ''}]\n", "isosurfaces.0.field", "empty", 2},
        {"output: {png: [a]}\n", "output.png", "expected a string", 2},
        {"volume: {color_tf: [[0, 1, 1, 1]], extinction_tf: [[0, 1]], glow: sparkly}\n",
         "volume.glow", "unknown glow model 'sparkly'", 2},
        {"accuracy: {projection_order: often}\n", "accuracy.projection_order",
         "expected auto or an integer", 2},
        // ranges
        {"camera: {width: 0}\n", "camera.width", "[1, 32768]", 2},
        {"camera: {height: 32769}\n", "camera.height", "[1, 32768]", 2},
        {"camera: {fov_y: 0}\n", "camera.fov_y", "must be in (0, 180)", 2},
        {"camera: {fov_y: 180}\n", "camera.fov_y", "must be in (0, 180)", 2},
        {"camera: {ortho_height: 0}\n", "camera.ortho_height", "must be > 0", 2},
        {"camera: {ortho_height: -2}\n", "camera.ortho_height", "must be > 0", 2},
        {"camera:\n  fov_y: 30\n  ortho_height: 2\n", "camera.ortho_height", "not both",
         4},
        {"isosurfaces: [{value: 0, color: [1, 0, 1.5]}]\n", "isosurfaces.0.color.2",
         "[0, 1]", 2},
        {"isosurfaces: [{value: 0, opacity: -0.1}]\n", "isosurfaces.0.opacity", "[0, 1]",
         2},
        {"background: [0, 0, 2]\n", "background.2", "[0, 1]", 2},
        {"slices: [{point: [0, 0, 0], normal: [0, 0, 1], color_tf: [[0, 1, 1, 1]], "
         "opacity: 2}]\n",
         "slices.0.opacity", "[0, 1]", 2},
        {"slices: [{point: [0, 0, 0], normal: [0, 0, 0], color_tf: [[0, 1, 1, 1]]}]\n",
         "slices.0.normal", "non-zero", 2},
        {"slices: [{point: [0, 0, 0], normal: [0, 0, 1]}]\n", "slices.0.color_tf",
         "required key is missing", 2},
        {"volume:\n  color_tf:\n    - [0, 1, 1, 1]\n    - [0, 0, 0, 0]\n  extinction_tf: "
         "[[0, 1]]\n",
         "volume.color_tf.1", "strictly increasing", 5},
        {"volume: {color_tf: [[1, 1, 1, 1], [0.5, 0, 0, 0]], extinction_tf: [[0, 1]]}\n",
         "volume.color_tf.1", "strictly increasing", 2},
        {"volume: {color_tf: [[0, 1, 1, 1]], extinction_tf: [[0, 1], [1, -1]]}\n",
         "volume.extinction_tf.1", "extinction must be >= 0", 2},
        {"volume: {color_tf: [[0, 1, 1, 1]], extinction_tf: [[0, 1], [-1, 1]]}\n",
         "volume.extinction_tf.1", "strictly increasing", 2},
        {"volume: {color_tf: [[0, 1, 2, 1]], extinction_tf: [[0, 1]]}\n",
         "volume.color_tf.0", "[0, 1]", 2},
        {"volume: {glow: wilhelms-van-gelder, color_tf: [[0, 1, -2, 1]], "
         "extinction_tf: [[0, 1]]}\n",
         "volume.color_tf.0", "glow components must be >= 0", 2},
        {"volume: {color_tf: [], extinction_tf: [[0, 1]]}\n", "volume.color_tf",
         "non-empty list", 2},
        {"volume: {color_tf: [[0, 1, 1]], extinction_tf: [[0, 1]]}\n",
         "volume.color_tf.0", "list of 4 numbers", 2},
        {"volume: {color_tf: [[0, 1, 1, 1]], extinction_tf: []}\n", "volume.extinction_tf",
         "expected a non-empty list", 0},
        {"accuracy: {mapping_tolerance: 0}\n", "accuracy.mapping_tolerance",
         "must be > 0", 2},
        {"accuracy: {root_tolerance: -1e-14}\n", "accuracy.root_tolerance", "must be > 0",
         2},
        {"accuracy: {projection_tolerance: 0}\n", "accuracy.projection_tolerance", "> 0",
         2},
        {"accuracy: {volume_tolerance: 0}\n", "accuracy.volume_tolerance", "> 0", 2},
        {"accuracy: {projection_order: 0}\n", "accuracy.projection_order", "[1, 64]", 2},
        {"lighting: {diffuse: -1}\n", "lighting.diffuse", "must be >= 0", 2},
        {"clip: {near: -1}\n", "clip.near", "must be >= 0", 2},
        {"clip: {near: 2, far: 1}\n", "clip.far", "must be > clip.near", 2},
        {"clip: {box: [[0, 0, 0], [1, 0, 1]]}\n", "clip.box", "below the second", 2},
        {"threads: -1\n", "threads", "[0, 4096]", 2},
        {"distribute: pixels\n", "distribute", "auto, space or image", 2},
        // degenerate cameras
        {"camera: {position: [1, 2, 3], look_at: [1, 2, 3]}\n", "camera.look_at",
         "coincides with position", 2},
        {"camera: {position: [0, 0, 0], look_at: [0, 5, 0], up: [0, 1, 0]}\n",
         "camera.up", "parallel to the view direction", 2},
        {"camera: {position: [0, 0, 0], look_at: [0, 0, 1], up: [0, 0, -3]}\n",
         "camera.up", "parallel", 2},
        {"camera: {up: [0, 0, 0]}\n", "camera.up", "non-zero", 2},
        // structure
        {"data: {mesh: other}\n", "data", "duplicate key 'data'", 2},
        {"camera: {width: 1, width: 2}\n", "camera.width", "duplicate key", 2},
    };
    for (const BadCase& c : cases) {
        const std::string e = ErrorOf(std::string(kMinimal) + c.yaml);
        SCOPED_TRACE(c.yaml);
        EXPECT_TRUE(Contains(e, "test.yaml: ")) << e;
        EXPECT_TRUE(Contains(e, c.keyPath)) << e;
        EXPECT_TRUE(Contains(e, c.message)) << e;
        if (c.line > 0) {
            EXPECT_TRUE(Contains(e, "line " + std::to_string(c.line) + ", " + c.keyPath))
                << e;
        }
    }
}

TEST(SceneValidationTest, ValuesAtTheRangeBoundariesAreAccepted) {
    const Scene s = ParseScene(std::string(kMinimal) + R"(
camera: {fov_y: 179.9, width: 1, height: 32768}
isosurfaces: [{value: -1e300, color: [0, 1, 0], opacity: 0}]
background: [0, 0, 0]
lighting: {ambient: 0, diffuse: 0, specular: 0, shininess: 0}
volume: {color_tf: [[-1, 0, 0, 0], [-0.999999, 1, 1, 1]], extinction_tf: [[5, 0]]}
)",
                               "t.yaml");
    EXPECT_EQ(s.camera.width, 1);
    EXPECT_EQ(s.camera.height, 32768);
    EXPECT_EQ(s.isosurfaces[0].value, -1e300);
}

TEST(SceneValidationTest, MissingMeshEmptyFileMalformedYaml) {
    std::string e = ErrorOf("camera: {width: 10}\n");
    EXPECT_TRUE(Contains(e, "data")) << e;
    EXPECT_TRUE(Contains(e, "required key is missing")) << e;
    e = ErrorOf("data: {}\n");
    EXPECT_TRUE(Contains(e, "data.mesh: required key is missing")) << e;
    e = ErrorOf("data:\n  mesh:\n");
    EXPECT_TRUE(Contains(e, "data.mesh")) << e;
    EXPECT_TRUE(Contains(e, "has no value")) << e;

    for (const char* empty : {"", "\n\n", "# only a comment\n", "---\n"}) {
        e = ErrorOf(empty);
        EXPECT_TRUE(Contains(e, "test.yaml")) << e;
        EXPECT_TRUE(Contains(e, "empty")) << e;
    }
    e = ErrorOf("- 1\n- 2\n");
    EXPECT_TRUE(Contains(e, "expected a mapping")) << e;

    // yaml-cpp's position: the unclosed flow sequence runs to the end of the text.
    e = ErrorOf("data: {mesh: builtin:nk-sinc}\ncamera:\n  position: [1, 2\n");
    EXPECT_TRUE(Contains(e, "test.yaml: line ")) << e;
    EXPECT_TRUE(Contains(e, ", column ")) << e;
    EXPECT_TRUE(Contains(e, "malformed YAML")) << e;
    e = ErrorOf("data: {mesh: builtin:nk-sinc}\ncamera:\n  width: 10\n   height: 10\n");
    EXPECT_TRUE(Contains(e, "test.yaml: line 4, column")) << e;
    e = ErrorOf("a: 1\n---\nb: 2\n");
    EXPECT_TRUE(Contains(e, "one YAML document")) << e;
    // Deep nesting is refused by yaml-cpp's depth guard, not by a stack overflow.
    e = ErrorOf(std::string(100000, '[') + std::string(100000, ']'));
    EXPECT_TRUE(Contains(e, "test.yaml")) << e;
}

// ---------------------------------------------------------------------------------------
// Overrides
// ---------------------------------------------------------------------------------------

TEST(SceneOverrideTest, SetsExistingCreatesAbsentAndIndexes) {
    const std::string yaml = std::string(kMinimal) +
                             "camera: {width: 512}\n"
                             "isosurfaces: [{value: 0}, {value: 1, color: [1, 0, 0]}]\n";
    const Scene s = ParseScene(
        yaml, "t.yaml",
        {"camera.width=64", "isosurfaces.0.value=0.5",
         "volume.color_tf=[[0,1,0,0],[1,0,0,1]]", "volume.extinction_tf=[[0, 2]]",
         "clip.far=10", "isosurfaces.1.color.2=0.75", "isosurfaces.2.value=-3",
         "lighting.shininess=8", "output.png=o/x.png"});
    EXPECT_EQ(s.camera.width, 64);
    EXPECT_EQ(s.camera.height, 512);
    ASSERT_EQ(s.isosurfaces.size(), 3u);
    EXPECT_EQ(s.isosurfaces[0].value, 0.5);
    EXPECT_EQ(s.isosurfaces[1].value, 1.0);
    EXPECT_EQ(s.isosurfaces[1].color, (Vec3{1, 0, 0.75}));
    EXPECT_EQ(s.isosurfaces[2].value, -3.0);  // appended, other keys default
    EXPECT_EQ(s.isosurfaces[2].field, "u");
    ASSERT_TRUE(s.volume.has_value());
    ASSERT_EQ(s.volume->colorTf.size(), 2u);
    EXPECT_EQ(s.volume->colorTf[0].rgb, (Vec3{1, 0, 0}));
    EXPECT_EQ(s.volume->colorTf[1].scalar, 1.0);
    EXPECT_EQ(s.volume->colorTf[1].rgb, (Vec3{0, 0, 1}));
    EXPECT_EQ(s.volume->extinctionTf[0].extinction, 2.0);
    EXPECT_EQ(s.clip.far, 10.0);
    EXPECT_EQ(s.lighting.shininess, 8.0);
    EXPECT_EQ(s.lighting.ambient, 0.1);
    EXPECT_EQ(s.output.png, Cwd("o/x.png"));
}

TEST(SceneOverrideTest, LaterOverridesWinAndNullRemoves) {
    const std::string yaml = std::string(kMinimal) + "camera: {fov_y: 40}\n";
    Scene s = ParseScene(yaml, "t.yaml", {"camera.width=10", "camera.width=20"});
    EXPECT_EQ(s.camera.width, 20);
    // Switching to orthographic: drop fov_y, add ortho_height.
    s = ParseScene(yaml, "t.yaml", {"camera.fov_y=null", "camera.ortho_height=3"});
    EXPECT_TRUE(s.camera.orthographic);
    EXPECT_EQ(s.camera.orthoHeight, 3.0);
    const std::string e = ErrorOf(yaml, {"camera.ortho_height=3"});
    EXPECT_TRUE(Contains(e, "not both")) << e;
    // Removing a list entry.
    s = ParseScene(std::string(kMinimal) + "isosurfaces: [{value: 1}, {value: 2}]\n",
                   "t.yaml", {"isosurfaces.0=~"});
    ASSERT_EQ(s.isosurfaces.size(), 1u);
    EXPECT_EQ(s.isosurfaces[0].value, 2.0);
    // Overrides on an empty text build the whole scene.
    s = ParseScene("", "t.yaml",
                   {"data.mesh=builtin:ball-p2", "isosurfaces.0.value=0.5"});
    EXPECT_EQ(s.data.mesh, "builtin:ball-p2");
    EXPECT_EQ(s.isosurfaces.at(0).value, 0.5);
}

TEST(SceneOverrideTest, BadOverridesAreErrors) {
    std::string e = ErrorOf(kMinimal, {"camera.fovy=20"});
    EXPECT_TRUE(Contains(e, "--set camera.fovy=20")) << e;
    EXPECT_TRUE(Contains(e, "unknown key 'camera.fovy'")) << e;
    EXPECT_TRUE(Contains(e, "did you mean 'fov_y'?")) << e;
    e = ErrorOf(kMinimal, {"camra.width=20"});
    EXPECT_TRUE(Contains(e, "did you mean 'camera'?")) << e;
    e = ErrorOf(kMinimal, {"isosurfaces.0.valeu=1"});
    EXPECT_TRUE(Contains(e, "did you mean 'value'?")) << e;
    e = ErrorOf(kMinimal, {"isosurfaces.3.value=1"});
    EXPECT_TRUE(Contains(e, "past the end")) << e;
    e = ErrorOf(kMinimal, {"isosurfaces.first.value=1"});
    EXPECT_TRUE(Contains(e, "not a list index")) << e;
    e = ErrorOf(kMinimal, {"camera.width.x=1"});
    EXPECT_TRUE(Contains(e, "takes a value, not sub-keys")) << e;
    e = ErrorOf(kMinimal, {"camera.width"});
    EXPECT_TRUE(Contains(e, "expected key.path=value")) << e;
    e = ErrorOf(kMinimal, {"camera..width=1"});
    EXPECT_TRUE(Contains(e, "empty key")) << e;
    e = ErrorOf(kMinimal, {"camera.position=[1, 2"});
    EXPECT_TRUE(Contains(e, "not valid YAML")) << e;
    // A bad value arriving by --set is reported against the override, not a file line.
    e = ErrorOf(kMinimal, {"camera.width=0"});
    EXPECT_TRUE(Contains(e, "camera.width (--set camera.width=0)")) << e;
    EXPECT_TRUE(Contains(e, "[1, 32768]")) << e;
    e = ErrorOf(kMinimal, {"volume.color_tf=[[1,1,0,0],[0,0,0,1]]",
                           "volume.extinction_tf=[[0, 1]]"});
    EXPECT_TRUE(Contains(e, "volume.color_tf.1 (--set volume.color_tf=")) << e;
    EXPECT_TRUE(Contains(e, "strictly increasing")) << e;
}

// ---------------------------------------------------------------------------------------
// Files and paths
// ---------------------------------------------------------------------------------------

class SceneFileTest : public ::testing::Test {
  protected:
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        dir_ =
            fs::temp_directory_path() / ("hpray_test_scene_" + std::string(info->name()));
        fs::remove_all(dir_);
        fs::create_directories(dir_ / "scenes");
    }
    void TearDown() override { fs::remove_all(dir_); }
    std::string Write(const std::string& name, const std::string& text) {
        const fs::path path = dir_ / name;
        std::ofstream(path) << text;
        return path.string();
    }
    fs::path dir_;
};

TEST_F(SceneFileTest, InputPathsResolveAgainstTheSceneFolder) {
    const std::string path = Write("scenes/a.yaml",
                                   "data: {mesh: ../meshes/m.vtu}\n"
                                   "output: {exr: out/a.exr, png: /abs/a.png}\n");
    const Scene s = LoadScene(path, {});
    EXPECT_EQ(s.sourcePath, path);
    EXPECT_EQ(s.data.mesh, (dir_ / "meshes/m.vtu").string());
    EXPECT_EQ(s.output.exr, Cwd("out/a.exr"));  // outputs: the working directory
    EXPECT_EQ(s.output.png, "/abs/a.png");

    const Scene abs =
        LoadScene(Write("scenes/b.yaml", "data: {mesh: /data/x.vtu}\n"), {});
    EXPECT_EQ(abs.data.mesh, "/data/x.vtu");
    const Scene builtin = LoadScene(
        Write("scenes/c.yaml", "data: {mesh: 'builtin:nk-sinc?order=4'}\n"), {});
    EXPECT_EQ(builtin.data.mesh, "builtin:nk-sinc?order=4");
    // An override of an input path resolves against the scene folder too.
    const Scene over = LoadScene(path, {"data.mesh=other.vtu"});
    EXPECT_EQ(over.data.mesh, (dir_ / "scenes/other.vtu").string());
    // ParseScene without a base folder: the working directory.
    EXPECT_EQ(ParseScene("data: {mesh: m.vtu}", "t.yaml").data.mesh, Cwd("m.vtu"));
}

TEST_F(SceneFileTest, FileErrorsNameTheFile) {
    const std::string missing = (dir_ / "nope.yaml").string();
    try {
        LoadScene(missing, {});
        FAIL() << "expected InputError";
    } catch (const InputError& e) {
        EXPECT_TRUE(Contains(e.what(), missing)) << e.what();
    }
    EXPECT_THROW(LoadScene(dir_.string(), {}), InputError);
    const std::string path = Write("bad.yaml", "data: {mesh: builtin:nk-sinc}\nfoo: 1\n");
    try {
        LoadScene(path, {});
        FAIL() << "expected InputError";
    } catch (const InputError& e) {
        EXPECT_TRUE(Contains(e.what(), path + ": line 2, foo: unknown key")) << e.what();
    }
}

TEST(SceneConfigsTest, EveryConfigParses) {
    const fs::path configs = fs::path(HPRAY_TEST_DATA) / ".." / ".." / "configs";
    ASSERT_TRUE(fs::is_directory(configs)) << configs;
    int count = 0;
    for (const auto& entry : fs::directory_iterator(configs)) {
        const std::string ext = entry.path().extension().string();
        if (ext != ".yaml" && ext != ".yml") continue;
        SCOPED_TRACE(entry.path().string());
        EXPECT_NO_THROW(LoadScene(entry.path().string(), {}));
        ++count;
    }
    EXPECT_GE(count, 1);
}

TEST(SceneConfigsTest, Quickstart) {
    const fs::path path =
        fs::path(HPRAY_TEST_DATA) / ".." / ".." / "configs" / "quickstart.yaml";
    const Scene s = LoadScene(path.string(), {});
    EXPECT_EQ(s.data.mesh, "builtin:nk-sinc");
    EXPECT_EQ(s.camera.position, (Vec3{2.2, 1.6, 2.6}));
    EXPECT_EQ(s.camera.lookAt, (Vec3{0.5, 0.5, 0.5}));
    EXPECT_EQ(s.camera.up, (Vec3{0, 1, 0}));
    EXPECT_EQ(s.camera.fovYDegrees, 30.0);
    EXPECT_EQ(s.camera.width, 512);
    EXPECT_EQ(s.camera.height, 512);
    ASSERT_EQ(s.isosurfaces.size(), 1u);
    EXPECT_EQ(s.isosurfaces[0].value, 0.0);
    EXPECT_EQ(s.output.exr, Cwd("out/quickstart.exr"));
    EXPECT_EQ(s.output.png, Cwd("out/quickstart.png"));
    EXPECT_EQ(s.output.stats, Cwd("out/quickstart.json"));
}

// ---------------------------------------------------------------------------------------
// Camera
// ---------------------------------------------------------------------------------------

double Dot(const Vec3& a, const Vec3& b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
double Norm(const Vec3& a) { return std::sqrt(Dot(a, a)); }
double AngleDegrees(const Vec3& a, const Vec3& b) {
    return std::acos(std::clamp(Dot(a, b) / (Norm(a) * Norm(b)), -1.0, 1.0)) * 180.0 /
           M_PI;
}

SceneCamera MakeCamera(Vec3 position, Vec3 lookAt, Vec3 up, int w, int h) {
    SceneCamera c;
    c.position = position;
    c.lookAt = lookAt;
    c.up = up;
    c.width = w;
    c.height = h;
    return c;
}

TEST(CameraTest, AxisAlignedFrame) {
    // Looking down -z with +y up: right = +x, trueUp = +y.
    const Camera cam(MakeCamera({0, 0, 5}, {0, 0, 0}, {0, 1, 0}, 5, 3));
    EXPECT_EQ(cam.Forward(), (Vec3{0, 0, -1}));
    EXPECT_EQ(cam.Right(), (Vec3{1, 0, 0}));
    EXPECT_EQ(cam.TrueUp(), (Vec3{0, 1, 0}));
    // The centre pixel of an odd-sized image looks exactly along forward.
    const CameraRay centre = cam.PixelRay(2, 1);
    EXPECT_EQ(centre.direction, (Vec3{0, 0, -1}));
    EXPECT_EQ(centre.origin, (Vec3{0, 0, 5}));
    // i grows to the right (+x), j grows downwards (-y).
    EXPECT_GT(cam.PixelRay(4, 1).direction[0], 0.0);
    EXPECT_LT(cam.PixelRay(0, 1).direction[0], 0.0);
    EXPECT_GT(cam.PixelRay(2, 0).direction[1], 0.0);
    EXPECT_LT(cam.PixelRay(2, 2).direction[1], 0.0);
}

TEST(CameraTest, CentreRayOfAGeneralCameraIsForward) {
    for (int seed = 0; seed < 20; ++seed) {
        const double a = 0.37 * seed, b = 1.1 + 0.13 * seed;
        const Vec3 position{3 * std::cos(a), 2 * std::sin(b), 1 + std::sin(a + b)};
        const Vec3 lookAt{0.5, -0.25 * seed, 0.1};
        const SceneCamera settings = MakeCamera(position, lookAt, {0, 1, 0}, 31, 17);
        const Camera cam(settings);
        const Vec3 d{lookAt[0] - position[0], lookAt[1] - position[1],
                     lookAt[2] - position[2]};
        const CameraRay ray = cam.PixelRay(15, 8);
        for (int k = 0; k < 3; ++k)
            EXPECT_NEAR(ray.direction[k], d[k] / Norm(d), 1e-15) << seed;
        EXPECT_NEAR(Norm(ray.direction), 1.0, 1e-15);
        // The frame is orthonormal and right-handed: right x trueUp = -forward.
        EXPECT_NEAR(Dot(cam.Right(), cam.Forward()), 0.0, 1e-15);
        EXPECT_NEAR(Dot(cam.TrueUp(), cam.Forward()), 0.0, 1e-15);
        EXPECT_NEAR(Dot(cam.TrueUp(), cam.Right()), 0.0, 1e-15);
        EXPECT_NEAR(Norm(cam.TrueUp()), 1.0, 1e-15);
        EXPECT_GT(cam.TrueUp()[1], 0.0);  // true_up leans towards up
    }
}

TEST(CameraTest, PerspectiveCornerAndEdgeAngles) {
    // W = 2H and fov_y = 90: the top image edge is 45 degrees above forward; the right
    // edge is at atan(W/H * tan 45) = atan 2 beside it. Pixel centres sit half a pixel
    // inside, so use continuous coordinates for the edges and check pixel centres apart.
    const int w = 400, h = 200;
    SceneCamera settings = MakeCamera({1, 2, 3}, {1, 2, -7}, {0, 1, 0}, w, h);
    settings.fovYDegrees = 90.0;
    const Camera cam(settings);
    const Vec3 f = cam.Forward();
    EXPECT_NEAR(AngleDegrees(cam.RayAt(w / 2.0, 0).direction, f), 45.0, 1e-12);
    EXPECT_NEAR(AngleDegrees(cam.RayAt(w / 2.0, h).direction, f), 45.0, 1e-12);
    EXPECT_NEAR(AngleDegrees(cam.RayAt(w, h / 2.0).direction, f),
                std::atan(2.0) * 180 / M_PI, 1e-12);
    // The corner (0, 0): tan of the angle = sqrt(2^2 + 1^2).
    EXPECT_NEAR(AngleDegrees(cam.RayAt(0, 0).direction, f),
                std::atan(std::sqrt(5.0)) * 180 / M_PI, 1e-12);
    // Corner pixel centres against the formula of docs/contracts.md.
    const double t = std::tan(M_PI / 4);
    for (const auto& [i, j] : {std::pair{0, 0}, std::pair{w - 1, 0}, std::pair{0, h - 1},
                               std::pair{w - 1, h - 1}, std::pair{17, 123}}) {
        const double sx = (2.0 * (i + 0.5) / w - 1.0) * (double(w) / h) * t;
        const double sy = (1.0 - 2.0 * (j + 0.5) / h) * t;
        // Here forward = -z, right = +x, trueUp = +y.
        const Vec3 expected{sx / std::sqrt(1 + sx * sx + sy * sy),
                            sy / std::sqrt(1 + sx * sx + sy * sy),
                            -1 / std::sqrt(1 + sx * sx + sy * sy)};
        const CameraRay ray = cam.PixelRay(i, j);
        for (int k = 0; k < 3; ++k)
            EXPECT_NEAR(ray.direction[k], expected[k], 1e-15) << i << "," << j;
        EXPECT_EQ(ray.origin, (Vec3{1, 2, 3}));
    }
    // Symmetric pixels mirror each other.
    const CameraRay a = cam.PixelRay(10, 20), b = cam.PixelRay(w - 1 - 10, h - 1 - 20);
    EXPECT_NEAR(a.direction[0], -b.direction[0], 1e-15);
    EXPECT_NEAR(a.direction[1], -b.direction[1], 1e-15);
    EXPECT_NEAR(a.direction[2], b.direction[2], 1e-15);
}

TEST(CameraTest, OrthographicOriginsSpacedByOrthoHeightOverH) {
    const int w = 6, h = 4;
    SceneCamera settings = MakeCamera({0, 0, 0}, {3, 0, 0}, {0, 0, 1}, w, h);
    settings.orthographic = true;
    settings.orthoHeight = 2.0;
    const Camera cam(settings);
    // forward = +x, right = forward x up = x cross z = -y, trueUp = right x forward = +z.
    EXPECT_EQ(cam.Forward(), (Vec3{1, 0, 0}));
    EXPECT_EQ(cam.Right(), (Vec3{0, -1, 0}));
    EXPECT_EQ(cam.TrueUp(), (Vec3{0, 0, 1}));
    const double spacing = settings.orthoHeight / h;  // the same in both directions
    for (int j = 0; j < h; ++j) {
        for (int i = 0; i < w; ++i) {
            const CameraRay ray = cam.PixelRay(i, j);
            EXPECT_EQ(ray.direction, (Vec3{1, 0, 0}));
            EXPECT_NEAR(ray.origin[0], 0.0, 1e-15);
            EXPECT_NEAR(ray.origin[1], -(i + 0.5 - w / 2.0) * spacing, 1e-15) << i;
            EXPECT_NEAR(ray.origin[2], (h / 2.0 - j - 0.5) * spacing, 1e-15) << j;
        }
    }
    // The image spans ortho_height vertically and ortho_height * W/H horizontally.
    EXPECT_NEAR(cam.RayAt(0, 0).origin[2] - cam.RayAt(0, h).origin[2], 2.0, 1e-15);
    EXPECT_NEAR(cam.RayAt(0, 0).origin[1] - cam.RayAt(w, 0).origin[1], 3.0, 1e-15);
}

TEST(CameraTest, FromAParsedScene) {
    const Scene s = ParseScene(std::string(kMinimal) +
                                   "camera: {position: [0, 0, 0], look_at: [0, 0, -1], "
                                   "fov_y: 60, width: 3, height: 3}\n",
                               "t.yaml");
    const Camera cam(s.camera);
    EXPECT_EQ(cam.Width(), 3);
    EXPECT_FALSE(cam.Orthographic());
    // Top-centre pixel: sy = (1 - 1/3) tan 30 deg.
    const double sy = (2.0 / 3.0) * std::tan(M_PI / 6);
    const CameraRay ray = cam.PixelRay(1, 0);
    EXPECT_NEAR(ray.direction[1], sy / std::sqrt(1 + sy * sy), 1e-15);
    EXPECT_NEAR(ray.direction[2], -1 / std::sqrt(1 + sy * sy), 1e-15);
}

TEST(SceneCamera, ViewOriginOrdersKdLeaves) {
    SceneCamera camera;
    camera.position = {0.2, 3.0, 0.7};
    camera.lookAt = {0.5, 0.5, 0.5};
    EXPECT_TRUE(LowInFront(0, 0.5, ViewOriginOf(camera)));
    EXPECT_FALSE(LowInFront(1, 0.5, ViewOriginOf(camera)));
    camera.orthographic = true;
    camera.orthoHeight = 2.0;
    // Direction (0.3, -2.5, -0.2): low in front along x, high along y and z.
    EXPECT_TRUE(LowInFront(0, 0.9, ViewOriginOf(camera)));
    EXPECT_FALSE(LowInFront(1, -4.0, ViewOriginOf(camera)));
    EXPECT_FALSE(LowInFront(2, 0.0, ViewOriginOf(camera)));
}

}  // namespace
}  // namespace hpray

// ---------------------------------------------------------------------------------------
// Automatic cameras
// ---------------------------------------------------------------------------------------

namespace hpray {
namespace {

TEST(AutoCameraTest, ParsedWhenAskedOrWithoutPosition) {
    EXPECT_TRUE(ParseScene(kMinimal, "t.yaml").camera.autoFit);
    EXPECT_TRUE(ParseScene(std::string(kMinimal) + "camera: auto\n", "t.yaml").camera.autoFit);
    const Scene sized = ParseScene(std::string(kMinimal) +
                                       "camera: {width: 64, height: 48, view: -z, zoom: 2, "
                                       "azimuth: 30, elevation: -10}\n",
                                   "t.yaml");
    EXPECT_TRUE(sized.camera.autoFit);
    EXPECT_EQ(sized.camera.width, 64);
    EXPECT_EQ(sized.camera.view, "-z");
    EXPECT_EQ(sized.camera.zoom, 2.0);
    EXPECT_EQ(sized.camera.azimuthDegrees, 30.0);
    EXPECT_EQ(sized.camera.elevationDegrees, -10.0);
    EXPECT_FALSE(ParseScene(std::string(kMinimal) + "camera: {position: [3, 2, 4]}\n", "t.yaml")
                     .camera.autoFit);
    const std::string bad = ErrorOf(std::string(kMinimal) + "camera: {view: top}\n");
    EXPECT_TRUE(Contains(bad, "camera.view")) << bad;
    const std::string both =
        ErrorOf(std::string(kMinimal) + "camera: {position: [3, 2, 4], zoom: 2}\n");
    EXPECT_TRUE(Contains(both, "camera.zoom")) << both;
    EXPECT_TRUE(Contains(ErrorOf(std::string(kMinimal) + "camera: {zoom: 0}\n"), "camera.zoom"));
    EXPECT_TRUE(Contains(ErrorOf(std::string(kMinimal) + "camera: {elevation: 95}\n"),
                         "camera.elevation"));
    EXPECT_TRUE(Contains(ErrorOf(std::string(kMinimal) + "camera: automatic\n"), "camera"));
}

/// Every corner of `box` seen by the camera lies inside the image (perspective: within
/// the field of view; orthographic: within the view's width and height).
void ExpectBoxInView(const SceneCamera& c, const Box& box, const std::string& what) {
    const Camera camera(c);
    const auto& f = camera.Forward();
    const auto& r = camera.Right();
    const auto& u = camera.TrueUp();
    const double aspect = double(c.width) / c.height;
    const double ty = std::tan(0.5 * c.fovYDegrees * M_PI / 180), tx = ty * aspect;
    for (int q = 0; q < 8; ++q) {
        double x[3], along = 0, right = 0, upward = 0;
        for (int d = 0; d < 3; ++d) {
            x[d] = ((q >> d) & 1 ? box.hi[d] : box.lo[d]) - c.position[d];
            along += x[d] * f[d];
            right += x[d] * r[d];
            upward += x[d] * u[d];
        }
        ASSERT_GT(along, 0) << what;
        if (c.orthographic) {
            EXPECT_LE(std::abs(upward), 0.5 * c.orthoHeight * (1 + 1e-12)) << what;
            EXPECT_LE(std::abs(right), 0.5 * c.orthoHeight * aspect * (1 + 1e-12)) << what;
        } else {
            EXPECT_LE(std::abs(right), tx * along * (1 + 1e-12)) << what << " corner " << q;
            EXPECT_LE(std::abs(upward), ty * along * (1 + 1e-12)) << what << " corner " << q;
        }
    }
}

// The fitted view holds the whole box from every side, aspect and zoom 1, and is tight:
// the box's projection fills 90% of the view's width or height about the image centre;
// the views look from the side they name, azimuth turns about up and elevation raises
// toward it.
TEST(AutoCameraTest, FitsTheBoxFromEverySide) {
    const Box box{{-1.0, 2.0, 0.5}, {3.0, 2.5, 4.0}};
    const double cx = 1.0, cy = 2.25, cz = 2.25;
    const double radius = std::sqrt(2.0 * 2.0 + 0.25 * 0.25 + 1.75 * 1.75);
    for (const char* view : {"iso", "+x", "-x", "+y", "-y", "+z", "-z"})
        for (const auto& [w, h] : {std::pair{64, 48}, std::pair{40, 90}}) {
            SceneCamera c;
            c.autoFit = true;
            c.view = view;
            c.width = w;
            c.height = h;
            FitCamera(c, box, std::nullopt);
            EXPECT_FALSE(c.autoFit);
            const std::string what = std::string(view) + " " + std::to_string(w) + "x" +
                                     std::to_string(h);
            EXPECT_EQ(c.lookAt, (std::array<double, 3>{cx, cy, cz})) << what;
            ExpectBoxInView(c, box, what);
            // The largest share of the half-width or half-height a corner takes is 0.9.
            const Camera camera(c);
            const double ty = std::tan(0.5 * c.fovYDegrees * M_PI / 180), tx = ty * w / h;
            double fill = 0;
            for (int q = 0; q < 8; ++q) {
                double along = 0, right = 0, upward = 0;
                for (int d = 0; d < 3; ++d) {
                    const double x = ((q >> d) & 1 ? box.hi[d] : box.lo[d]) - c.position[d];
                    along += x * camera.Forward()[d];
                    right += x * camera.Right()[d];
                    upward += x * camera.TrueUp()[d];
                }
                fill = std::max({fill, std::fabs(right) / (tx * along),
                                 std::fabs(upward) / (ty * along)});
            }
            EXPECT_NEAR(fill, 0.9, 1e-12) << what;
            // No farther than where the sphere about the box fills 90% of the view.
            EXPECT_LE(std::hypot(c.position[0] - cx, c.position[1] - cy, c.position[2] - cz),
                      radius / std::sin(std::atan(0.9 * std::min(tx, ty))) * (1 + 1e-12))
                << what;
        }
    SceneCamera c;
    c.autoFit = true;
    c.view = "+x";
    FitCamera(c, box, std::nullopt);
    EXPECT_GT(c.position[0], box.hi[0]);
    EXPECT_DOUBLE_EQ(c.position[1], cy);
    EXPECT_DOUBLE_EQ(c.position[2], cz);
    // From +z turned 90 degrees about +y: the eye is on the +x side.
    SceneCamera turned;
    turned.autoFit = true;
    turned.view = "+z";
    turned.azimuthDegrees = 90;
    FitCamera(turned, box, std::nullopt);
    EXPECT_NEAR(turned.position[0], c.position[0], 1e-12 * radius);
    EXPECT_NEAR(turned.position[2], cz, 1e-12 * radius);
    // Raised by 30 degrees toward up: the view direction drops by 30 degrees.
    SceneCamera raised;
    raised.autoFit = true;
    raised.view = "+x";
    raised.elevationDegrees = 30;
    FitCamera(raised, box, std::nullopt);
    const double dy = raised.position[1] - cy, dx = raised.position[0] - cx;
    EXPECT_NEAR(std::atan2(dy, dx) * 180 / M_PI, 30.0, 1e-9);
    // Zoom 2 halves the distance; an orthographic camera keeps its height over zoom.
    SceneCamera zoomed = c;
    zoomed.autoFit = true;
    zoomed.zoom = 2;
    FitCamera(zoomed, box, std::nullopt);
    EXPECT_NEAR(zoomed.position[0] - cx, 0.5 * (c.position[0] - cx), 1e-12);
    SceneCamera ortho;
    ortho.autoFit = true;
    ortho.orthographic = true;
    ortho.orthoHeight = 9;
    ortho.zoom = 1.5;
    FitCamera(ortho, box, std::nullopt);
    EXPECT_EQ(ortho.orthoHeight, 6);
    ExpectBoxInView(ortho, box, "ortho");
    // A clip box narrows what is fitted.
    SceneCamera clipped;
    clipped.autoFit = true;
    FitCamera(clipped, box, Box{{0, 2, 1}, {1, 2.5, 2}});
    EXPECT_EQ(clipped.lookAt, (std::array<double, 3>{0.5, 2.25, 1.5}));
}

}  // namespace
}  // namespace hpray

// ---------------------------------------------------------------------------------------
// Named colour maps
// ---------------------------------------------------------------------------------------

namespace hpray {
namespace {

double LinearToSrgbValue(double c) {
    return c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1 / 2.4) - 0.055;
}

// The maps end where their published definitions do (hex values of the matplotlib and
// Moreland tables), spread over the range asked for, in linear RGB.
TEST(ColorMapTest, ExpandedMapsMatchTheirPublishedEnds) {
    struct End {
        const char* name;
        int first[3], last[3];
    };
    const End ends[] = {{"viridis", {0x44, 0x01, 0x54}, {0xfd, 0xe7, 0x25}},
                        {"inferno", {0x00, 0x00, 0x04}, {0xfc, 0xff, 0xa4}},
                        {"plasma", {0x0d, 0x08, 0x87}, {0xf0, 0xf9, 0x21}},
                        {"cividis", {0x00, 0x22, 0x4e}, {0xfe, 0xe8, 0x38}},
                        {"cool-to-warm", {59, 76, 192}, {180, 4, 38}},
                        {"grayscale", {0, 0, 0}, {255, 255, 255}}};
    for (const End& e : ends) {
        const auto tf = ExpandColorMap(e.name, -2.0, 6.0);
        ASSERT_EQ(tf.size(), 33u) << e.name;
        EXPECT_EQ(tf.front().scalar, -2.0);
        EXPECT_EQ(tf.back().scalar, 6.0);
        EXPECT_DOUBLE_EQ(tf[16].scalar, 2.0);
        for (std::size_t k = 1; k < tf.size(); ++k) EXPECT_GT(tf[k].scalar, tf[k - 1].scalar);
        for (int c = 0; c < 3; ++c) {
            EXPECT_NEAR(LinearToSrgbValue(tf.front().rgb[c]) * 255, e.first[c], 1.0) << e.name;
            EXPECT_NEAR(LinearToSrgbValue(tf.back().rgb[c]) * 255, e.last[c], 1.0) << e.name;
        }
    }
    // Moreland's cool-to-warm passes through a light grey (221, 221, 221) at the middle;
    // grayscale is mid-grey in sRGB (linear 0.214) there.
    const auto cw = ExpandColorMap("cool-to-warm", 0, 1);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(LinearToSrgbValue(cw[16].rgb[c]) * 255, 221, 2.0);
    const auto gray = ExpandColorMap("grayscale", 0, 1);
    EXPECT_NEAR(gray[16].rgb[0], 0.2140, 2e-3);
}

// Inside the maps: the quarter, half and three-quarter points of the matplotlib tables
// (their published five-colour palettes, e.g. viridis #440154 #3b528b #21918c #5ec962
// #fde725), within 2 of 255 (the tables' own rounding differs by 1 between copies).
TEST(ColorMapTest, ExpandedMapsMatchTheirPublishedQuarterPoints) {
    struct Points {
        const char* name;
        int rgb[3][3];  // at 0.25, 0.5, 0.75
    };
    const Points maps[] = {
        {"viridis", {{0x3b, 0x52, 0x8b}, {0x21, 0x91, 0x8c}, {0x5e, 0xc9, 0x62}}},
        {"inferno", {{0x57, 0x10, 0x6e}, {0xbc, 0x37, 0x54}, {0xf9, 0x8e, 0x09}}},
        {"plasma", {{0x7e, 0x03, 0xa8}, {0xcc, 0x47, 0x78}, {0xf8, 0x95, 0x40}}}};
    for (const Points& m : maps) {
        const auto tf = ExpandColorMap(m.name, 0.0, 1.0);
        ASSERT_EQ(tf.size(), 33u);
        for (int q = 0; q < 3; ++q) {
            const auto& point = tf[8 * (q + 1)];  // samples at k / 32
            EXPECT_DOUBLE_EQ(point.scalar, 0.25 * (q + 1));
            for (int c = 0; c < 3; ++c)
                EXPECT_NEAR(LinearToSrgbValue(point.rgb[c]) * 255, m.rgb[q][c], 2.0)
                    << m.name << " at " << 0.25 * (q + 1) << " channel " << c;
        }
    }
}

TEST(ColorMapTest, ParsedExplicitOrResolvedFromTheData) {
    const std::string volume =
        std::string(kMinimal) + "volume: {color_field: u, extinction_tf: [[0, 1]], ";
    const Scene fixed =
        ParseScene(volume + "color_tf: {map: plasma, range: [-1, 3]}}\n", "t.yaml");
    ASSERT_TRUE(fixed.volume);
    ASSERT_EQ(fixed.volume->colorTf.size(), 33u);
    EXPECT_EQ(fixed.volume->colorTf.front().scalar, -1.0);
    EXPECT_EQ(fixed.volume->colorTf.back().scalar, 3.0);
    Scene automatic = ParseScene(volume + "color_tf: {map: viridis}}\n", "t.yaml");
    ASSERT_TRUE(automatic.volume->colorMap);
    EXPECT_TRUE(automatic.volume->colorTf.empty());  // the data's range is not known yet
    ResolveColorMaps(automatic, [](const std::string& f) {
        EXPECT_EQ(f, "u");
        return std::optional<std::array<double, 2>>(std::array<double, 2>{-1.6, 1.04});
    });
    EXPECT_EQ(automatic.volume->colorTf.front().scalar, -1.6);
    EXPECT_EQ(automatic.volume->colorTf.back().scalar, 1.04);
    // A constant field gets a unit-wide range around its value.
    Scene constant = ParseScene(volume + "color_tf: {map: viridis, range: auto}}\n", "t.yaml");
    ResolveColorMaps(constant, [](const std::string&) {
        return std::optional<std::array<double, 2>>(std::array<double, 2>{4.0, 4.0});
    });
    EXPECT_EQ(constant.volume->colorTf.front().scalar, 2.0);
    EXPECT_EQ(constant.volume->colorTf.back().scalar, 6.0);
    // A volume with only its field: viridis over the field and an extinction ramp from 0
    // to 10 / (the data's diagonal).
    Scene bare = ParseScene(std::string(kMinimal) + "volume: {color_field: u}\n", "t.yaml");
    ASSERT_TRUE(bare.volume);
    EXPECT_TRUE(bare.volume->defaultExtinction);
    ResolveColorMaps(
        bare,
        [](const std::string&) {
            return std::optional<std::array<double, 2>>(std::array<double, 2>{-1.0, 3.0});
        },
        8.0);
    ASSERT_EQ(bare.volume->extinctionTf.size(), 2u);
    EXPECT_EQ(bare.volume->extinctionTf[0].scalar, -1.0);
    EXPECT_EQ(bare.volume->extinctionTf[0].extinction, 0.0);
    EXPECT_EQ(bare.volume->extinctionTf[1].scalar, 3.0);
    EXPECT_EQ(bare.volume->extinctionTf[1].extinction, 1.25);
    EXPECT_EQ(bare.volume->colorTf.size(), 33u);
    EXPECT_EQ(bare.volume->colorTf.front().rgb, ExpandColorMap("viridis", -1, 3).front().rgb);
    // Slices too.
    const Scene slice = ParseScene(std::string(kMinimal) +
                                       "slices: [{point: [0, 0, 0], normal: [0, 0, 1], "
                                       "color_tf: {map: grayscale, range: [0, 1]}}]\n",
                                   "t.yaml");
    EXPECT_EQ(slice.slices[0].colorTf.size(), 33u);
    // Errors name the key.
    const std::string misspelt = ErrorOf(volume + "color_tf: {map: virdis}}\n");
    EXPECT_TRUE(Contains(misspelt, "volume.color_tf.map")) << misspelt;
    EXPECT_TRUE(Contains(misspelt, "viridis")) << misspelt;
    EXPECT_TRUE(Contains(ErrorOf(volume + "color_tf: {map: viridis, range: [2, 1]}}\n"),
                         "volume.color_tf.range"));
    EXPECT_TRUE(Contains(ErrorOf(volume + "color_tf: {map: viridis, rnage: auto}}\n"),
                         "volume.color_tf.rnage"));
    EXPECT_TRUE(
        Contains(ErrorOf(volume + "color_tf: {range: auto}}\n"), "volume.color_tf.map"));
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// docs/scene.md documents every key the parser accepts, and nothing else: each key path
// of the schema appears as a table row "| `path` |", and every such row is a key path.
// ---------------------------------------------------------------------------------------
// Time steps and frames
// ---------------------------------------------------------------------------------------

const char* kSeries = "data: {mesh: sol.pvd}\n";

TEST(SceneTimeTest, IndexValueAndDefault) {
    Scene s = ParseScene(kSeries, "t.yaml", {}, "/base");
    EXPECT_EQ(s.data.mesh, "/base/sol.pvd");
    EXPECT_FALSE(s.data.time.has_value());
    EXPECT_FALSE(s.frames.has_value());
    auto time = [](const std::vector<std::string>& sets) {
        const Scene scene = ParseScene(kSeries, "t.yaml", sets, "/base");
        EXPECT_TRUE(scene.data.time.has_value());
        return scene.data.time.value_or(SceneData::Time{});
    };
    SceneData::Time t = time({"data.time=2"});
    EXPECT_FALSE(t.byValue);
    EXPECT_EQ(t.index, 2);
    t = time({"data.time={index: 0}"});
    EXPECT_FALSE(t.byValue);
    EXPECT_EQ(t.index, 0);
    // A number with a fraction or exponent is a time; {value: 2} the time 2.
    t = time({"data.time=0.3"});
    EXPECT_TRUE(t.byValue);
    EXPECT_EQ(t.value, 0.3);
    t = time({"data.time=2.0"});
    EXPECT_TRUE(t.byValue);
    EXPECT_EQ(t.value, 2.0);
    t = time({"data.time=1e-3"});
    EXPECT_TRUE(t.byValue);
    EXPECT_EQ(t.value, 1e-3);
    t = time({"data.time={value: 2}"});
    EXPECT_TRUE(t.byValue);
    EXPECT_EQ(t.value, 2.0);
    // The extension decides, in any case.
    EXPECT_NO_THROW(ParseScene("data: {mesh: A.PVD, time: 1}\n", "t.yaml", {}, "/base"));
}

TEST(SceneTimeTest, BadTimesNameTheKey) {
    std::string e = ErrorOf("data: {mesh: m.vtu, time: 1}\n");
    EXPECT_TRUE(Contains(e, "data.time")) << e;
    EXPECT_TRUE(Contains(e, "is not a .pvd collection")) << e;
    e = ErrorOf("data: {mesh: builtin:ball-p2}\n", {"data.time=0"});
    EXPECT_TRUE(Contains(e, "is not a .pvd collection")) << e;
    e = ErrorOf(kSeries, {"data.time=-2"});
    EXPECT_TRUE(Contains(e, "data.time")) << e;
    EXPECT_TRUE(Contains(e, "must be >= 0")) << e;
    for (const char* bad : {"data.time=later", "data.time=[1, 2]", "data.time={step: 1}",
                            "data.time={value: 1, index: 1}", "data.time=.nan"}) {
        e = ErrorOf(kSeries, {bad});
        EXPECT_TRUE(Contains(e, "data.time")) << bad << ": " << e;
    }
    e = ErrorOf(kSeries, {"data.time={value: x}"});
    EXPECT_TRUE(Contains(e, "data.time.value")) << e;
    e = ErrorOf(kSeries, {"data.time=null", "data.time.value=1"});
    EXPECT_NE(e, "NO ERROR");
}

TEST(SceneFramesTest, CameraPathInterpolatesBothEnds) {
    const Scene s = ParseScene("data: {mesh: builtin:ball-p2}\n"
                               "frames: {count: 4, azimuth: [0, 90], elevation: [-30, 30], "
                               "zoom: [1, 2.5]}\n",
                               "f.yaml", {}, "/base");
    ASSERT_TRUE(s.frames.has_value());
    EXPECT_EQ(s.frames->count, 4);
    const auto frames = FrameOverrides(s, 0);
    ASSERT_EQ(frames.size(), 4u);
    EXPECT_EQ(frames[0], (std::vector<std::string>{"camera.azimuth=0", "camera.elevation=-30",
                                                   "camera.zoom=1"}));
    EXPECT_EQ(frames[1], (std::vector<std::string>{"camera.azimuth=30", "camera.elevation=-10",
                                                   "camera.zoom=1.5"}));
    EXPECT_EQ(frames[3], (std::vector<std::string>{"camera.azimuth=90", "camera.elevation=30",
                                                   "camera.zoom=2.5"}));
    // One frame: the first value; count alone repeats the scene.
    Scene one = ParseScene("data: {mesh: builtin:ball-p2}\nframes: {count: 1, azimuth: [10, "
                           "20]}\n", "f.yaml", {}, "/base");
    EXPECT_EQ(FrameOverrides(one, 0),
              (std::vector<std::vector<std::string>>{{"camera.azimuth=10"}}));
    one = ParseScene("data: {mesh: builtin:ball-p2}\n", "f.yaml", {"frames.count=3"}, "/base");
    EXPECT_EQ(FrameOverrides(one, 0), (std::vector<std::vector<std::string>>(3)));
    // Every frame's items parse as --set items of the scene.
    for (const auto& items : frames)
        EXPECT_NO_THROW(ParseScene("data: {mesh: builtin:ball-p2}\n", "f.yaml", items, "/b"));
}

TEST(SceneFramesTest, TimeStepsAllOrARangeWithTheCameraAlong) {
    Scene s = ParseScene(kSeries, "f.yaml", {"frames.time=all"}, "/base");
    EXPECT_TRUE(s.frames->timeAll);
    EXPECT_EQ(FrameOverrides(s, 3), (std::vector<std::vector<std::string>>{
                                        {"data.time=0"}, {"data.time=1"}, {"data.time=2"}}));
    s = ParseScene(kSeries, "f.yaml", {"frames={time: [1, 2], azimuth: [0, 45]}"}, "/base");
    EXPECT_EQ(FrameOverrides(s, 3),
              (std::vector<std::vector<std::string>>{{"camera.azimuth=0", "data.time=1"},
                                                     {"camera.azimuth=45", "data.time=2"}}));
    // A range past the last step, or a count that disagrees with the steps.
    try {
        FrameOverrides(s, 2);
        ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
        EXPECT_EQ(e.where(), "frames.time");
        EXPECT_TRUE(Contains(e.what(), "step 2 is past the last step")) << e.what();
    }
    s = ParseScene(kSeries, "f.yaml", {"frames={time: all, count: 2}"}, "/base");
    EXPECT_THROW(FrameOverrides(s, 3), InputError);
    EXPECT_EQ(FrameOverrides(s, 2).size(), 2u);
}

TEST(SceneFramesTest, ListItemsBecomeOverrides) {
    const Scene s = ParseScene(kSeries, "f.yaml",
                               {"frames.list=[{camera.azimuth: 10, data.time: 2}, {}, "
                                "{isosurfaces.0.color: [1, 0, 0]}, {'data.time': {value: "
                                "0.5}}]"},
                               "/base");
    const auto frames = FrameOverrides(s, 0);
    ASSERT_EQ(frames.size(), 4u);
    EXPECT_EQ(frames[0], (std::vector<std::string>{"camera.azimuth=10", "data.time=2"}));
    EXPECT_TRUE(frames[1].empty());
    EXPECT_EQ(frames[2], (std::vector<std::string>{"isosurfaces.0.color=[1, 0, 0]"}));
    EXPECT_EQ(frames[3], (std::vector<std::string>{"data.time={value: 0.5}"}));
    const Scene f3 = ParseScene(kSeries, "f.yaml", frames[3], "/base");
    EXPECT_TRUE(f3.data.time->byValue);
    EXPECT_EQ(f3.data.time->value, 0.5);
}

TEST(SceneFramesTest, BadFramesNameTheKey) {
    const std::string mesh = "data: {mesh: builtin:ball-p2}\n";
    struct Case {
        std::string yaml;
        std::vector<std::string> sets;
        std::string key, fragment;
    };
    const Case cases[] = {
        {mesh + "frames:\n", {}, "frames", "give count"},
        {mesh + "frames: {azimuth: [0, 90]}\n", {}, "frames.count", "required"},
        {mesh + "frames: {count: 0}\n", {}, "frames.count", "[1, 1000000]"},
        {mesh + "frames: {count: 3, azimuth: 90}\n", {}, "frames.azimuth", "[first, last]"},
        {mesh + "frames: {count: 3, elevation: [0, 90]}\n", {}, "frames.elevation.1", "(-90, 90)"},
        {mesh + "frames: {count: 3, zoom: [0, 2]}\n", {}, "frames.zoom.0", "(0,"},
        {mesh + "camera: {position: [3, 3, 3]}\nframes: {count: 3, azimuth: [0, 9]}\n", {},
         "frames.azimuth", "camera.position"},
        {mesh + "frames: {time: all}\n", {}, "frames.time", "not a .pvd collection"},
        {kSeries + std::string("frames: {time: [2, 1]}\n"), {}, "frames.time", "first <= last"},
        {kSeries + std::string("frames: {time: some}\n"), {}, "frames.time", "all or"},
        {mesh + "frames: {count: 2, list: [{}]}\n", {}, "frames.count", "frames.list"},
        {mesh + "frames: {list: []}\n", {}, "frames.list", "non-empty"},
        {mesh + "frames: {list: [5]}\n", {}, "frames.list.0", "mapping"},
        {mesh + "frames: {list: [{}, {camera.fovy: 3}]}\n", {}, "frames.list.1.camera.fovy",
         "did you mean 'fov_y'"},
        {mesh + "frames: {list: [{output.png: a.png}]}\n", {}, "frames.list.0.output.png",
         "cannot change"},
        {mesh + "frames: {list: [{data.mesh: b.vtu}]}\n", {}, "frames.list.0.data.mesh",
         "cannot change"},
        {mesh + "frames: {list: [{frames.count: 2}]}\n", {}, "frames.list.0.frames.count",
         "cannot change"},
        {mesh + "frames: {list: [{isosurfaces.x.value: 2}]}\n", {},
         "frames.list.0.isosurfaces.x.value", "not a list index"},
        {mesh, {"frames.frobnicate=1"}, "frames.frobnicate", "valid keys here"},
    };
    for (const Case& c : cases) {
        const std::string e = ErrorOf(c.yaml, c.sets);
        EXPECT_TRUE(Contains(e, c.key)) << c.yaml << "\n -> " << e;
        EXPECT_TRUE(Contains(e, c.fragment)) << c.yaml << "\n -> " << e;
    }
}

TEST(SceneDocsTest, EveryKeyIsDocumented) {
    std::ifstream in(std::string(HPRAY_SOURCE_DIR) + "/docs/scene.md");
    ASSERT_TRUE(in) << "docs/scene.md is missing";
    std::set<std::string> documented;
    for (std::string line; std::getline(in, line);) {
        if (line.rfind("| `", 0) != 0) continue;
        const std::size_t end = line.find('`', 3);
        documented.insert(line.substr(3, end - 3));
    }
    std::set<std::string> schema;
    for (const std::string& path : SceneKeyPaths()) schema.insert(path);
    for (const std::string& path : schema)
        EXPECT_TRUE(documented.count(path)) << path << " is not in docs/scene.md";
    for (const std::string& path : documented)
        EXPECT_TRUE(schema.count(path)) << path << " in docs/scene.md is not a scene key";
}

}  // namespace
}  // namespace hpray

// ---------------------------------------------------------------------------------------
// Annotations: outline and legend
// ---------------------------------------------------------------------------------------

namespace hpray {
namespace {

TEST(AnnotationKeysTest, OutlineAndLegendParse) {
    const std::string m = kMinimal;
    const Scene none = ParseScene(m, "t.yaml");
    EXPECT_FALSE(none.outline.enabled);
    EXPECT_FALSE(none.legend);
    const Scene on = ParseScene(m + "outline: true\nlegend: true\n", "t.yaml");
    EXPECT_TRUE(on.outline.enabled);
    EXPECT_FALSE(on.outline.color.has_value());
    EXPECT_EQ(on.outline.width, 1.5);
    EXPECT_TRUE(on.legend);
    EXPECT_FALSE(ParseScene(m + "outline: false\n", "t.yaml").outline.enabled);
    const Scene styled =
        ParseScene(m + "outline: {color: [1, 0, 0.5], width: 3}\n", "t.yaml");
    EXPECT_TRUE(styled.outline.enabled);
    EXPECT_EQ(*styled.outline.color, (std::array<double, 3>{1, 0, 0.5}));
    EXPECT_EQ(styled.outline.width, 3.0);
    EXPECT_TRUE(ParseScene(m + "outline: {}\n", "t.yaml").outline.enabled);
    // --set: a colour or width asks for an outline, even over `outline: true` or `false`.
    for (const char* given : {"", "outline: true\n", "outline: false\n"}) {
        const Scene set = ParseScene(m + given, "t.yaml", {"outline.width=2.5"});
        EXPECT_TRUE(set.outline.enabled) << given;
        EXPECT_EQ(set.outline.width, 2.5) << given;
    }
    EXPECT_TRUE(ParseScene(m, "t.yaml", {"outline=true", "legend=true"}).legend);
    EXPECT_FALSE(ParseScene(m + "outline: true\n", "t.yaml", {"outline=null"}).outline.enabled);
}

TEST(AnnotationKeysTest, BadValuesNameTheKey) {
    const std::string m = kMinimal;
    const std::pair<std::string, std::string> cases[] = {
        {"outline: 2\n", "outline"},
        {"outline: yes please\n", "outline"},
        {"outline:\n", "outline"},
        {"outline: [1, 2]\n", "outline"},
        {"outline: {width: 0}\n", "outline.width"},
        {"outline: {width: 17}\n", "outline.width"},
        {"outline: {color: [2, 0, 0]}\n", "outline.color"},
        {"outline: {colour: [1, 0, 0]}\n", "outline.colour"},
        {"legend: yes\n", "legend"},
        {"legend: {bars: 2}\n", "legend"},
        {"legends: true\n", "legends"},
    };
    for (const auto& [yaml, key] : cases) {
        const std::string error = ErrorOf(m + yaml);
        EXPECT_TRUE(Contains(error, key)) << yaml << " -> " << error;
        EXPECT_FALSE(Contains(error, "NO ERROR")) << yaml;
    }
    EXPECT_TRUE(Contains(ErrorOf(m + "outline: {colour: [1, 0, 0]}\n"), "did you mean 'color'"));
    EXPECT_TRUE(Contains(ErrorOf(m + "legends: true\n"), "did you mean 'legend'"));
    EXPECT_TRUE(Contains(ErrorOf(m, {"outline.widht=2"}), "outline.widht"));
}

}  // namespace
}  // namespace hpray
