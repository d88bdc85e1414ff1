// pbrlod — SVG line charts (svg_chart.hpp).
#include "svg_chart.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace pbrlod_tool {
namespace {

constexpr double width = 800, height = 500, left = 70, right = 210, top = 40, bottom = 60;
const char* const palette[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e",
                               "#8c564b", "#e377c2", "#7f7f7f", "#17becf", "#bcbd22"};

std::string escape(const std::string& s) {
  std::string o;
  for (const char c : s) {
    if (c == '<')
      o += "&lt;";
    else if (c == '>')
      o += "&gt;";
    else if (c == '&')
      o += "&amp;";
    else
      o += c;
  }
  return o;
}

std::string fmt(double v) {
  std::ostringstream o;
  o.precision(4);
  o << v;
  return o.str();
}

struct axis {
  double lo, hi;
  bool log;
  [[nodiscard]] double map(double v, double a, double b) const {
    const double t = log ? (std::log10(v) - lo) / (hi - lo) : (v - lo) / (hi - lo);
    return a + t * (b - a);
  }
  /// Tick values: powers of ten (log) or about six round steps (linear).
  [[nodiscard]] std::vector<double> ticks() const {
    std::vector<double> t;
    if (log) {
      for (double e = std::floor(lo); e <= std::ceil(hi); ++e)
        if (e >= lo - 1e-9 && e <= hi + 1e-9) t.push_back(std::pow(10.0, e));
      return t;
    }
    const double raw = (hi - lo) / 6, mag = std::pow(10.0, std::floor(std::log10(raw)));
    const double step = raw / mag < 2 ? 2 * mag : raw / mag < 5 ? 5 * mag : 10 * mag;
    for (double v = std::ceil(lo / step) * step; v <= hi + 1e-9 * step; v += step) t.push_back(v);
    return t;
  }
};

bool usable(const chart& c, const std::pair<double, double>& p) {
  return std::isfinite(p.first) && std::isfinite(p.second) && (!c.log_x || p.first > 0);
}

/// Axes fitted to the usable points, with a margin; a log axis spans whole decades.
std::pair<axis, axis> fit(const chart& c) {
  double x0 = std::numeric_limits<double>::infinity(), x1 = -x0, y0 = x0, y1 = -x0;
  for (const auto& s : c.series)
    for (const auto& p : s.points) {
      if (!usable(c, p)) continue;
      const double x = c.log_x ? std::log10(p.first) : p.first;
      x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, p.second),
      y1 = std::max(y1, p.second);
    }
  if (!(x0 <= x1)) x0 = 0, x1 = 1, y0 = 0, y1 = 1;
  if (c.log_x) x0 = std::floor(x0), x1 = std::max(std::ceil(x1), x0 + 1);
  if (x1 - x0 < 1e-12) x1 = x0 + 1;
  if (y1 - y0 < 1e-12) y1 = y0 + 1;
  const double ym = 0.05 * (y1 - y0);
  return {axis{x0, x1, c.log_x}, axis{y0 - ym, y1 + ym, false}};
}

void draw_axes(std::ostringstream& o, const chart& c, const axis& ax, const axis& ay) {
  const double x_end = width - right, y_end = height - bottom;
  o << "<rect x='" << left << "' y='" << top << "' width='" << x_end - left << "' height='"
    << y_end - top << "' fill='none' stroke='#444'/>\n";
  for (const double t : ax.ticks()) {
    const double x = ax.map(t, left, x_end);
    o << "<line x1='" << x << "' y1='" << top << "' x2='" << x << "' y2='" << y_end
      << "' stroke='#ddd'/><text x='" << x << "' y='" << y_end + 16
      << "' font-size='11' text-anchor='middle'>" << fmt(t) << "</text>\n";
  }
  for (const double t : ay.ticks()) {
    const double y = ay.map(t, y_end, top);
    o << "<line x1='" << left << "' y1='" << y << "' x2='" << x_end << "' y2='" << y
      << "' stroke='#ddd'/><text x='" << left - 6 << "' y='" << y + 4
      << "' font-size='11' text-anchor='end'>" << fmt(t) << "</text>\n";
  }
  o << "<text x='" << (left + x_end) / 2 << "' y='" << height - 18
    << "' font-size='13' text-anchor='middle'>" << escape(c.x_label) << "</text>\n";
  o << "<text x='18' y='" << (top + y_end) / 2 << "' font-size='13' text-anchor='middle' "
    << "transform='rotate(-90 18 " << (top + y_end) / 2 << ")'>" << escape(c.y_label)
    << "</text>\n";
  o << "<text x='" << left << "' y='24' font-size='15'>" << escape(c.title) << "</text>\n";
}

}  // namespace

std::string to_svg(const chart& c) {
  const auto [ax, ay] = fit(c);
  std::ostringstream o;
  o << "<svg xmlns='http://www.w3.org/2000/svg' width='" << width << "' height='" << height
    << "' font-family='sans-serif'>\n<rect width='100%' height='100%' fill='white'/>\n";
  draw_axes(o, c, ax, ay);
  const double x_end = width - right, y_end = height - bottom;
  for (std::size_t i = 0; i < c.series.size(); ++i) {
    const chart_series& s = c.series[i];
    const std::string colour = s.highlight ? "#000" : palette[i % std::size(palette)];
    std::string path;
    for (const auto& p : s.points) {
      if (!usable(c, p)) continue;
      const double x = ax.map(p.first, left, x_end), y = ay.map(p.second, y_end, top);
      if (!path.empty()) path += ' ';
      path += fmt(x);
      path += ',';
      path += fmt(y);
      if (!s.highlight)
        o << "<circle cx='" << x << "' cy='" << y << "' r='3' fill='" << colour << "'/>\n";
    }
    o << "<polyline points='" << path << "' fill='none' stroke='" << colour << "' stroke-width='"
      << (s.highlight ? 2.5 : 1.2) << "'" << (s.highlight ? " stroke-dasharray='6,4'" : "")
      << "/>\n";
    const double ly = top + 14 + 18 * static_cast<double>(i);
    o << "<line x1='" << x_end + 12 << "' y1='" << ly - 4 << "' x2='" << x_end + 32 << "' y2='"
      << ly - 4 << "' stroke='" << colour << "' stroke-width='2'/><text x='" << x_end + 38
      << "' y='" << ly << "' font-size='12'>" << escape(s.name) << "</text>\n";
  }
  o << "</svg>\n";
  return o.str();
}

std::vector<std::pair<double, double>> pareto_front(std::vector<std::pair<double, double>> pts) {
  std::sort(pts.begin(), pts.end(), [](const auto& a, const auto& b) {
    return a.first < b.first || (a.first == b.first && a.second > b.second);
  });
  std::vector<std::pair<double, double>> front;
  double best = -std::numeric_limits<double>::infinity();
  for (const auto& p : pts)
    if (p.second > best) {
      front.push_back(p);
      best = p.second;
    }
  return front;
}

}  // namespace pbrlod_tool
