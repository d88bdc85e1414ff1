// pbrlod — the table of build methods and what a file or view asks of them: the parts of the
// tool that the OpenGL viewer (examples/gl_viewer) shares through the pbrlod_core library.
#include "pbr_lod/core/error.hpp"
#include "tool.hpp"

namespace pbrlod_tool {

const std::vector<method_entry>& methods() {
  static const std::vector<method_entry> m = {
#define PBRLOD_METHOD(id) id##_method(),
#include "methods.inc"  // cmake/builders.cmake's builders, in its order
#undef PBRLOD_METHOD
  };
  return m;
}

const method_entry& method_named(const std::string& name) {
  std::string names;
  for (const auto& m : methods()) {
    if (m.name == name) return m;
    names += (names.empty() ? "" : ", ") + m.name;
  }
  throw InvalidArgument("unknown method '" + name + "' (expected one of " + names + ")");
}

const method_entry& lod_method(const std::string& path) {
  const auto h = peek_lod(path);
  for (const auto& m : methods())
    if (m.load && ((!m.magic.empty() && m.magic == h.magic) ||
                   (!m.dir_magic.empty() && m.dir_magic == h.magic)))
      return m;
  throw FormatError(path +
                    ": not a hierarchy file written by this version of pbrlod (unknown magic)");
}

render_options make_render_options(const loaded_input& in, const view_args& a) {
  render_options o;
  if (a.effects_list == "default") {
    o.fx = no_effects;
    o.fx.shading = in.is_mesh() || !in.mesh.vertices.normals.empty();
    o.fx.colour = !in.mesh.vertices.colours.empty();
    o.fx.blending = !in.is_mesh();  // a cloud's splats blended, as its hierarchies' finest cuts
  } else {
    o.fx = parse_effects(a.effects_list);
  }
  o.supersample = a.supersample;
  return o;
}

}  // namespace pbrlod_tool
