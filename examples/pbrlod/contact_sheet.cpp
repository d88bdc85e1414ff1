// pbrlod — the demo's contact sheet (contact_sheet.hpp).
#include "contact_sheet.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <limits>

#include "pbr_lod/core/error.hpp"

namespace pbrlod_tool {
namespace {
using pbr_lod::image;
using pbr_lod::rgb8;

// A 5×7 bitmap font for the labels: digits, upper-case letters and the punctuation the demo
// prints. Each row is drawn as written ('#' = ink), so a glyph can be checked by eye.
struct glyph {
  char c;
  std::array<const char*, 7> rows;
};
constexpr glyph font[] = {
    {'0', {".###.", "#...#", "#..##", "#.#.#", "##..#", "#...#", ".###."}},
    {'1', {"..#..", ".##..", "..#..", "..#..", "..#..", "..#..", ".###."}},
    {'2', {".###.", "#...#", "....#", "...#.", "..#..", ".#...", "#####"}},
    {'3', {"#####", "...#.", "..#..", "...#.", "....#", "#...#", ".###."}},
    {'4', {"...#.", "..##.", ".#.#.", "#..#.", "#####", "...#.", "...#."}},
    {'5', {"#####", "#....", "####.", "....#", "....#", "#...#", ".###."}},
    {'6', {"..##.", ".#...", "#....", "####.", "#...#", "#...#", ".###."}},
    {'7', {"#####", "....#", "...#.", "..#..", ".#...", ".#...", ".#..."}},
    {'8', {".###.", "#...#", "#...#", ".###.", "#...#", "#...#", ".###."}},
    {'9', {".###.", "#...#", "#...#", ".####", "....#", "...#.", ".##.."}},
    {'A', {".###.", "#...#", "#...#", "#####", "#...#", "#...#", "#...#"}},
    {'B', {"####.", "#...#", "#...#", "####.", "#...#", "#...#", "####."}},
    {'C', {".###.", "#...#", "#....", "#....", "#....", "#...#", ".###."}},
    {'D', {"###..", "#..#.", "#...#", "#...#", "#...#", "#..#.", "###.."}},
    {'E', {"#####", "#....", "#....", "####.", "#....", "#....", "#####"}},
    {'F', {"#####", "#....", "#....", "####.", "#....", "#....", "#...."}},
    {'G', {".###.", "#...#", "#....", "#.###", "#...#", "#...#", ".####"}},
    {'H', {"#...#", "#...#", "#...#", "#####", "#...#", "#...#", "#...#"}},
    {'I', {".###.", "..#..", "..#..", "..#..", "..#..", "..#..", ".###."}},
    {'J', {"..###", "...#.", "...#.", "...#.", "...#.", "#..#.", ".##.."}},
    {'K', {"#...#", "#..#.", "#.#..", "##...", "#.#..", "#..#.", "#...#"}},
    {'L', {"#....", "#....", "#....", "#....", "#....", "#....", "#####"}},
    {'M', {"#...#", "##.##", "#.#.#", "#.#.#", "#...#", "#...#", "#...#"}},
    {'N', {"#...#", "#...#", "##..#", "#.#.#", "#..##", "#...#", "#...#"}},
    {'O', {".###.", "#...#", "#...#", "#...#", "#...#", "#...#", ".###."}},
    {'P', {"####.", "#...#", "#...#", "####.", "#....", "#....", "#...."}},
    {'Q', {".###.", "#...#", "#...#", "#...#", "#.#.#", "#..#.", ".##.#"}},
    {'R', {"####.", "#...#", "#...#", "####.", "#.#..", "#..#.", "#...#"}},
    {'S', {".####", "#....", "#....", ".###.", "....#", "....#", "####."}},
    {'T', {"#####", "..#..", "..#..", "..#..", "..#..", "..#..", "..#.."}},
    {'U', {"#...#", "#...#", "#...#", "#...#", "#...#", "#...#", ".###."}},
    {'V', {"#...#", "#...#", "#...#", "#...#", "#...#", ".#.#.", "..#.."}},
    {'W', {"#...#", "#...#", "#...#", "#.#.#", "#.#.#", "#.#.#", ".#.#."}},
    {'X', {"#...#", "#...#", ".#.#.", "..#..", ".#.#.", "#...#", "#...#"}},
    {'Y', {"#...#", "#...#", ".#.#.", "..#..", "..#..", "..#..", "..#.."}},
    {'Z', {"#####", "....#", "...#.", "..#..", ".#...", "#....", "#####"}},
    {'.', {".....", ".....", ".....", ".....", ".....", ".##..", ".##.."}},
    {',', {".....", ".....", ".....", ".....", ".##..", "..#..", ".#..."}},
    {'-', {".....", ".....", ".....", "#####", ".....", ".....", "....."}},
    {'=', {".....", ".....", "#####", ".....", "#####", ".....", "....."}},
    {'%', {"##...", "##..#", "...#.", "..#..", ".#...", "#..##", "...##"}},
    {':', {".....", ".##..", ".##..", ".....", ".##..", ".##..", "....."}},
    {'/', {".....", "....#", "...#.", "..#..", ".#...", "#....", "....."}},
    {'(', {"...#.", "..#..", ".#...", ".#...", ".#...", "..#..", "...#."}},
    {')', {".#...", "..#..", "...#.", "...#.", "...#.", "..#..", ".#..."}},
    {'+', {".....", "..#..", "..#..", "#####", "..#..", "..#..", "....."}},
    {'?', {".###.", "#...#", "....#", "...#.", "..#..", ".....", "..#.."}},
    {'_', {".....", ".....", ".....", ".....", ".....", ".....", "#####"}},
};
constexpr int glyph_w = 5, glyph_h = 7, margin = 6;

/// The font's size: twice its pixels under tiles wide enough for 25 such characters, else
/// once, so that a label line fits under small tiles too.
struct font_scale {
  int scale;
  [[nodiscard]] int advance() const { return (glyph_w + 1) * scale; }
  [[nodiscard]] int line_height() const { return (glyph_h + 3) * scale; }
};
font_scale scale_for(int tile_width) {
  return {tile_width >= 25 * (glyph_w + 1) * 2 ? 2 : 1};
}

const glyph& find_glyph(char c) {
  const char u = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  for (const glyph& g : font)
    if (g.c == u) return g;
  for (const glyph& g : font)
    if (g.c == '?') return g;
  return font[0];
}

/// Draws s from (x0, y0), clipped at x_end.
void draw_text(image& img, int x0, int y0, int x_end, const std::string& s, rgb8 ink,
               font_scale f) {
  const int scale = f.scale;
  int x = x0;
  for (const char c : s) {
    if (x + glyph_w * scale > x_end) break;
    if (c != ' ') {
      const glyph& g = find_glyph(c);
      for (int r = 0; r < glyph_h; ++r)
        for (int col = 0; col < glyph_w; ++col) {
          if (g.rows[static_cast<std::size_t>(r)][col] != '#') continue;
          for (int dy = 0; dy < scale; ++dy)
            for (int dx = 0; dx < scale; ++dx) {
              const int px = x + col * scale + dx, py = y0 + r * scale + dy;
              if (px >= 0 && py >= 0 && px < img.width && py < img.height)
                img.colour[img.index(px, py)] = ink;
            }
        }
    }
    x += f.advance();
  }
}

}  // namespace

image shrink(const image& src, int factor) {
  if (factor < 1) throw pbr_lod::InvalidArgument("shrink: the factor must be at least 1");
  image out(src.width / factor, src.height / factor);
  for (int y = 0; y < out.height; ++y)
    for (int x = 0; x < out.width; ++x) {
      unsigned sum[3] = {0, 0, 0};
      float depth = std::numeric_limits<float>::infinity();
      for (int dy = 0; dy < factor; ++dy)
        for (int dx = 0; dx < factor; ++dx) {
          const std::size_t i = src.index(x * factor + dx, y * factor + dy);
          sum[0] += src.colour[i].r;
          sum[1] += src.colour[i].g;
          sum[2] += src.colour[i].b;
          depth = std::min(depth, src.depth[i]);
        }
      const unsigned n = static_cast<unsigned>(factor * factor);
      const auto avg = [&](unsigned s) { return static_cast<std::uint8_t>((s + n / 2) / n); };
      out.colour[out.index(x, y)] = {avg(sum[0]), avg(sum[1]), avg(sum[2])};
      out.depth[out.index(x, y)] = depth;
    }
  return out;
}

image contact_sheet(const std::vector<std::vector<sheet_tile>>& rows) {
  int tile_w = 0, tile_h = 0, cols = 0;
  std::size_t lines = 0;
  for (const auto& row : rows) {
    cols = std::max(cols, static_cast<int>(row.size()));
    for (const auto& t : row) {
      if (tile_w == 0) tile_w = t.img.width, tile_h = t.img.height;
      if (t.img.width != tile_w || t.img.height != tile_h)
        throw pbr_lod::InvalidArgument("contact_sheet: tiles of different sizes");
      lines = std::max(lines, t.lines.size());
    }
  }
  const font_scale f = scale_for(tile_w);
  const int cell_w = tile_w + margin,
            cell_h = tile_h + static_cast<int>(lines) * f.line_height() + margin;
  image sheet(cols * cell_w + margin, static_cast<int>(rows.size()) * cell_h + margin,
              rgb8{255, 255, 255});
  std::fill(sheet.depth.begin(), sheet.depth.end(), 0.0f);  // opaque: PNG alpha marks coverage
  for (std::size_t r = 0; r < rows.size(); ++r)
    for (std::size_t c = 0; c < rows[r].size(); ++c) {
      const sheet_tile& t = rows[r][c];
      const int x0 = margin + static_cast<int>(c) * cell_w;
      const int y0 = margin + static_cast<int>(r) * cell_h;
      for (int y = 0; y < tile_h; ++y)
        for (int x = 0; x < tile_w; ++x)
          sheet.colour[sheet.index(x0 + x, y0 + y)] = t.img.colour[t.img.index(x, y)];
      for (std::size_t l = 0; l < t.lines.size(); ++l)
        draw_text(sheet, x0, y0 + tile_h + 2 * f.scale + static_cast<int>(l) * f.line_height(),
                  x0 + tile_w, t.lines[l], rgb8{0, 0, 0}, f);
    }
  return sheet;
}

}  // namespace pbrlod_tool
