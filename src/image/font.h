// A small bitmap font for the annotations of the PNG (legend titles and tick labels).
#pragma once

#include <cstdint>

namespace hpray::font {

/// Every glyph is 5 pixels wide and 9 tall: rows 0-6 from the cap height down to the
/// baseline, rows 7-8 for descenders. Text advances 6 pixels per character and 10 per
/// line, so neighbouring glyphs and lines keep a blank pixel between them.
constexpr int kGlyphWidth = 5;
constexpr int kGlyphHeight = 9;
constexpr int kAdvance = 6;
constexpr int kLineHeight = 10;
/// Rows 0 .. kCapHeight - 1 hold capitals and digits.
constexpr int kCapHeight = 7;

/// The rows of the glyph of `c`, top first; bit 4 of a row is its leftmost pixel.
/// Printable ASCII (32-126) has a glyph of its own, any other byte that of '?'.
const std::uint8_t* Glyph(char c);

}  // namespace hpray::font
