// What the PNG shows besides the data (docs/scene.md, Annotations): the outline of the
// data's bounding box, drawn where the camera sees it and hidden behind isosurfaces, and
// a colour legend with ticks for each colour transfer function of the scene. Drawn on the
// PNG's picture only (image/canvas.h), on rank 0 once the image is composited: the EXR
// and the arrays stay data.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "geom/box.h"
#include "image/canvas.h"
#include "image/image.h"
#include "scene/camera.h"
#include "scene/scene.h"

namespace hpray {

/// The PNG's picture of `image`: over the scene's background, with the outline and the
/// legend the scene asks for. `dataBounds`: the guaranteed bounds of the data.
Canvas AnnotatedPicture(const Scene& scene, const Image& image, const Box& dataBounds);

// --- outline --------------------------------------------------------------------------

/// Black over a light background (linear luminance above 0.18, mid grey), white over a
/// dark one: the default colour of the outline and the legend's text.
Rgb ContrastColor(const Rgb& background);

/// The box the outline draws: `dataBounds` cut to the scene's clip box (what can be
/// drawn at all), or the clip box itself if they do not meet.
Box OutlineBox(const Scene& scene, const Box& dataBounds);

/// An edge of a box as the camera sees it: its part in front of the camera (for a
/// perspective camera, at a depth of at least 1e-9 of the farthest corner's distance;
/// for an orthographic one, on the rays' side of the image plane) and its image points.
struct ProjectedEdge {
    std::array<double, 3> p0{}, p1{};  ///< world ends of the part
    LinePiece image;                   ///< their image points (Camera::ImagePoint)
    /// Both faces that meet at the edge face away from the eye: the rays that pass it
    /// leave the box there, so all of the box's content they meet lies in front of it.
    /// Otherwise they enter the box there (all of it lies behind) or only graze it.
    bool behind = false;
};
/// The parts of the twelve edges of `box` in front of `camera` (edges wholly behind it
/// are left out).
std::vector<ProjectedEdge> ProjectBoxEdges(const Camera& camera, const Box& box);
/// The world point of `edge` seen at parameter u in [0, 1] along its image piece (image
/// points are not spread evenly along a perspective edge: 1 / depth is linear in u).
std::array<double, 3> EdgePointAt(const Camera& camera, const ProjectedEdge& edge,
                                  double u);

/// Draws the outline of OutlineBox into `canvas`: lines scene.outline.width pixels wide
/// (LineCoverage) in scene.outline.color. The data lies inside the box, so an edge lies
/// in front of all that a pixel near it shows, or behind all of it (ProjectedEdge::
/// behind): the first are drawn over the picture, the second under it, in place of the
/// background and seen through 1 - alpha of the image, which hides them behind opaque
/// surfaces and dims them behind translucent ones, volumes and slices alike. Parts
/// outside [clip.near, clip.far] are not drawn.
void DrawOutline(Canvas& canvas, const Image& image, const Scene& scene,
                 const Box& dataBounds);

// --- legend ---------------------------------------------------------------------------

/// Between 3 and 5 round values in [lo, hi] (lo < hi, both finite), ascending, evenly
/// spaced by the largest step of 1, 2 or 5 times a power of ten that gives three or more
/// (2.5 times one where 5 gives two and 2 six or seven).
std::vector<double> NiceTicks(double lo, double hi);
/// A tick value written for the legend: fixed point with as many decimals as `step`
/// needs (0.25: two), or, when the range's largest absolute value `magnitude` is at least
/// 1e5 or below 1e-3, as m.deX with the digits down to the step's and no trailing zeros,
/// '+' or leading zeros in the exponent (7.5e5, 1e6, 2e-5); 0 as "0".
std::string TickLabel(double value, double step, double magnitude);

/// A colour bar of the legend, in pixels of the image.
struct LegendBar {
    /// The field coloured; where two bars show one field, with what it colours: "u
    /// (slice)", "u (volume)", or "u (slice 2)" among slices.
    std::string title;
    std::vector<ColorControlPoint> colorTf;
    /// The colours shown are colorTf's divided by this: 1, or for a volume's glow
    /// (wilhelms-van-gelder) above 1 its largest component, so the bar shows its hues.
    double colorScale = 1;
    double lo = 0, hi = 1;  ///< the range shown: colorTf's first and last control points
    /// The bar: pixels [x, x + width) x [y, y + height). Pixel row y + k shows the value
    /// hi - (k + 1/2) / height * (hi - lo), the same on every column.
    int x = 0, y = 0, width = 0, height = 0;
    struct Tick {
        double value = 0;
        std::string label;
        /// The pixel row of the tick mark: the bar's row nearest the value.
        int row = 0;
        int labelX = 0, labelY = 0, labelWidth = 0, labelHeight = 0;  ///< the label's box
    };
    std::vector<Tick> ticks;
    int titleX = 0, titleY = 0;
    int panelX = 0, panelY = 0, panelWidth = 0, panelHeight = 0;  ///< behind all of it
};

/// The legend's layout for the scene's camera: one bar per distinct (field, colour
/// transfer function) of the isosurfaces coloured by a field, the slices and the volume,
/// in that order, placed from the right edge of the image leftwards, vertically centred;
/// the text at an integer scale, max(1, round(min(W, H) / 512)).
struct LegendLayout {
    std::vector<LegendBar> bars;
    int scale = 1;
    int omitted = 0;  ///< bars left out because the image has no room for them
};
LegendLayout LayOutLegend(const Scene& scene);

/// The colour bar's colour at `value` (linear RGB): bar.colorTf there over colorScale.
Rgb LegendColor(const LegendBar& bar, double value);

/// Draws the legend (LayOutLegend) into `canvas`: each bar on a panel of the background
/// colour (85% opaque), framed, with tick marks, labels and its field's name in
/// ContrastColor(background).
void DrawLegend(Canvas& canvas, const Scene& scene);

}  // namespace hpray
