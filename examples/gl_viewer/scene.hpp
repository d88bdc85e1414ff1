// gl_viewer — what is drawn: a .lod file, an input file at full detail, or either built on the
// fly by a method, through the pbrlod tool's machinery (pbrlod_core), so that FILE, --view and
// --tolerance mean what they mean to `pbrlod render`.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lod.hpp"
#include "tool.hpp"

namespace gl_viewer {

/// One frame's request: the view and tolerance as `pbrlod render` takes them.
struct frame_settings {
  pbrlod_tool::view_args view;
  float tolerance = 1;
  std::uint64_t seed = 1;
};

/// What a frame selected, and how long selection (and the hand-over to the host) took.
struct selection {
  pbrlod_tool::traverse_stats st;  // zero for an input drawn at full detail
  double seconds = 0;
};

class scene {
 public:
  /// `file` empty: the generated scene of `pbrlod demo`. `method` empty: a .lod file as it is,
  /// an input at full detail (pbrlod render's reference); else the input built by that method
  /// with `params` (as `pbrlod build --method M --param k=v`). Throws pbr_lod::Error.
  scene(const std::string& file, const std::string& method, const std::vector<std::string>& params);

  /// Sends the frame's primitives to host (host.begin() first).
  selection draw(pbrlod_tool::host_sink& host, const frame_settings& f) const;
  /// The CPU reference rasteriser's image of the same frame (the same cut).
  [[nodiscard]] pbr_lod::image draw_cpu(const frame_settings& f) const;
  /// For the window title.
  [[nodiscard]] const std::string& name() const { return name_; }
  /// What --tolerance means here (tolerance_px, factor, ...): the method's render --json key.
  [[nodiscard]] const std::string& tolerance_key() const { return tolerance_key_; }

 private:
  [[nodiscard]] pbr_lod::camera camera_of(const pbrlod_tool::view_args& va) const;

  std::string name_, tolerance_key_ = "tolerance_px";
  std::unique_ptr<pbrlod_tool::lod> lod_;        // a hierarchy, or
  std::optional<pbrlod_tool::loaded_input> in_;  // an input drawn at full detail
};

}  // namespace gl_viewer
