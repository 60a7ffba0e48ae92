// The picture a PNG shows: the rendered image over its background, opaque, in linear RGB,
// and what can be drawn on it afterwards (anti-aliased lines, rectangles, bitmap text).
// Annotations go here and never into the Image, so that the EXR and the arrays stay data.
#pragma once

#include <array>
#include <functional>
#include <string>
#include <vector>

#include "image/image.h"

namespace hpray {

using Rgb = std::array<double, 3>;

/// An opaque W x H picture in linear RGB, row-major with the top row first; pixel (i, j)
/// covers the square [i, i + 1] x [j, j + 1] of continuous image coordinates (the
/// camera's, scene/camera.h: RayAt), its centre at (i + 1/2, j + 1/2).
struct Canvas {
    int width = 0;
    int height = 0;
    std::vector<double> rgb;  ///< 3 values per pixel

    /// The premultiplied `image` over the opaque `background`: c + (1 - a) background.
    static Canvas Over(const Image& image, const Rgb& background);

    Rgb At(int i, int j) const;
    /// Mixes `color` into pixel (i, j) with weight `alpha` in [0, 1] (linear RGB, where
    /// coverage adds up as light does); pixels outside the canvas are ignored.
    void Blend(int i, int j, const Rgb& color, double alpha);
    /// Blend over the pixels [x, x + w) x [y, y + h), clipped to the canvas.
    void FillRect(int x, int y, int w, int h, const Rgb& color, double alpha = 1.0);
    /// A frame `thickness` pixels wide around [x, x + w) x [y, y + h), just outside.
    void FrameRect(int x, int y, int w, int h, int thickness, const Rgb& color);
};

/// A straight piece of line in continuous image coordinates, from (x0, y0) to (x1, y1).
struct LinePiece {
    double x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};

/// How much of a line is seen at a pixel: `piece` is the index of the line piece, `u` in
/// [0, 1] the parameter of its point nearest the pixel's centre, (i, j) the pixel. 1 is
/// fully seen, 0 hidden.
using LineVisibility = std::function<double(std::size_t piece, double u, int i, int j)>;

/// The coverage of each pixel by the pieces drawn `width` pixels wide with round ends:
/// for a pixel whose centre lies at distance d from a piece, min(1, max(0, width / 2 +
/// 1/2 - d)) (a one-pixel ramp centred on the line's edge, the box filter's coverage of a
/// straight edge), times visible(piece, u, i, j); where pieces overlap the largest
/// coverage counts, so corners and crossings are not drawn twice. W * H values, row-major
/// (float: the coverage of an 8-bit picture needs no more).
/// Pieces may reach far outside the canvas (only the part on it costs time).
std::vector<float> LineCoverage(int width, int height,
                                const std::vector<LinePiece>& pieces, double lineWidth,
                                const LineVisibility& visible);

/// Blend `color` into every pixel with its coverage as weight.
void DrawCoverage(Canvas& canvas, const std::vector<float>& coverage, const Rgb& color);

/// Width and height in pixels of `text` drawn at integer `scale` (image/font.h: 6 x 10
/// per character, the blank column after the last one not counted).
int TextWidth(const std::string& text, int scale);
int TextHeight(int scale);
/// Draws `text` in `color` with its top-left corner at pixel (x, y), each font pixel a
/// `scale` x `scale` block (no anti-aliasing: the glyphs are pixel art).
void DrawText(Canvas& canvas, int x, int y, const std::string& text, int scale,
              const Rgb& color);

}  // namespace hpray
