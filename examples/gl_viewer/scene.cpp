// gl_viewer — scene.hpp: a file or generated scene, drawn through pbrlod's method table.
#include "scene.hpp"

#include <algorithm>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/raster/reference.hpp"

namespace gl_viewer {

using namespace pbrlod_tool;

scene::scene(const std::string& file, const std::string& method,
             const std::vector<std::string>& params) {
  name_ = file.empty() ? "generated demo scene" : file;
  if (method.empty()) {
    if (!file.empty() && is_hierarchy_file(file)) {
      const method_entry& m = lod_method(file);
      lod_ = m.load(file);
      tolerance_key_ = m.tolerance_key;
    } else if (file.empty()) {
      loaded_input in;
      in.mesh = make_demo_scene(64);
      in_ = std::move(in);
    } else {
      in_ = load(file);
    }
    return;
  }
  const auto& all = methods();
  const auto it = std::find_if(all.begin(), all.end(),
                               [&](const method_entry& m) { return m.name == method && m.build; });
  if (it == all.end()) throw InvalidArgument("--method: unknown method '" + method + "'");
  tolerance_key_ = it->tolerance_key;
  if (file.empty()) {
    loaded_input in;
    in.mesh = make_demo_scene(64);
    lod_ = it->build(params, build_input(std::move(in), name_), false);
  } else {
    lod_ = it->build(params, build_input(file), false);
  }
  name_ += " (" + method + ")";
}

camera scene::camera_of(const view_args& va) const {
  if (lod_) {
    const auto [centre, radius] = lod_->input_bounds();
    return make_camera(centre, radius, va);
  }
  return make_camera(in_->mesh.vertices, va);
}

selection scene::draw(host_sink& host, const frame_settings& f) const {
  const camera cam = camera_of(f.view);
  if (lod_) {
    const frame fr = lod_->draw({.cam = cam,
                                 .view = f.view,
                                 .tolerance = f.tolerance,
                                 .seed = f.seed,
                                 .time_traversal = false,
                                 .host = &host,
                                 .collect_samples = false,
                                 .sample_spacing = 0});
    return {fr.st, fr.seconds};
  }
  // An input at full detail: render_reference's primitives (pbrlod render INPUT).
  const auto t0 = clock_type::now();
  const render_options o = make_render_options(*in_, f.view);
  thread_local buffer_sink<host_attributes> prims;
  prims.clear();
  const attributes carried = in_->is_mesh()
                                 ? reference_primitives(in_->mesh, cam, prims)
                                 : reference_primitives(in_->mesh.vertices, cam, o, prims);
  render_options ho = o;
  ho.fx = o.fx & applicable_effects(all_effects, carried);
  host.begin(view(cam, in_->mesh.vertices.origin), ho, carried);
  struct forward {
    host_sink& out;
    void point(const point_prim<host_attributes>& p) { out.point(p); }
    void splat(const splat_prim<host_attributes>& s) { out.splat(s); }
    void triangle(const triangle_prim<host_attributes>& t) { out.triangle(t); }
  } fw{host};
  prims.replay(fw);
  selection s;
  s.st.points = prims.points.size();
  s.st.splats = prims.splats.size();
  s.st.triangles = prims.triangles.size();
  s.seconds = seconds_since(t0);
  return s;
}

image scene::draw_cpu(const frame_settings& f) const {
  const camera cam = camera_of(f.view);
  if (lod_)
    return lod_->draw({.cam = cam, .view = f.view, .tolerance = f.tolerance, .seed = f.seed}).img;
  const render_options o = make_render_options(*in_, f.view);
  return in_->is_mesh() ? render_reference(in_->mesh, cam, o)
                        : render_reference(in_->mesh.vertices, cam, o);
}

}  // namespace gl_viewer
