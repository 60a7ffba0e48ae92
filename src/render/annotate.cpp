// The outline and the legend drawn on the PNG's picture (see annotate.h).
#include "render/annotate.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "image/font.h"
#include "render/volume.h"

namespace hpray {

namespace {

using Vec3 = std::array<double, 3>;

Vec3 Lerp(const Vec3& a, const Vec3& b, double s) {
    return {a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]), a[2] + s * (b[2] - a[2])};
}

/// The colour transfer functions a legend shows, with the field each colours.
struct ColoredField {
    std::string field;
    const std::vector<ColorControlPoint>* tf;
    bool glow;          ///< a volume's glow per unit length rather than a colour
    std::string kind;   ///< isosurface, slice or volume
    std::size_t index;  ///< in its list
};

/// The bar's title: the field's name, and where another bar shows the same field, what
/// colours it (with its index where that is not enough: "u (slice 2)").
std::string Title(const std::vector<ColoredField>& all, std::size_t k) {
    int sameField = 0, sameKind = 0;
    for (const ColoredField& c : all) {
        sameField += c.field == all[k].field;
        sameKind += c.field == all[k].field && c.kind == all[k].kind;
    }
    if (sameField == 1) return all[k].field;
    return all[k].field + " (" + all[k].kind +
           (sameKind > 1 ? " " + std::to_string(all[k].index) : "") + ")";
}

std::vector<ColoredField> ColoredFields(const Scene& scene) {
    std::vector<ColoredField> out;
    auto add = [&](const std::string& field, const std::vector<ColorControlPoint>& tf,
                   bool glow, const char* kind, std::size_t index) {
        if (tf.empty()) return;
        // The same map over the same field (two slices, say) gets one bar.
        for (const ColoredField& c : out) {
            if (c.field != field || c.tf->size() != tf.size() || c.glow != glow) continue;
            bool same = true;
            for (std::size_t k = 0; k < tf.size() && same; ++k)
                same = (*c.tf)[k].scalar == tf[k].scalar && (*c.tf)[k].rgb == tf[k].rgb;
            if (same) return;
        }
        out.push_back({field, &tf, glow, kind, index});
    };
    for (std::size_t k = 0; k < scene.isosurfaces.size(); ++k) {
        const SceneIsosurface& iso = scene.isosurfaces[k];
        if (!iso.colorField.empty())
            add(iso.colorField, iso.colorTf, false, "isosurface", k);
    }
    for (std::size_t k = 0; k < scene.slices.size(); ++k)
        add(scene.slices[k].field, scene.slices[k].colorTf, false, "slice", k);
    if (scene.volume)
        add(scene.volume->colorField, scene.volume->colorTf,
            scene.volume->glow == GlowModel::WilhelmsVanGelder, "volume", 0);
    return out;
}

PiecewiseLinearTf ColorFunction(const std::vector<ColorControlPoint>& tf) {
    std::vector<double> scalars, values;
    for (const ColorControlPoint& p : tf) {
        scalars.push_back(p.scalar);
        values.insert(values.end(), p.rgb.begin(), p.rgb.end());
    }
    return PiecewiseLinearTf(std::move(scalars), std::move(values), 3);
}

/// Lays out one bar with its panel's right edge at `right`; the panel's width follows
/// from its labels.
LegendBar LayOutBar(const ColoredField& colored, const std::string& title, int right,
                    int imageHeight, int barHeight, int s) {
    LegendBar bar;
    bar.title = title;
    bar.colorTf = *colored.tf;
    bar.lo = bar.colorTf.front().scalar;
    bar.hi = bar.colorTf.back().scalar;
    if (!(bar.hi > bar.lo)) {
        // One control point: a constant colour, shown over a range around its value.
        const double half = 0.5 * std::max(1.0, std::fabs(bar.lo));
        bar.lo -= half;
        bar.hi += half;
    }
    if (colored.glow)
        bar.colorScale = std::max(1.0, ColorFunction(bar.colorTf).MaxValue());

    const int pad = 4 * s, tickLength = 4 * s, labelGap = 2 * s, titleGap = 6 * s;
    bar.width = 12 * s;
    bar.height = barHeight;
    const std::vector<double> values = NiceTicks(bar.lo, bar.hi);
    const double step = values.size() > 1 ? values[1] - values[0] : bar.hi - bar.lo;
    const double magnitude = std::max(std::fabs(bar.lo), std::fabs(bar.hi));
    int labelsWidth = 0;
    for (double v : values) {
        LegendBar::Tick tick;
        tick.value = v;
        tick.label = TickLabel(v, step, magnitude);
        tick.labelWidth = TextWidth(tick.label, s);
        tick.labelHeight = font::kCapHeight * s;
        labelsWidth = std::max(labelsWidth, tick.labelWidth);
        bar.ticks.push_back(tick);
    }
    const int contentWidth = std::max(TextWidth(bar.title, s),
                                      bar.width + tickLength + labelGap + labelsWidth);
    bar.panelWidth = pad + contentWidth + pad;
    // Labels reach half their height above the top tick and below the bottom one.
    bar.panelHeight = pad + TextHeight(s) + titleGap + barHeight + 4 * s + pad;
    bar.panelX = right - bar.panelWidth;
    bar.panelY = std::max(0, (imageHeight - bar.panelHeight) / 2);
    bar.titleX = bar.panelX + pad;
    bar.titleY = bar.panelY + pad;
    bar.x = bar.panelX + pad + s;  // room for the bar's frame
    bar.y = bar.titleY + TextHeight(s) + titleGap;
    for (LegendBar::Tick& tick : bar.ticks) {
        const double k =
            std::floor((bar.hi - tick.value) / (bar.hi - bar.lo) * barHeight);
        tick.row = bar.y + static_cast<int>(std::clamp(k, 0.0, double(barHeight - 1)));
        tick.labelX = bar.x + bar.width + tickLength + labelGap;
        // The label's capitals centred on the tick's row.
        tick.labelY = tick.row - (tick.labelHeight - s) / 2;
    }
    return bar;
}

}  // namespace

Canvas AnnotatedPicture(const Scene& scene, const Image& image, const Box& dataBounds) {
    Canvas canvas = Canvas::Over(image, scene.background);
    if (scene.outline.enabled) DrawOutline(canvas, image, scene, dataBounds);
    if (scene.legend) DrawLegend(canvas, scene);
    return canvas;
}

Rgb ContrastColor(const Rgb& background) {
    const double luminance =
        0.2126 * background[0] + 0.7152 * background[1] + 0.0722 * background[2];
    return luminance > 0.18 ? Rgb{0, 0, 0} : Rgb{1, 1, 1};
}

Box OutlineBox(const Scene& scene, const Box& dataBounds) {
    if (!scene.clip.box) return dataBounds;
    const Box cut = dataBounds.Intersect(*scene.clip.box);
    return cut.IsEmpty() ? *scene.clip.box : cut;
}

namespace {

/// Whether the edge from corner q along axis `axis` lies behind everything the image
/// shows along the rays that pass it: both faces that meet there face away from the eye
/// (the rays leave the box there). A face's direction to the eye is the same over the
/// whole face: its outward normal n dotted with the ray direction, forward for an
/// orthographic camera and (point - eye) for a perspective one, whose n-component is the
/// face's coordinate less the eye's.
bool BehindTheData(const Camera& camera, const Box& box, int q, int axis) {
    for (int a = 0; a < 3; ++a) {
        if (a == axis) continue;
        const bool high = (q >> a) & 1;
        const double along = camera.Orthographic()
                                 ? camera.Forward()[a]
                                 : (high ? box.hi[a] : box.lo[a]) - camera.Position()[a];
        if (!((high ? along : -along) > 0)) return false;
    }
    return true;
}

}  // namespace

std::vector<ProjectedEdge> ProjectBoxEdges(const Camera& camera, const Box& box) {
    std::vector<ProjectedEdge> edges;
    if (box.IsEmpty()) return edges;
    Vec3 corner[8];
    double farthest = 0;
    for (int q = 0; q < 8; ++q) {
        for (int d = 0; d < 3; ++d) corner[q][d] = (q >> d) & 1 ? box.hi[d] : box.lo[d];
        farthest = std::max(farthest, std::fabs(camera.Depth(corner[q])));
    }
    if (!std::isfinite(farthest)) return edges;
    // Perspective: points nearer than this project too far out to matter (and the eye
    // itself to nowhere). Orthographic rays start on the image plane: depth 0.
    const double near = camera.Orthographic() ? 0.0 : 1e-9 * farthest;
    for (int q = 0; q < 8; ++q)
        for (int d = 0; d < 3; ++d) {
            if ((q >> d) & 1) continue;
            const Vec3& a = corner[q];
            const Vec3& b = corner[q | (1 << d)];
            const double za = camera.Depth(a), zb = camera.Depth(b);
            const bool inA = camera.Orthographic() ? za >= near : za > near;
            const bool inB = camera.Orthographic() ? zb >= near : zb > near;
            if (!inA && !inB) continue;
            // The part at or beyond the near depth.
            const Vec3 cut = inA && inB ? a : Lerp(a, b, (near - za) / (zb - za));
            ProjectedEdge e{
                inA ? a : cut, inB ? b : cut, {}, BehindTheData(camera, box, q, d)};
            if (!camera.Orthographic() &&
                !(camera.Depth(e.p0) > 0 && camera.Depth(e.p1) > 0))
                continue;  // the eye on the box's edge: nothing of it to see
            const auto i0 = camera.ImagePoint(e.p0), i1 = camera.ImagePoint(e.p1);
            e.image = {i0[0], i0[1], i1[0], i1[1]};
            edges.push_back(e);
        }
    return edges;
}

std::array<double, 3> EdgePointAt(const Camera& camera, const ProjectedEdge& edge,
                                  double u) {
    if (camera.Orthographic()) return Lerp(edge.p0, edge.p1, u);
    // Perspective: 1 / depth is linear along the image piece.
    const double z0 = camera.Depth(edge.p0), z1 = camera.Depth(edge.p1);
    const double s = u * z0 / ((1 - u) * z1 + u * z0);
    return Lerp(edge.p0, edge.p1, std::clamp(s, 0.0, 1.0));
}

void DrawOutline(Canvas& canvas, const Image& image, const Scene& scene,
                 const Box& dataBounds) {
    const Camera camera(scene.camera);
    const std::vector<ProjectedEdge> edges =
        ProjectBoxEdges(camera, OutlineBox(scene, dataBounds));
    // The edges behind the data and the others, drawn apart (LineCoverage's index k is
    // the k-th edge of its group).
    std::vector<std::size_t> group[2];
    std::vector<LinePiece> pieces[2];
    for (std::size_t k = 0; k < edges.size(); ++k) {
        group[edges[k].behind].push_back(k);
        pieces[edges[k].behind].push_back(edges[k].image);
    }
    const Rgb color =
        scene.outline.color ? *scene.outline.color : ContrastColor(scene.background);
    std::vector<float> coverage[2];
    for (int behind = 0; behind < 2; ++behind) {
        // Where the box lies outside [clip.near, clip.far], neither are its edges drawn.
        auto inClip = [&](std::size_t k, double u, int, int) {
            const double t =
                camera.RayParameter(EdgePointAt(camera, edges[group[behind][k]], u));
            return t >= scene.clip.near && t <= scene.clip.far ? 1.0 : 0.0;
        };
        coverage[behind] = LineCoverage(canvas.width, canvas.height, pieces[behind],
                                        scene.outline.width, inClip);
    }
    // Behind the data the line replaces the background with its coverage, seen through
    // all that the pixel shows: c + (1 - a) background becomes c + (1 - a) (background +
    // coverage (line - background)).
    const bool hasAlpha = image.a.size() == static_cast<std::size_t>(canvas.width) *
                                                static_cast<std::size_t>(canvas.height);
    for (std::size_t p = 0; p < coverage[1].size(); ++p) {
        if (!(coverage[1][p] > 0)) continue;
        const double seen =
            coverage[1][p] * (hasAlpha ? std::clamp(1 - image.a[p], 0.0, 1.0) : 1.0);
        for (int c = 0; c < 3; ++c)
            canvas.rgb[3 * p + c] += seen * (color[c] - scene.background[c]);
    }
    // In front of the data (or beside it, on the silhouette) over everything.
    DrawCoverage(canvas, coverage[0], color);
}

std::vector<double> NiceTicks(double lo, double hi) {
    const double span = hi - lo;
    const double slack = 1e-9 * span;  // a range end that is a multiple up to rounding
    auto multiples = [&](double step) {
        std::vector<double> ticks;
        const double first = std::ceil((lo - slack) / step);
        const double last = std::floor((hi + slack) / step);
        for (double k = first; k <= last; ++k) ticks.push_back(k * step);
        return ticks;
    };
    // The largest step of 1, 2 or 5 times a power of ten with at least three multiples in
    // [lo, hi]. Going down from 5 to 2 can jump from two to six or seven; then 2.5 has
    // three to five (from any step to half of it at most doubles the count, minus one).
    for (int e = static_cast<int>(std::ceil(std::log10(span))) + 1;; --e) {
        const double unit = std::pow(10.0, e);
        for (const double m : {5.0, 2.0, 1.0}) {
            std::vector<double> ticks = multiples(m * unit);
            if (ticks.size() < 3) continue;
            if (ticks.size() > 5) ticks = multiples(2.5 * unit);
            return ticks;
        }
    }
}

std::string TickLabel(double value, double step, double magnitude) {
    if (std::fabs(value) < 1e-9 * step) return "0";
    // The digits a step needs: one more than its power of ten for 2.5 (or 25, ...).
    const int stepExponent = static_cast<int>(std::floor(std::log10(step) + 1e-9));
    const double mantissa = step / std::pow(10.0, stepExponent);
    const int extra = std::fabs(mantissa - std::round(mantissa)) > 1e-6 ? 1 : 0;
    char text[64];
    if (magnitude >= 1e5 || magnitude < 1e-3) {
        // The value's own power of ten, digits down to the step's, then as short as it
        // goes: "7.50e+05" -> "7.5e5", "1.00e+06" -> "1e6", "2e-05" -> "2e-5".
        const int exponent =
            static_cast<int>(std::floor(std::log10(std::fabs(value)) + 1e-9));
        std::snprintf(text, sizeof text, "%.*e",
                      std::max(0, exponent - stepExponent + extra), value);
        const std::string s = text;
        const std::size_t e = s.find('e');
        std::string mantissa = s.substr(0, e);
        if (mantissa.find('.') != std::string::npos) {
            mantissa.erase(mantissa.find_last_not_of('0') + 1);
            if (mantissa.back() == '.') mantissa.pop_back();
        }
        std::string digits = s.substr(e + 2);
        digits.erase(0, std::min(digits.find_first_not_of('0'), digits.size() - 1));
        return mantissa + "e" + (s[e + 1] == '-' ? "-" : "") + digits;
    }
    std::snprintf(text, sizeof text, "%.*f", std::max(0, extra - stepExponent), value);
    return text;
}

LegendLayout LayOutLegend(const Scene& scene) {
    LegendLayout layout;
    const int W = scene.camera.width, H = scene.camera.height;
    const int s = std::max(1, static_cast<int>(std::lround(std::min(W, H) / 512.0)));
    layout.scale = s;
    const std::vector<ColoredField> colored = ColoredFields(scene);
    // Half the image's height, less where the panel would not fit between the margins.
    const int margin = 8 * s;
    const int chrome = 2 * 4 * s + TextHeight(s) + 6 * s + 4 * s;
    const int barHeight =
        std::min(static_cast<int>(std::lround(0.5 * H)), H - 2 * margin - chrome);
    int right = W - margin;
    for (std::size_t k = 0; k < colored.size(); ++k) {
        if (barHeight < 24 * s) {
            layout.omitted = static_cast<int>(colored.size() - k);
            break;
        }
        LegendBar bar = LayOutBar(colored[k], Title(colored, k), right, H, barHeight, s);
        if (bar.panelX < margin) {
            layout.omitted = static_cast<int>(colored.size() - k);
            break;
        }
        right = bar.panelX - 4 * s;
        layout.bars.push_back(std::move(bar));
    }
    return layout;
}

Rgb LegendColor(const LegendBar& bar, double value) {
    Rgb rgb;
    ColorFunction(bar.colorTf).Eval(value, rgb.data());
    for (double& c : rgb) c = std::clamp(c / bar.colorScale, 0.0, 1.0);
    return rgb;
}

void DrawLegend(Canvas& canvas, const Scene& scene) {
    const LegendLayout layout = LayOutLegend(scene);
    const int s = layout.scale;
    const Rgb ink = ContrastColor(scene.background);
    for (const LegendBar& bar : layout.bars) {
        canvas.FillRect(bar.panelX, bar.panelY, bar.panelWidth, bar.panelHeight,
                        scene.background, 0.85);
        DrawText(canvas, bar.titleX, bar.titleY, bar.title, s, ink);
        for (int k = 0; k < bar.height; ++k) {
            const double value = bar.hi - (k + 0.5) / bar.height * (bar.hi - bar.lo);
            canvas.FillRect(bar.x, bar.y + k, bar.width, 1, LegendColor(bar, value));
        }
        canvas.FrameRect(bar.x, bar.y, bar.width, bar.height, 1, ink);
        for (const LegendBar::Tick& tick : bar.ticks) {
            canvas.FillRect(bar.x + bar.width, tick.row, 4 * s, std::max(1, s / 2), ink);
            DrawText(canvas, tick.labelX, tick.labelY, tick.label, s, ink);
        }
    }
}

}  // namespace hpray
