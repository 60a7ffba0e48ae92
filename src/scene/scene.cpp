// Scene files: YAML parsing with yaml-cpp, --set overrides, schema and range validation.
#include "scene/scene.h"

#include "scene/colormaps.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "util/error.h"
#include "util/text.h"

namespace hpray {

namespace {

namespace fs = std::filesystem;
using Vec3 = std::array<double, 3>;

// ---------------------------------------------------------------------------------------
// Schema: the key tree every scene file is checked against.
// ---------------------------------------------------------------------------------------

/// A node of the key schema: a mapping with known keys, a list of one item schema, or a
/// leaf value (a scalar or a fixed-shape sequence such as a colour).
struct SchemaNode {
    enum class Kind { Map, List, Leaf };
    std::string name;
    Kind kind = Kind::Leaf;
    std::vector<SchemaNode> children;  // Map: the keys; List: children[0] is the item

    const SchemaNode* Find(const std::string& key) const {
        for (const SchemaNode& child : children)
            if (child.name == key) return &child;
        return nullptr;
    }
    std::vector<std::string> KeyNames() const {
        std::vector<std::string> names;
        for (const SchemaNode& child : children) names.push_back(child.name);
        return names;
    }
};

SchemaNode Leaf(const std::string& name) { return {name, SchemaNode::Kind::Leaf, {}}; }

SchemaNode MapOf(const std::string& name, const std::vector<std::string>& leaves) {
    SchemaNode node{name, SchemaNode::Kind::Map, {}};
    for (const std::string& leaf : leaves) node.children.push_back(Leaf(leaf));
    return node;
}

SchemaNode ListOf(const std::string& name, SchemaNode item) {
    return {name, SchemaNode::Kind::List, {std::move(item)}};
}

const SchemaNode& Schema() {
    static const SchemaNode root = [] {
        SchemaNode r{"", SchemaNode::Kind::Map, {}};
        r.children = {
            MapOf("data", {"mesh", "time"}),
            MapOf("camera", {"position", "look_at", "up", "fov_y", "ortho_height",
                             "width", "height", "view", "zoom", "azimuth", "elevation"}),
            ListOf("isosurfaces", MapOf("#", {"field", "value", "color", "opacity",
                                              "color_field", "color_tf"})),
            ListOf("slices",
                   MapOf("#", {"point", "normal", "field", "color_tf", "opacity"})),
            MapOf("volume", {"color_field", "extinction_field", "glow", "color_tf",
                             "extinction_tf"}),
            MapOf("lighting", {"ambient", "diffuse", "specular", "shininess"}),
            Leaf("background"),
            MapOf("accuracy",
                  {"mapping_tolerance", "projection_order", "projection_tolerance",
                   "root_tolerance", "volume_tolerance", "polish", "target_residual"}),
            MapOf("clip", {"near", "far", "box"}),
            MapOf("output", {"exr", "png", "stats", "hits", "rgba", "errors"}),
            MapOf("outline", {"color", "width"}),
            Leaf("legend"),
            Leaf("threads"),
            Leaf("distribute"),
            [] {
                SchemaNode frames =
                    MapOf("frames", {"count", "azimuth", "elevation", "zoom", "time"});
                frames.children.push_back(ListOf("list", Leaf("#")));
                return frames;
            }(),
        };
        return r;
    }();
    return root;
}

void CollectKeyPaths(const SchemaNode& node, const std::string& prefix,
                     std::vector<std::string>& out) {
    for (const SchemaNode& child : node.children) {
        const std::string path = prefix.empty() ? child.name : prefix + "." + child.name;
        out.push_back(path);
        CollectKeyPaths(child, path, out);
    }
}

// ---------------------------------------------------------------------------------------
// Suggestions for misspelt keys.
// ---------------------------------------------------------------------------------------

bool IsAbbreviation(const std::string& key, const std::string& candidate) {
    return key.size() >= 3 && key.size() < candidate.size() &&
           EditDistance(key, candidate.substr(0, key.size())) == 0;
}

/// "did you mean 'x'?" for the nearest candidate (by edit distance, an abbreviation
/// counting as distance 1) if it is plausibly a misspelling, otherwise the valid keys.
std::string Suggestion(const std::string& key,
                       const std::vector<std::string>& candidates) {
    std::string best;
    std::size_t bestDistance = std::string::npos;
    for (const std::string& candidate : candidates) {
        const std::size_t d =
            IsAbbreviation(key, candidate) ? 1 : EditDistance(key, candidate);
        if (d < bestDistance) {
            bestDistance = d;
            best = candidate;
        }
    }
    const std::size_t allowed = std::max<std::size_t>(2, (key.size() + 2) / 3);
    if (!best.empty() && bestDistance <= allowed) return "did you mean '" + best + "'?";
    std::string list;
    for (const std::string& candidate : candidates)
        list += (list.empty() ? "" : ", ") + candidate;
    return "valid keys here: " + list;
}

std::string Join(const std::vector<std::string>& parts, std::size_t count) {
    std::string out;
    for (std::size_t k = 0; k < count && k < parts.size(); ++k)
        out += (k == 0 ? "" : ".") + parts[k];
    return out;
}

std::string Describe(const YAML::Node& node) {
    if (!node.IsDefined() || node.IsNull()) return "nothing";
    if (node.IsSequence()) return "a list";
    if (node.IsMap()) return "a mapping";
    return "'" + node.Scalar() + "'";
}

std::string FormatNumber(double v) {
    std::ostringstream os;
    os.precision(17);
    os << v;
    return os.str();
}

bool AllDigits(const std::string& s) {
    return !s.empty() && s.size() < 10 &&
           std::all_of(s.begin(), s.end(),
                       [](unsigned char c) { return std::isdigit(c) != 0; });
}

/// Whether a data path names a .pvd collection (by its extension, as io/mesh_io.h).
bool IsCollection(const std::string& path) {
    if (path.rfind("builtin:", 0) == 0) return false;
    std::string ext = fs::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return ext == ".pvd";
}

// Refuse alias expansions ("billion laughs") and absurd files before walking them.
constexpr std::size_t kMaxNodes = 1'000'000;
constexpr std::uintmax_t kMaxSceneBytes = 16u << 20;

// ---------------------------------------------------------------------------------------
// The parser.
// ---------------------------------------------------------------------------------------

class SceneParser {
  public:
    SceneParser(std::string source, std::string baseDir)
        : source_(std::move(source)), baseDir_(std::move(baseDir)) {}

    void ApplyOverride(YAML::Node root, const std::string& text);
    Scene Build(const YAML::Node& root);

  private:
    // --- errors ---------------------------------------------------------------------
    std::string Where(const std::string& path, const YAML::Node& node) const;
    [[noreturn]] void Fail(const std::string& path, const YAML::Node& node,
                           const std::string& what) const {
        throw InputError(source_, Where(path, node), what);
    }

    // --- generic checks -------------------------------------------------------------
    void CountNodes(const YAML::Node& node, std::size_t& count) const;
    void CheckKeys(const YAML::Node& node, const SchemaNode& schema,
                   const std::string& path) const;
    void ApplyAt(YAML::Node node, const SchemaNode& schema,
                 const std::vector<std::string>& segments, std::size_t k,
                 const YAML::Node& value, const std::string& text);

    // --- typed readers --------------------------------------------------------------
    static std::string Child(const std::string& path, const std::string& key) {
        return path.empty() ? key : path + "." + key;
    }
    /// The value of `key` in `map`, or an undefined node if absent. `map` is a mapping
    /// (CheckKeys ran) or null.
    static YAML::Node Get(const YAML::Node& map, const std::string& key) {
        if (!map.IsMap()) return YAML::Node(YAML::NodeType::Undefined);
        for (auto it = map.begin(); it != map.end(); ++it) {
            const YAML::Node keyNode = it->first;
            if (keyNode.Scalar() == key) return it->second;
        }
        return YAML::Node(YAML::NodeType::Undefined);
    }
    static bool Has(const YAML::Node& map, const std::string& key) {
        return Get(map, key).IsDefined();
    }
    void RequireValue(const YAML::Node& node, const std::string& path) const {
        if (!node.IsDefined()) Fail(path, node, "required key is missing");
        if (node.IsNull()) Fail(path, node, "has no value");
    }
    double Number(const YAML::Node& node, const std::string& path,
                  bool allowInfinite = false) const;
    long long Integer(const YAML::Node& node, const std::string& path) const;
    std::string String(const YAML::Node& node, const std::string& path) const;
    std::vector<double> Numbers(const YAML::Node& node, const std::string& path,
                                std::size_t count) const;
    Vec3 Vector(const YAML::Node& node, const std::string& path) const;
    Vec3 Color(const YAML::Node& node, const std::string& path) const;
    double InRange(const YAML::Node& node, const std::string& path, double lo, double hi,
                   bool openLo, bool openHi) const;
    double Positive(const YAML::Node& node, const std::string& path) const;
    double NonNegative(const YAML::Node& node, const std::string& path) const;
    bool Bool(const YAML::Node& node, const std::string& path) const;
    std::string FieldName(const YAML::Node& node, const std::string& path) const;
    std::vector<ColorControlPoint> ColorTf(const YAML::Node& node,
                                           const std::string& path, bool unitRange) const;
    /// `{map: NAME, range: auto | [lo, hi]}`, or nothing for a list of control points.
    std::optional<ColorMapRequest> ColorMap(const YAML::Node& node,
                                            const std::string& path) const;
    std::vector<ExtinctionControlPoint> ExtinctionTf(const YAML::Node& node,
                                                     const std::string& path) const;
    std::string InputPath(const std::string& path) const;
    static std::string OutputPath(const std::string& path);

    // --- sections -------------------------------------------------------------------
    void ReadData(const YAML::Node& root, Scene& scene) const;
    void ReadCamera(const YAML::Node& root, Scene& scene) const;
    void ReadIsosurfaces(const YAML::Node& root, Scene& scene) const;
    void ReadSlices(const YAML::Node& root, Scene& scene) const;
    void ReadVolume(const YAML::Node& root, Scene& scene) const;
    void ReadLighting(const YAML::Node& root, Scene& scene) const;
    void ReadAccuracy(const YAML::Node& root, Scene& scene) const;
    void ReadClip(const YAML::Node& root, Scene& scene) const;
    void ReadOutput(const YAML::Node& root, Scene& scene) const;
    void ReadAnnotations(const YAML::Node& root, Scene& scene) const;
    void ReadExtras(const YAML::Node& root, Scene& scene) const;
    void ReadFrames(const YAML::Node& root, Scene& scene) const;
    /// A key path of a frames.list item: a path of the schema, not one a frame may not
    /// change.
    void CheckFrameKey(const std::string& key, const YAML::Node& keyNode,
                       const std::string& itemPath) const;

    std::string source_;
    std::string baseDir_;
    /// Key paths set by --set (e.g. "isosurfaces.0.value") -> the override text.
    std::map<std::string, std::string> overridden_;
};

std::string SceneParser::Where(const std::string& path, const YAML::Node& node) const {
    // A key set or created by --set has no line in the file: name the override instead.
    std::string probe = path;
    while (true) {
        const auto it = overridden_.find(probe);
        if (it != overridden_.end()) return path + " (--set " + it->second + ")";
        const std::size_t dot = probe.rfind('.');
        if (dot == std::string::npos) break;
        probe.resize(dot);
    }
    const YAML::Mark mark = node.IsDefined() ? node.Mark() : YAML::Mark::null_mark();
    if (mark.is_null()) return path;
    return "line " + std::to_string(mark.line + 1) + (path.empty() ? "" : ", " + path);
}

void SceneParser::CountNodes(const YAML::Node& node, std::size_t& count) const {
    if (++count > kMaxNodes)
        throw InputError(source_, "", "scene has more than a million YAML nodes");
    if (node.IsSequence()) {
        for (const YAML::Node& item : node) CountNodes(item, count);
    } else if (node.IsMap()) {
        for (auto it = node.begin(); it != node.end(); ++it) {
            const YAML::Node key = it->first;
            const YAML::Node value = it->second;
            CountNodes(key, count);
            CountNodes(value, count);
        }
    }
}

void SceneParser::CheckKeys(const YAML::Node& node, const SchemaNode& schema,
                            const std::string& path) const {
    if (node.IsNull()) return;  // an empty section: all defaults
    if (path == "camera" && node.IsScalar() && node.Scalar() == "auto") return;
    if (path == "outline" && node.IsScalar()) return;  // true or false: ReadAnnotations
    if (schema.kind == SchemaNode::Kind::Map) {
        if (!node.IsMap())
            Fail(path, node, "expected a mapping of keys, got " + Describe(node));
        std::vector<std::string> seen;
        for (auto it = node.begin(); it != node.end(); ++it) {
            const YAML::Node keyNode = it->first;
            const YAML::Node valueNode = it->second;
            if (!keyNode.IsScalar())
                Fail(path, keyNode, "keys must be plain names, got " + Describe(keyNode));
            const std::string key = keyNode.Scalar();
            const std::string keyPath = Child(path, key);
            const SchemaNode* child = schema.Find(key);
            if (child == nullptr)
                Fail(keyPath, keyNode,
                     "unknown key '" + key + "'; " + Suggestion(key, schema.KeyNames()));
            if (std::find(seen.begin(), seen.end(), key) != seen.end())
                Fail(keyPath, keyNode, "duplicate key '" + key + "'");
            seen.push_back(key);
            CheckKeys(valueNode, *child, keyPath);
        }
    } else if (schema.kind == SchemaNode::Kind::List) {
        if (!node.IsSequence())
            Fail(path, node, "expected a list, got " + Describe(node));
        for (std::size_t k = 0; k < node.size(); ++k)
            CheckKeys(node[k], schema.children[0], Child(path, std::to_string(k)));
    }
}

void SceneParser::ApplyOverride(YAML::Node root, const std::string& text) {
    const std::string where = "--set " + text;
    const std::size_t eq = text.find('=');
    if (eq == std::string::npos || eq == 0)
        throw InputError(source_, where, "expected key.path=value");
    const std::string keyPath = text.substr(0, eq);
    std::vector<std::string> segments;
    std::size_t start = 0;
    while (true) {
        const std::size_t dot = keyPath.find('.', start);
        segments.push_back(keyPath.substr(start, dot - start));
        if (dot == std::string::npos) break;
        start = dot + 1;
    }
    for (const std::string& segment : segments)
        if (segment.empty())
            throw InputError(source_, where, "empty key in '" + keyPath + "'");

    YAML::Node value;
    try {
        value = YAML::Load(text.substr(eq + 1));
    } catch (const YAML::Exception& e) {
        throw InputError(source_, where, "the value is not valid YAML: " + e.msg);
    }
    ApplyAt(root, Schema(), segments, 0, value, text);
    overridden_[keyPath] = text;
}

void SceneParser::ApplyAt(YAML::Node node, const SchemaNode& schema,
                          const std::vector<std::string>& segments, std::size_t k,
                          const YAML::Node& value, const std::string& text) {
    // `node` is a handle to the tree (yaml-cpp nodes are references); assigning to one of
    // its children edits the document in place.
    const std::string where = "--set " + text;
    const std::string& segment = segments[k];
    const bool last = k + 1 == segments.size();
    const std::string pathSoFar = Join(segments, k + 1);
    const std::string parentPath = Join(segments, k);

    if (schema.kind == SchemaNode::Kind::Map) {
        const SchemaNode* child = schema.Find(segment);
        if (child == nullptr)
            throw InputError(source_, where,
                             "unknown key '" + pathSoFar + "'; " +
                                 Suggestion(segment, schema.KeyNames()));
        if (!node.IsMap() && !node.IsNull())
            throw InputError(
                source_, where,
                "'" + parentPath + "' is " + Describe(node) + ", not a mapping");
        if (last) {
            if (value.IsNull()) {
                if (node.IsMap()) node.remove(segment);
            } else {
                node[segment] = value;
            }
            return;
        }
        // Create a missing (or empty) intermediate section, then descend into it. An
        // outline given as true or false becomes a mapping: setting its colour or width
        // asks for one.
        const YAML::Node existing = Get(node, segment);
        const bool shorthand = pathSoFar == "outline" && existing.IsScalar();
        if (!existing.IsDefined() || existing.IsNull() || shorthand)
            node[segment] = YAML::Node(child->kind == SchemaNode::Kind::List
                                           ? YAML::NodeType::Sequence
                                           : YAML::NodeType::Map);
        ApplyAt(node[segment], *child, segments, k + 1, value, text);
        return;
    }

    // A list (of the schema) or a leaf holding a sequence (a colour, a transfer
    // function): the segment is an index.
    if (!node.IsSequence() && !(schema.kind == SchemaNode::Kind::List && node.IsNull()))
        throw InputError(source_, where,
                         "'" + parentPath + "' " +
                             (schema.kind == SchemaNode::Kind::Leaf
                                  ? "takes a value, not sub-keys"
                                  : "is " + Describe(node) + ", not a list"));
    if (!AllDigits(segment))
        throw InputError(source_, where,
                         "'" + segment + "' is not a list index of '" + parentPath + "'");
    const std::size_t index = std::stoul(segment);
    const std::size_t size = node.IsSequence() ? node.size() : 0;
    const bool canAppend = schema.kind == SchemaNode::Kind::List;
    if (index > size || (index == size && !canAppend))
        throw InputError(source_, where,
                         "index " + segment + " is past the end of '" + parentPath +
                             "' (" + std::to_string(size) + " entries)");
    const SchemaNode& itemSchema =
        schema.kind == SchemaNode::Kind::List ? schema.children[0] : schema;
    if (last) {
        if (value.IsNull()) {
            if (index < size) node.remove(index);
        } else if (index == size) {
            node.push_back(value);
        } else {
            node[index] = value;
        }
        return;
    }
    if (index == size) node.push_back(YAML::Node(YAML::NodeType::Map));
    YAML::Node next = node[index];
    ApplyAt(next, itemSchema, segments, k + 1, value, text);
}

double SceneParser::Number(const YAML::Node& node, const std::string& path,
                           bool allowInfinite) const {
    RequireValue(node, path);
    if (!node.IsScalar()) Fail(path, node, "expected a number, got " + Describe(node));
    double v = 0.0;
    try {
        v = node.as<double>();
    } catch (const YAML::Exception&) {
        Fail(path, node, "expected a number, got " + Describe(node));
    }
    if (std::isnan(v)) Fail(path, node, "NaN is not allowed");
    if (std::isinf(v) && !allowInfinite) Fail(path, node, "must be finite");
    return v;
}

long long SceneParser::Integer(const YAML::Node& node, const std::string& path) const {
    RequireValue(node, path);
    if (!node.IsScalar()) Fail(path, node, "expected an integer, got " + Describe(node));
    try {
        return node.as<long long>();
    } catch (const YAML::Exception&) {
    }
    // 512.0 or 1e3 are integers too; 512.5 and 'abc' are not.
    double v = 0.0;
    try {
        v = node.as<double>();
    } catch (const YAML::Exception&) {
        Fail(path, node, "expected an integer, got " + Describe(node));
    }
    if (!std::isfinite(v) || v != std::floor(v) || std::fabs(v) > 9.0e15)
        Fail(path, node, "expected an integer, got " + Describe(node));
    return static_cast<long long>(v);
}

std::string SceneParser::String(const YAML::Node& node, const std::string& path) const {
    RequireValue(node, path);
    if (!node.IsScalar()) Fail(path, node, "expected a string, got " + Describe(node));
    return node.Scalar();
}

std::vector<double> SceneParser::Numbers(const YAML::Node& node, const std::string& path,
                                         std::size_t count) const {
    RequireValue(node, path);
    if (!node.IsSequence() || node.size() != count)
        Fail(path, node,
             "expected a list of " + std::to_string(count) + " numbers, got " +
                 (node.IsSequence() ? "a list of " + std::to_string(node.size())
                                    : Describe(node)));
    std::vector<double> out(count);
    for (std::size_t k = 0; k < count; ++k)
        out[k] = Number(node[k], Child(path, std::to_string(k)));
    return out;
}

Vec3 SceneParser::Vector(const YAML::Node& node, const std::string& path) const {
    const std::vector<double> v = Numbers(node, path, 3);
    return {v[0], v[1], v[2]};
}

Vec3 SceneParser::Color(const YAML::Node& node, const std::string& path) const {
    const Vec3 c = Vector(node, path);
    for (std::size_t k = 0; k < 3; ++k)
        if (c[k] < 0.0 || c[k] > 1.0)
            Fail(Child(path, std::to_string(k)), node[k],
                 "colour components must be in [0, 1], got " + FormatNumber(c[k]));
    return c;
}

double SceneParser::InRange(const YAML::Node& node, const std::string& path, double lo,
                            double hi, bool openLo, bool openHi) const {
    const double v = Number(node, path);
    const bool ok = (openLo ? v > lo : v >= lo) && (openHi ? v < hi : v <= hi);
    if (!ok)
        Fail(path, node,
             std::string("must be in ") + (openLo ? "(" : "[") + FormatNumber(lo) + ", " +
                 FormatNumber(hi) + (openHi ? ")" : "]") + ", got " + FormatNumber(v));
    return v;
}

double SceneParser::Positive(const YAML::Node& node, const std::string& path) const {
    const double v = Number(node, path);
    if (!(v > 0.0)) Fail(path, node, "must be > 0, got " + FormatNumber(v));
    return v;
}

double SceneParser::NonNegative(const YAML::Node& node, const std::string& path) const {
    const double v = Number(node, path);
    if (!(v >= 0.0)) Fail(path, node, "must be >= 0, got " + FormatNumber(v));
    return v;
}

bool SceneParser::Bool(const YAML::Node& node, const std::string& path) const {
    RequireValue(node, path);
    const std::string v = node.IsScalar() ? node.Scalar() : "";
    if (v == "true") return true;
    if (v == "false") return false;
    Fail(path, node, "expected true or false, got " + Describe(node));
}

std::string SceneParser::FieldName(const YAML::Node& node,
                                   const std::string& path) const {
    const std::string name = String(node, path);
    if (name.empty()) Fail(path, node, "field name is empty");
    return name;
}

std::vector<ColorControlPoint> SceneParser::ColorTf(const YAML::Node& node,
                                                    const std::string& path,
                                                    bool unitRange) const {
    RequireValue(node, path);
    if (!node.IsSequence() || node.size() == 0)
        Fail(path, node,
             "expected a non-empty list of [scalar, r, g, b], got " + Describe(node));
    std::vector<ColorControlPoint> points;
    for (std::size_t k = 0; k < node.size(); ++k) {
        const std::string itemPath = Child(path, std::to_string(k));
        const std::vector<double> v = Numbers(node[k], itemPath, 4);
        ColorControlPoint p;
        p.scalar = v[0];
        for (std::size_t c = 0; c < 3; ++c) {
            p.rgb[c] = v[c + 1];
            const bool bad =
                unitRange ? (p.rgb[c] < 0.0 || p.rgb[c] > 1.0) : p.rgb[c] < 0.0;
            if (bad)
                Fail(itemPath, node[k],
                     std::string(unitRange ? "colour components must be in [0, 1]"
                                           : "glow components must be >= 0") +
                         ", got " + FormatNumber(p.rgb[c]));
        }
        if (!points.empty() && !(p.scalar > points.back().scalar))
            Fail(itemPath, node[k],
                 "control-point scalars must be strictly increasing (" +
                     FormatNumber(p.scalar) + " after " +
                     FormatNumber(points.back().scalar) + ")");
        points.push_back(p);
    }
    return points;
}

std::optional<ColorMapRequest> SceneParser::ColorMap(const YAML::Node& node,
                                                     const std::string& path) const {
    if (!node.IsMap()) return std::nullopt;
    ColorMapRequest r;
    for (auto it = node.begin(); it != node.end(); ++it) {
        const std::string key = it->first.Scalar();
        if (key != "map" && key != "range")
            Fail(Child(path, key), it->first,
                 "unknown key '" + key + "'; a colour map has map and range");
    }
    if (!Has(node, "map")) Fail(Child(path, "map"), node, "required key is missing");
    r.name = String(Get(node, "map"), Child(path, "map"));
    if (!IsColorMap(r.name)) {
        std::string names;
        for (const std::string& n : ColorMapNames()) names += (names.empty() ? "" : ", ") + n;
        Fail(Child(path, "map"), Get(node, "map"),
             "unknown colour map '" + r.name + "'; " + Suggestion(r.name, ColorMapNames()) +
                 " (maps: " + names + ")");
    }
    if (Has(node, "range")) {
        const YAML::Node range = Get(node, "range");
        if (range.IsScalar() && range.Scalar() == "auto") {
            r.autoRange = true;
        } else {
            const std::vector<double> v = Numbers(range, Child(path, "range"), 2);
            if (!(v[0] < v[1]))
                Fail(Child(path, "range"), range,
                     "expected auto or [lo, hi] with lo < hi, got [" + FormatNumber(v[0]) +
                         ", " + FormatNumber(v[1]) + "]");
            r.autoRange = false;
            r.lo = v[0];
            r.hi = v[1];
        }
    }
    return r;
}

std::vector<ExtinctionControlPoint> SceneParser::ExtinctionTf(
    const YAML::Node& node, const std::string& path) const {
    RequireValue(node, path);
    if (!node.IsSequence() || node.size() == 0)
        Fail(path, node,
             "expected a non-empty list of [scalar, extinction], got " + Describe(node));
    std::vector<ExtinctionControlPoint> points;
    for (std::size_t k = 0; k < node.size(); ++k) {
        const std::string itemPath = Child(path, std::to_string(k));
        const std::vector<double> v = Numbers(node[k], itemPath, 2);
        ExtinctionControlPoint p{v[0], v[1]};
        if (p.extinction < 0.0)
            Fail(itemPath, node[k],
                 "extinction must be >= 0, got " + FormatNumber(p.extinction));
        if (!points.empty() && !(p.scalar > points.back().scalar))
            Fail(itemPath, node[k],
                 "control-point scalars must be strictly increasing (" +
                     FormatNumber(p.scalar) + " after " +
                     FormatNumber(points.back().scalar) + ")");
        points.push_back(p);
    }
    return points;
}

std::string SceneParser::InputPath(const std::string& path) const {
    if (path.rfind("builtin:", 0) == 0) return path;
    fs::path p(path);
    if (p.is_relative())
        p = (baseDir_.empty() ? fs::current_path() : fs::path(baseDir_)) / p;
    return fs::absolute(p).lexically_normal().string();
}

std::string SceneParser::OutputPath(const std::string& path) {
    if (path.empty()) return path;
    return fs::absolute(fs::path(path)).lexically_normal().string();
}

// --- sections
// ---------------------------------------------------------------------------

void SceneParser::ReadData(const YAML::Node& root, Scene& scene) const {
    const YAML::Node data = Get(root, "data");
    if (!data.IsDefined())
        Fail("data", root, "required key is missing (data: {mesh: ...})");
    const std::string mesh = String(Get(data, "mesh"), "data.mesh");
    if (mesh.empty()) Fail("data.mesh", Get(data, "mesh"), "is empty");
    if (mesh == "builtin:") Fail("data.mesh", Get(data, "mesh"), "builtin name is empty");
    scene.data.mesh = InputPath(mesh);
    if (!Has(data, "time")) return;
    const YAML::Node n = Get(data, "time");
    const std::string p = "data.time";
    RequireValue(n, p);
    if (!IsCollection(scene.data.mesh))
        Fail(p, n,
             "data.mesh (" + scene.data.mesh + ") is not a .pvd collection: only a "
             "collection has time steps");
    SceneData::Time t;
    const std::string expected =
        "expected a step index (0, 1, ...), a time ({value: 0.25}, or a number with a "
        "fraction: 0.25) or {index: 2}, got ";
    auto index = [&](const YAML::Node& v, const std::string& path) {
        const long long i = Integer(v, path);
        if (i < 0) Fail(path, v, "a step index must be >= 0, got " + std::to_string(i));
        return i;
    };
    if (n.IsMap()) {
        if (n.size() != 1 || !(Has(n, "value") || Has(n, "index")))
            Fail(p, n, expected + Describe(n));
        if (Has(n, "value")) {
            t.byValue = true;
            t.value = Number(Get(n, "value"), p + ".value");
        } else {
            t.index = index(Get(n, "index"), p + ".index");
        }
    } else if (n.IsScalar()) {
        const std::string text = n.Scalar();
        const bool integer =
            !text.empty() &&
            std::all_of(text.begin() + (text[0] == '+' || text[0] == '-' ? 1 : 0), text.end(),
                        [](unsigned char c) { return std::isdigit(c) != 0; }) &&
            text.find_first_of("0123456789") != std::string::npos;
        if (integer) {
            t.index = index(n, p);
        } else {
            bool number = true;
            try {
                (void)n.as<double>();
            } catch (const YAML::Exception&) {
                number = false;
            }
            if (!number) Fail(p, n, expected + Describe(n));
            t.byValue = true;
            t.value = Number(n, p);
        }
    } else {
        Fail(p, n, expected + Describe(n));
    }
    scene.data.time = t;
}

void SceneParser::ReadCamera(const YAML::Node& root, Scene& scene) const {
    const YAML::Node cam = Get(root, "camera");
    SceneCamera& c = scene.camera;
    const std::string p = "camera";
    // No position (or `camera: auto`): fitted to the data's bounds once they are known.
    c.autoFit = !Has(cam, "position");
    if (Has(cam, "position")) c.position = Vector(Get(cam, "position"), p + ".position");
    c.lookAtGiven = Has(cam, "look_at");
    c.upGiven = Has(cam, "up");
    if (Has(cam, "look_at")) c.lookAt = Vector(Get(cam, "look_at"), p + ".look_at");
    if (Has(cam, "up")) c.up = Vector(Get(cam, "up"), p + ".up");
    for (const char* key : {"view", "zoom", "azimuth", "elevation"})
        if (Has(cam, key) && !c.autoFit)
            Fail(p + "." + key, Get(cam, key),
                 std::string(key) + " places an automatic camera; it cannot be combined "
                 "with camera.position (remove one of them)");
    if (Has(cam, "view")) {
        const YAML::Node n = Get(cam, "view");
        c.view = String(n, p + ".view");
        static const std::vector<std::string> views = {"iso", "+x", "-x", "+y",
                                                       "-y",  "+z", "-z"};
        if (std::find(views.begin(), views.end(), c.view) == views.end())
            Fail(p + ".view", n,
                 "must be one of iso, +x, -x, +y, -y, +z, -z (the side the eye is on), got '" +
                     c.view + "'");
    }
    if (Has(cam, "zoom")) c.zoom = Positive(Get(cam, "zoom"), p + ".zoom");
    if (Has(cam, "azimuth"))
        c.azimuthDegrees = Number(Get(cam, "azimuth"), p + ".azimuth");
    if (Has(cam, "elevation"))
        c.elevationDegrees =
            InRange(Get(cam, "elevation"), p + ".elevation", -90.0, 90.0, true, true);
    for (const char* key : {"width", "height"}) {
        if (!Has(cam, key)) continue;
        const YAML::Node n = Get(cam, key);
        const long long v = Integer(n, p + "." + key);
        if (v < 1 || v > 32768)
            Fail(p + "." + key, n, "must be in [1, 32768], got " + std::to_string(v));
        (std::string(key) == "width" ? c.width : c.height) = static_cast<int>(v);
    }
    if (Has(cam, "fov_y") && Has(cam, "ortho_height"))
        Fail(p + ".ortho_height", Get(cam, "ortho_height"),
             "give either fov_y (perspective) or ortho_height (orthographic), not both");
    if (Has(cam, "fov_y"))
        c.fovYDegrees = InRange(Get(cam, "fov_y"), p + ".fov_y", 0.0, 180.0, true, true);
    if (Has(cam, "ortho_height")) {
        c.orthographic = true;
        c.orthoHeight = Positive(Get(cam, "ortho_height"), p + ".ortho_height");
    }

    if (c.autoFit) {
        // FitCamera builds a valid frame; only a given up must be usable.
        const double upLength =
            std::sqrt(c.up[0] * c.up[0] + c.up[1] * c.up[1] + c.up[2] * c.up[2]);
        if (!(upLength > 0.0) || !std::isfinite(upLength))
            Fail(p + ".up", Get(cam, "up"), "up must be a non-zero vector");
        return;
    }
    // Degenerate frames: the basis of camera.h would divide by zero.
    const Vec3 d = {c.lookAt[0] - c.position[0], c.lookAt[1] - c.position[1],
                    c.lookAt[2] - c.position[2]};
    const double dLength = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    const double scale = std::max({std::fabs(c.position[0]), std::fabs(c.position[1]),
                                   std::fabs(c.position[2]), std::fabs(c.lookAt[0]),
                                   std::fabs(c.lookAt[1]), std::fabs(c.lookAt[2])});
    if (!(dLength > 1e-12 * scale) || !std::isfinite(dLength))
        Fail(p + ".look_at", Get(cam, "look_at"),
             "look_at coincides with position: no view direction");
    const double upLength =
        std::sqrt(c.up[0] * c.up[0] + c.up[1] * c.up[1] + c.up[2] * c.up[2]);
    if (!(upLength > 0.0) || !std::isfinite(upLength))
        Fail(p + ".up", Get(cam, "up"), "up must be a non-zero vector");
    const Vec3 f = {d[0] / dLength, d[1] / dLength, d[2] / dLength};
    const Vec3 u = {c.up[0] / upLength, c.up[1] / upLength, c.up[2] / upLength};
    const Vec3 x = {f[1] * u[2] - f[2] * u[1], f[2] * u[0] - f[0] * u[2],
                    f[0] * u[1] - f[1] * u[0]};
    if (std::sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) < 1e-9)
        Fail(p + ".up", Get(cam, "up"),
             "up is parallel to the view direction (look_at - position)");
}

void SceneParser::ReadIsosurfaces(const YAML::Node& root, Scene& scene) const {
    const YAML::Node list = Get(root, "isosurfaces");
    if (!list.IsSequence()) return;
    for (std::size_t k = 0; k < list.size(); ++k) {
        const YAML::Node item = list[k];
        const std::string p = "isosurfaces." + std::to_string(k);
        if (!item.IsMap())
            Fail(p, item, "expected a mapping {field, value, color, opacity}");
        SceneIsosurface iso;
        if (Has(item, "field")) iso.field = FieldName(Get(item, "field"), p + ".field");
        if (!Has(item, "value")) Fail(p + ".value", item, "required key is missing");
        iso.value = Number(Get(item, "value"), p + ".value");
        if (Has(item, "color")) iso.color = Color(Get(item, "color"), p + ".color");
        if (Has(item, "opacity"))
            iso.opacity =
                InRange(Get(item, "opacity"), p + ".opacity", 0, 1, false, false);
        if (Has(item, "color_tf") && !Has(item, "color_field"))
            Fail(p + ".color_tf", Get(item, "color_tf"),
                 "colours by the value of color_field, which is missing");
        if (Has(item, "color_field")) {
            if (Has(item, "color"))
                Fail(p + ".color", Get(item, "color"),
                     "give either color (one colour) or color_field (colour by a field), "
                     "not both");
            iso.colorField = FieldName(Get(item, "color_field"), p + ".color_field");
            if (!Has(item, "color_tf")) {
                iso.colorMap = ColorMapRequest{"viridis", true, 0.0, 1.0};
            } else if ((iso.colorMap = ColorMap(Get(item, "color_tf"), p + ".color_tf"))) {
                if (!iso.colorMap->autoRange)
                    iso.colorTf =
                        ExpandColorMap(iso.colorMap->name, iso.colorMap->lo, iso.colorMap->hi);
            } else {
                iso.colorTf = ColorTf(Get(item, "color_tf"), p + ".color_tf", true);
            }
        }
        scene.isosurfaces.push_back(iso);
    }
}

void SceneParser::ReadSlices(const YAML::Node& root, Scene& scene) const {
    const YAML::Node list = Get(root, "slices");
    if (!list.IsSequence()) return;
    for (std::size_t k = 0; k < list.size(); ++k) {
        const YAML::Node item = list[k];
        const std::string p = "slices." + std::to_string(k);
        if (!item.IsMap())
            Fail(p, item, "expected a mapping {point, normal, field, ...}");
        SceneSlice slice;
        for (const char* key : {"point", "normal", "color_tf"})
            if (!Has(item, key)) Fail(p + "." + key, item, "required key is missing");
        slice.point = Vector(Get(item, "point"), p + ".point");
        slice.normal = Vector(Get(item, "normal"), p + ".normal");
        if (slice.normal[0] == 0.0 && slice.normal[1] == 0.0 && slice.normal[2] == 0.0)
            Fail(p + ".normal", Get(item, "normal"), "normal must be a non-zero vector");
        if (Has(item, "field")) slice.field = FieldName(Get(item, "field"), p + ".field");
        slice.colorMap = ColorMap(Get(item, "color_tf"), p + ".color_tf");
        if (!slice.colorMap)
            slice.colorTf = ColorTf(Get(item, "color_tf"), p + ".color_tf", true);
        else if (!slice.colorMap->autoRange)
            slice.colorTf =
                ExpandColorMap(slice.colorMap->name, slice.colorMap->lo, slice.colorMap->hi);
        if (Has(item, "opacity"))
            slice.opacity =
                InRange(Get(item, "opacity"), p + ".opacity", 0, 1, false, false);
        scene.slices.push_back(slice);
    }
}

void SceneParser::ReadVolume(const YAML::Node& root, Scene& scene) const {
    if (!Has(root, "volume")) return;
    const YAML::Node vol = Get(root, "volume");
    SceneVolume v;
    const std::string p = "volume";
    if (Has(vol, "color_field"))
        v.colorField = FieldName(Get(vol, "color_field"), p + ".color_field");
    v.extinctionField =
        Has(vol, "extinction_field")
            ? FieldName(Get(vol, "extinction_field"), p + ".extinction_field")
            : v.colorField;
    if (Has(vol, "glow")) {
        const std::string glow = String(Get(vol, "glow"), p + ".glow");
        if (glow == "williams-max") {
            v.glow = GlowModel::WilliamsMax;
        } else if (glow == "wilhelms-van-gelder") {
            v.glow = GlowModel::WilhelmsVanGelder;
        } else {
            Fail(p + ".glow", Get(vol, "glow"),
                 "unknown glow model '" + glow +
                     "'; expected williams-max or wilhelms-van-gelder");
        }
    }
    // Without transfer functions: viridis over the field's range and an extinction ramp
    // scaled to the data's size (ResolveColorMaps), a first picture without tuning.
    if (!Has(vol, "color_tf")) {
        v.colorMap = ColorMapRequest{"viridis", true, 0.0, 1.0};
    } else if ((v.colorMap = ColorMap(Get(vol, "color_tf"), p + ".color_tf"))) {
        if (!v.colorMap->autoRange)
            v.colorTf = ExpandColorMap(v.colorMap->name, v.colorMap->lo, v.colorMap->hi);
    } else {
        v.colorTf =
            ColorTf(Get(vol, "color_tf"), p + ".color_tf", v.glow == GlowModel::WilliamsMax);
    }
    if (Has(vol, "extinction_tf"))
        v.extinctionTf = ExtinctionTf(Get(vol, "extinction_tf"), p + ".extinction_tf");
    else
        v.defaultExtinction = true;
    scene.volume = v;
}

void SceneParser::ReadLighting(const YAML::Node& root, Scene& scene) const {
    const YAML::Node light = Get(root, "lighting");
    SceneLighting& l = scene.lighting;
    const std::pair<const char*, double*> keys[] = {{"ambient", &l.ambient},
                                                    {"diffuse", &l.diffuse},
                                                    {"specular", &l.specular},
                                                    {"shininess", &l.shininess}};
    for (const auto& [key, target] : keys)
        if (Has(light, key))
            *target = NonNegative(Get(light, key), std::string("lighting.") + key);
}

void SceneParser::ReadAccuracy(const YAML::Node& root, Scene& scene) const {
    const YAML::Node acc = Get(root, "accuracy");
    SceneAccuracy& a = scene.accuracy;
    const std::pair<const char*, double*> keys[] = {
        {"mapping_tolerance", &a.mappingTolerance},
        {"projection_tolerance", &a.projectionTolerance},
        {"root_tolerance", &a.rootTolerance},
        {"volume_tolerance", &a.volumeTolerance}};
    for (const auto& [key, target] : keys)
        if (Has(acc, key))
            *target = Positive(Get(acc, key), std::string("accuracy.") + key);
    if (Has(acc, "projection_order")) {
        const YAML::Node n = Get(acc, "projection_order");
        const std::string path = "accuracy.projection_order";
        if (n.IsScalar() && n.Scalar() == "auto") {
            a.projectionOrder = 0;
        } else {
            if (!n.IsScalar())
                Fail(path, n, "expected auto or an integer, got " + Describe(n));
            long long order = 0;
            try {
                order = Integer(n, path);
            } catch (const InputError&) {
                Fail(path, n, "expected auto or an integer, got " + Describe(n));
            }
            if (order < 1 || order > 64)
                Fail(path, n, "must be auto or in [1, 64], got " + std::to_string(order));
            a.projectionOrder = static_cast<int>(order);
        }
    }
    if (Has(acc, "target_residual")) {
        const std::string path = "accuracy.target_residual";
        const YAML::Node n = Get(acc, "target_residual");
        a.targetResidual = Positive(n, path);
        if (a.targetResidual > 1e-2)
            Fail(path, n, "must be at most 1e-2 (a fraction of the field's range)");
        // The projection's error budget follows the target unless given explicitly.
        if (!Has(acc, "projection_tolerance"))
            a.projectionTolerance = std::max(a.projectionTolerance, a.targetResidual / 4);
    }
    if (Has(acc, "polish")) a.polish = Bool(Get(acc, "polish"), "accuracy.polish");
}

void SceneParser::ReadClip(const YAML::Node& root, Scene& scene) const {
    const YAML::Node clip = Get(root, "clip");
    SceneClip& c = scene.clip;
    if (Has(clip, "near")) c.near = NonNegative(Get(clip, "near"), "clip.near");
    if (Has(clip, "far")) {
        c.far = Number(Get(clip, "far"), "clip.far", true);
        if (!(c.far > c.near))
            Fail("clip.far", Get(clip, "far"),
                 "must be > clip.near (" + FormatNumber(c.near) + "), got " +
                     FormatNumber(c.far));
    }
    if (Has(clip, "box")) {
        const YAML::Node box = Get(clip, "box");
        RequireValue(box, "clip.box");
        if (!box.IsSequence() || box.size() != 2)
            Fail("clip.box", box,
                 "expected [[x0, y0, z0], [x1, y1, z1]], got " + Describe(box));
        const Vec3 lo = Vector(box[0], "clip.box.0");
        const Vec3 hi = Vector(box[1], "clip.box.1");
        for (std::size_t k = 0; k < 3; ++k)
            if (!(lo[k] < hi[k]))
                Fail("clip.box", box,
                     "the first corner must be below the second on every axis");
        c.box = Box{lo, hi};
    }
}

void SceneParser::ReadOutput(const YAML::Node& root, Scene& scene) const {
    const YAML::Node out = Get(root, "output");
    SceneOutput& o = scene.output;
    const std::pair<const char*, std::string*> keys[] = {{"exr", &o.exr},
                                                         {"png", &o.png},
                                                         {"stats", &o.stats},
                                                         {"hits", &o.hits},
                                                         {"rgba", &o.rgba},
                                                         {"errors", &o.errors}};
    for (const auto& [key, target] : keys) {
        if (!Has(out, key)) continue;
        const std::string path = std::string("output.") + key;
        const std::string value = String(Get(out, key), path);
        if (value.empty()) Fail(path, Get(out, key), "is empty (omit the key instead)");
        *target = OutputPath(value);
    }
}

void SceneParser::ReadAnnotations(const YAML::Node& root, Scene& scene) const {
    if (Has(root, "legend")) scene.legend = Bool(Get(root, "legend"), "legend");
    if (!Has(root, "outline")) return;
    const YAML::Node node = Get(root, "outline");
    SceneOutline& o = scene.outline;
    if (!node.IsMap()) {
        if (!node.IsScalar() || (node.Scalar() != "true" && node.Scalar() != "false"))
            Fail("outline", node,
                 "expected true, false or a mapping {color, width}, got " + Describe(node));
        o.enabled = node.Scalar() == "true";
        return;
    }
    o.enabled = true;
    if (Has(node, "color")) o.color = Color(Get(node, "color"), "outline.color");
    if (Has(node, "width"))
        o.width = InRange(Get(node, "width"), "outline.width", 0.0, 16.0, true, false);
}

void SceneParser::ReadExtras(const YAML::Node& root, Scene& scene) const {
    if (Has(root, "background"))
        scene.background = Color(Get(root, "background"), "background");
    if (Has(root, "threads")) {
        const long long t = Integer(Get(root, "threads"), "threads");
        if (t < 0 || t > 4096)
            Fail("threads", Get(root, "threads"),
                 "must be in [0, 4096] (0 = all hardware threads), got " +
                     std::to_string(t));
        scene.threads = static_cast<int>(t);
    }
    if (Has(root, "distribute")) {
        const std::string d = String(Get(root, "distribute"), "distribute");
        if (d == "auto") {
            scene.distribute = Distribution::Auto;
        } else if (d == "space") {
            scene.distribute = Distribution::Space;
        } else if (d == "image") {
            scene.distribute = Distribution::Image;
        } else {
            Fail("distribute", Get(root, "distribute"),
                 "must be auto, space or image, got '" + d + "'");
        }
    }
}

void SceneParser::CheckFrameKey(const std::string& key, const YAML::Node& keyNode,
                                const std::string& itemPath) const {
    const std::string where = Child(itemPath, key);
    std::vector<std::string> segments;
    for (std::size_t start = 0;;) {
        const std::size_t dot = key.find('.', start);
        segments.push_back(key.substr(start, dot - start));
        if (dot == std::string::npos) break;
        start = dot + 1;
    }
    const SchemaNode* node = &Schema();
    for (std::size_t k = 0; k < segments.size(); ++k) {
        const std::string& segment = segments[k];
        if (segment.empty()) Fail(where, keyNode, "empty key in '" + key + "'");
        if (node->kind == SchemaNode::Kind::Map) {
            const SchemaNode* child = node->Find(segment);
            if (child == nullptr)
                Fail(where, keyNode,
                     "unknown key '" + Join(segments, k + 1) + "'; " +
                         Suggestion(segment, node->KeyNames()));
            node = child;
        } else if (!AllDigits(segment)) {
            Fail(where, keyNode,
                 "'" + segment + "' is not a list index of '" + Join(segments, k) + "'");
        } else if (node->kind == SchemaNode::Kind::List) {
            node = &node->children[0];
        }
    }
    const std::string top = segments[0];
    if (top == "frames" || top == "output" || top == "threads" || top == "distribute" ||
        key == "data" || key == "data.mesh")
        Fail(where, keyNode,
             "a frame cannot change '" + key + "' (frames render the same data.mesh with "
             "the same outputs, numbered, and job settings); give it outside frames");
}

void SceneParser::ReadFrames(const YAML::Node& root, Scene& scene) const {
    if (!Has(root, "frames")) return;
    const YAML::Node fr = Get(root, "frames");
    const std::string p = "frames";
    const std::string what = "give count (with azimuth, elevation or zoom), time, or list";
    if (fr.IsNull()) Fail(p, fr, "is empty: " + what);
    SceneFrames f;
    const bool hasList = Has(fr, "list");
    if (hasList)
        for (const char* key : {"count", "azimuth", "elevation", "zoom", "time"})
            if (Has(fr, key))
                Fail(p + "." + key, Get(fr, key),
                     std::string("frames.list gives each frame's keys; it cannot be combined "
                                 "with frames.") + key + " (put the keys in the list's items)");
    if (Has(fr, "count")) {
        const YAML::Node n = Get(fr, "count");
        const long long c = Integer(n, p + ".count");
        if (c < 1 || c > 1000000)
            Fail(p + ".count", n, "must be in [1, 1000000], got " + std::to_string(c));
        f.count = static_cast<int>(c);
    }
    auto pair = [&](const char* key, double lo, double hi, bool open,
                    std::optional<std::array<double, 2>>& out) {
        if (!Has(fr, key)) return;
        const YAML::Node n = Get(fr, key);
        const std::string path = p + "." + key;
        RequireValue(n, path);
        if (!n.IsSequence() || n.size() != 2)
            Fail(path, n, "expected [first, last] (two numbers), got " + Describe(n));
        std::array<double, 2> v{};
        for (std::size_t k = 0; k < 2; ++k)
            v[k] = std::isinf(lo) ? Number(n[k], Child(path, std::to_string(k)))
                                  : InRange(n[k], Child(path, std::to_string(k)), lo, hi,
                                            open, true);
        out = v;
        if (!scene.camera.autoFit)
            Fail(path, n,
                 std::string("moves the automatic camera (camera.") + key + "); it cannot be "
                 "combined with camera.position (remove one of them)");
    };
    const double inf = std::numeric_limits<double>::infinity();
    pair("azimuth", -inf, inf, true, f.azimuth);
    pair("elevation", -90.0, 90.0, true, f.elevation);
    pair("zoom", 0.0, inf, true, f.zoom);
    if (Has(fr, "time")) {
        const YAML::Node n = Get(fr, "time");
        const std::string path = p + ".time";
        RequireValue(n, path);
        if (n.IsScalar() && n.Scalar() == "all") {
            f.timeAll = true;
        } else if (n.IsSequence() && n.size() == 2) {
            const long long a = Integer(n[0], path + ".0"), b = Integer(n[1], path + ".1");
            if (a < 0 || b < a)
                Fail(path, n,
                     "expected [first, last] step indices with 0 <= first <= last, got [" +
                         std::to_string(a) + ", " + std::to_string(b) + "]");
            f.timeRange = std::array<long long, 2>{a, b};
        } else {
            Fail(path, n, "expected all or [first, last] step indices, got " + Describe(n));
        }
        if (!IsCollection(scene.data.mesh))
            Fail(path, n,
                 "data.mesh (" + scene.data.mesh + ") is not a .pvd collection: only a "
                 "collection has time steps");
    }
    if (hasList) {
        const YAML::Node list = Get(fr, "list");
        const std::string path = p + ".list";
        RequireValue(list, path);
        if (!list.IsSequence() || list.size() == 0)
            Fail(path, list,
                 "expected a non-empty list of frames, each a mapping of keys such as "
                 "{camera.azimuth: 10}, got " + Describe(list));
        for (std::size_t k = 0; k < list.size(); ++k) {
            const YAML::Node item = list[k];
            const std::string itemPath = Child(path, std::to_string(k));
            if (!(item.IsMap() || item.IsNull()))
                Fail(itemPath, item,
                     "expected a mapping of keys such as {camera.azimuth: 10} ({} for the "
                     "scene as it is), got " + Describe(item));
            std::vector<std::string> overrides;
            if (item.IsMap())
                for (auto it = item.begin(); it != item.end(); ++it) {
                    const YAML::Node keyNode = it->first;
                    if (!keyNode.IsScalar())
                        Fail(itemPath, keyNode,
                             "keys must be key paths such as camera.azimuth, got " +
                                 Describe(keyNode));
                    CheckFrameKey(keyNode.Scalar(), keyNode, itemPath);
                    YAML::Emitter out;
                    out << YAML::Flow << it->second;
                    overrides.push_back(keyNode.Scalar() + "=" + out.c_str());
                }
            f.list.push_back(std::move(overrides));
        }
    } else if (f.count == 0 && !f.HasTime()) {
        if (f.azimuth || f.elevation || f.zoom)
            Fail(p + ".count", fr,
                 "required key is missing: the number of frames of the camera path");
        Fail(p, fr, what);
    }
    scene.frames = f;
}

Scene SceneParser::Build(const YAML::Node& root) {
    std::size_t count = 0;
    CountNodes(root, count);
    if (!root.IsDefined() || root.IsNull())
        throw InputError(source_, "",
                         "the scene is empty (expected at least data: {mesh: ...})");
    if (!root.IsMap())
        throw InputError(source_, Where("", root),
                         "expected a mapping of top-level keys, got " + Describe(root));
    CheckKeys(root, Schema(), "");

    Scene scene;
    ReadData(root, scene);
    ReadCamera(root, scene);
    ReadIsosurfaces(root, scene);
    ReadSlices(root, scene);
    ReadVolume(root, scene);
    ReadLighting(root, scene);
    ReadAccuracy(root, scene);
    ReadClip(root, scene);
    ReadOutput(root, scene);
    ReadAnnotations(root, scene);
    ReadExtras(root, scene);
    ReadFrames(root, scene);
    return scene;
}

}  // namespace

std::vector<std::string> Scene::FieldNames() const {
    std::vector<std::string> names;
    auto add = [&](const std::string& name) {
        if (std::find(names.begin(), names.end(), name) == names.end())
            names.push_back(name);
    };
    for (const SceneIsosurface& iso : isosurfaces) {
        add(iso.field);
        if (!iso.colorField.empty()) add(iso.colorField);
    }
    for (const SceneSlice& slice : slices) add(slice.field);
    if (volume) {
        add(volume->colorField);
        add(volume->extinctionField);
    }
    return names;
}

Scene ParseScene(const std::string& yamlText, const std::string& sourceName,
                 const std::vector<std::string>& overrides, const std::string& baseDir) {
    const std::string source = sourceName.empty() ? "scene" : sourceName;
    std::vector<YAML::Node> documents;
    try {
        documents = YAML::LoadAll(yamlText);
    } catch (const YAML::Exception& e) {
        const std::string where =
            e.mark.is_null() ? ""
                             : "line " + std::to_string(e.mark.line + 1) + ", column " +
                                   std::to_string(e.mark.column + 1);
        throw InputError(source, where, "malformed YAML: " + e.msg);
    }
    if (documents.size() > 1)
        throw InputError(
            source, "",
            "expected one YAML document, found " + std::to_string(documents.size()));
    YAML::Node root = documents.empty() ? YAML::Node() : documents[0];

    SceneParser parser(source, baseDir);
    try {
        if (!overrides.empty()) {
            if (!root.IsDefined() || root.IsNull())
                root = YAML::Node(YAML::NodeType::Map);
            if (!root.IsMap())
                throw InputError(source, "", "expected a mapping of top-level keys");
            for (const std::string& text : overrides) parser.ApplyOverride(root, text);
        }
        Scene scene = parser.Build(root);
        scene.sourcePath = sourceName;
        return scene;
    } catch (const YAML::Exception& e) {
        // A shape the checks above did not foresee: still bad input, never a crash.
        const std::string where =
            e.mark.is_null() ? "" : "line " + std::to_string(e.mark.line + 1);
        throw InputError(source, where, "invalid scene: " + e.msg);
    }
}

std::string MergeSceneOverrides(const std::string& yamlText, const std::string& sourceName,
                                const std::vector<std::string>& overrides) {
    ParseScene(yamlText, sourceName, overrides);  // every check, with its messages
    YAML::Node root = YAML::Load(yamlText);
    if (!root.IsDefined() || root.IsNull()) root = YAML::Node(YAML::NodeType::Map);
    SceneParser parser(sourceName, "");
    for (const std::string& text : overrides) parser.ApplyOverride(root, text);
    YAML::Emitter out;
    out << root;
    return out.c_str();
}

std::string ReadSceneText(const std::string& path) {
    std::error_code ec;
    const fs::file_status status = fs::status(path, ec);
    if (ec || !fs::exists(status))
        throw InputError(path, "", "scene file does not exist");
    if (fs::is_directory(status))
        throw InputError(path, "", "is a folder, not a scene file");
    const std::uintmax_t size = fs::file_size(path, ec);
    if (ec) throw InputError(path, "", "cannot read scene file: " + ec.message());
    if (size > kMaxSceneBytes)
        throw InputError(path, "", "scene file is larger than 16 MB");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(path, "", "cannot open scene file");
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

Scene LoadScene(const std::string& path, const std::vector<std::string>& overrides) {
    const std::string text = ReadSceneText(path);
    const std::string baseDir = fs::absolute(fs::path(path)).parent_path().string();
    Scene scene = ParseScene(text, path, overrides, baseDir);
    scene.sourcePath = path;
    return scene;
}

std::vector<std::vector<std::string>> FrameOverrides(const Scene& scene, int timeSteps) {
    if (!scene.frames) return {};
    const SceneFrames& f = *scene.frames;
    if (!f.list.empty()) return f.list;
    const std::string source = scene.sourcePath.empty() ? "scene" : scene.sourcePath;
    std::vector<long long> steps;
    if (f.HasTime()) {
        const std::string count = std::to_string(timeSteps) + " time step" +
                                  (timeSteps == 1 ? "" : "s");
        if (timeSteps <= 0)
            throw InputError(source, "frames.time",
                             "data.mesh (" + scene.data.mesh + ") has no time steps");
        long long first = 0, last = timeSteps - 1;
        if (f.timeRange) {
            first = (*f.timeRange)[0];
            last = (*f.timeRange)[1];
            if (last >= timeSteps)
                throw InputError(source, "frames.time",
                                 "step " + std::to_string(last) + " is past the last step of " +
                                     scene.data.mesh + " (" + count + ": 0 to " +
                                     std::to_string(timeSteps - 1) + ")");
        }
        for (long long k = first; k <= last; ++k) steps.push_back(k);
        if (f.count > 0 && f.count != static_cast<long long>(steps.size()))
            throw InputError(source, "frames.count",
                             "is " + std::to_string(f.count) + " but frames.time selects " +
                                 std::to_string(steps.size()) + " step" +
                                 (steps.size() == 1 ? "" : "s") +
                                 ": a path over time has one frame per step (omit count)");
    }
    const long long n = steps.empty() ? f.count : static_cast<long long>(steps.size());
    std::vector<std::vector<std::string>> frames(static_cast<std::size_t>(n));
    auto at = [n](const std::array<double, 2>& ends, long long k) {
        return n == 1 ? ends[0] : ends[0] + (ends[1] - ends[0]) * double(k) / double(n - 1);
    };
    for (long long k = 0; k < n; ++k) {
        std::vector<std::string>& items = frames[static_cast<std::size_t>(k)];
        if (f.azimuth) items.push_back("camera.azimuth=" + FormatNumber(at(*f.azimuth, k)));
        if (f.elevation)
            items.push_back("camera.elevation=" + FormatNumber(at(*f.elevation, k)));
        if (f.zoom) items.push_back("camera.zoom=" + FormatNumber(at(*f.zoom, k)));
        if (!steps.empty())
            items.push_back("data.time=" + std::to_string(steps[static_cast<std::size_t>(k)]));
    }
    return frames;
}

std::vector<std::string> SceneKeyPaths() {
    std::vector<std::string> out;
    CollectKeyPaths(Schema(), "", out);
    return out;
}

void ResolveColorMaps(
    Scene& scene,
    const std::function<std::optional<std::array<double, 2>>(const std::string&)>& fieldRange,
    double dataSize) {
    auto rangeOf = [&](const std::string& field) {
        std::array<double, 2> r{0.0, 1.0};
        if (const auto known = fieldRange(field)) r = *known;
        if (!(r[1] > r[0])) {
            const double half = 0.5 * std::max(1.0, std::fabs(r[0]));
            r = {r[0] - half, r[0] + half};
        }
        return r;
    };
    auto resolve = [&](const std::optional<ColorMapRequest>& map, const std::string& field,
                       std::vector<ColorControlPoint>& tf) {
        if (!map || !map->autoRange) return;
        const auto r = rangeOf(field);
        tf = ExpandColorMap(map->name, r[0], r[1]);
    };
    if (scene.volume) {
        SceneVolume& v = *scene.volume;
        resolve(v.colorMap, v.colorField, v.colorTf);
        if (v.defaultExtinction) {
            const auto r = rangeOf(v.extinctionField.empty() ? v.colorField : v.extinctionField);
            const double size = dataSize > 0 && std::isfinite(dataSize) ? dataSize : 1.0;
            // 10 / diagonal: rays through typical data meet an optical depth of about 1 to
            // 3 where the field is high, so its colours show and little is opaque.
            v.extinctionTf = {{r[0], 0.0}, {r[1], 10.0 / size}};
        }
    }
    for (SceneSlice& s : scene.slices) resolve(s.colorMap, s.field, s.colorTf);
    for (SceneIsosurface& iso : scene.isosurfaces)
        resolve(iso.colorMap, iso.colorField, iso.colorTf);
}

}  // namespace hpray
