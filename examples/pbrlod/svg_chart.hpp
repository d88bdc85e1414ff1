// pbrlod — line charts as SVG files, for the sweep's report (no plotting library: a chart is a
// few dozen elements).
#pragma once

#include <string>
#include <vector>

namespace pbrlod_tool {

struct chart_series {
  std::string name;
  std::vector<std::pair<double, double>> points;  ///< (x, y), drawn in this order
  bool highlight = false;                         ///< drawn thick and dashed (a Pareto front)
};

struct chart {
  std::string title, x_label, y_label;
  bool log_x = false;  ///< x on a log10 axis (times, bytes); x ≤ 0 points are left out
  std::vector<chart_series> series;
};

/// The chart as an SVG document (800×500), axes fitted to the finite points, one colour per
/// series with a legend.
[[nodiscard]] std::string to_svg(const chart& c);

/// The points of `pts` that no other point beats in both coordinates (lower x and higher y is
/// better: time or bytes against PSNR), sorted by x.
[[nodiscard]] std::vector<std::pair<double, double>> pareto_front(
    std::vector<std::pair<double, double>> pts);

}  // namespace pbrlod_tool
