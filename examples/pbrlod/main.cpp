// pbrlod — the command-line tool of pbr_lod (see DESIGN.md "The command-line tool").
// This file: the subcommands and the method table; tool.hpp/.cpp the shared parts; one
// <method>_method.cpp per builder.
//
//   pbrlod build  --method NAME [--param k=v]... INPUT -o OUT.lod
//   pbrlod render OUT.lod|INPUT [--view AZ,EL,DIST] [--size WxH] [--tolerance PX]
//                 [--effects LIST] [--up y|z] [--supersample K] -o IMAGE.png [--json]
//   pbrlod stats  OUT.lod|INPUT [--json]
//   pbrlod compare A.png B.png [--json]
//   pbrlod demo   [INPUT] [-o DIR] [--json]
//   pbrlod sweep  [INPUT...] [-o DIR] [--size small|full] [--check] [--json]
//
// Exit codes: 0 success, 1 bad input or failure (message on stderr), 2 usage error or a method
// that this version does not have.
#include <CLI/CLI.hpp>

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <sstream>

#include "child_build.hpp"
#include "contact_sheet.hpp"
#include "distributed.hpp"
#include "lod.hpp"
#include "papers.hpp"
#include "pbr_lod/builders/chunked_gaussian_hierarchy.hpp"
#include "pbr_lod/builders/gaussian_hierarchy.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/io/copc.hpp"
#include "pbr_lod/io/gaussians.hpp"
#include "pbr_lod/io/texture.hpp"
#include "pbr_lod/raster/gaussians.hpp"
#include "pbr_lod/raster/png.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "pbr_lod/raster/reference.hpp"
#include "pbr_lod/version.hpp"
#include "sweep.hpp"
#include "tool.hpp"

namespace {
using namespace pbrlod_tool;
namespace fs = std::filesystem;

void add_view_options(CLI::App* cmd, view_args& a) {
  cmd->add_option("--view", a.view,
                  "AZ,EL,DIST: azimuth and elevation in degrees around the "
                  "model's bounding-sphere centre, distance in radii")
      ->capture_default_str();
  cmd->add_option("--size", a.size, "WxH image size in pixels")->capture_default_str();
  cmd->add_option("--up", a.up, "up axis: y (scans) or z (LiDAR)")
      ->check(CLI::IsMember({"y", "z"}))
      ->capture_default_str();
  cmd->add_option(
      "--effects", a.effects_list,
      "comma list of shading, colour, backface_cull, shadows, hole_filling, blending; 'none'; "
      "'all'; 'default' = shading where the data has normals (or faces), colour where "
      "it has colours, and splats and points blended (a list without 'blending', e.g. "
      "'shading,colour', draws them unblended)");
  cmd->add_option("--supersample", a.supersample,
                  "draw at K x K the resolution (the same cut) and box-filter down: antialiasing")
      ->check(CLI::Range(1, 16))
      ->capture_default_str();
}

/// The input as the user sees it: a mesh's triangles, a cloud's splats, a Gaussian scene's every
/// Gaussian (raster/gaussians.hpp; the effects do not apply to it but the background).
image render_input(const loaded_input& in, const camera& cam, const render_options& o) {
  if (in.is_gaussians()) {
    gaussian_render_options go;
    go.background = o.background;
    return render_gaussians(in.gaussians, cam, go);
  }
  return in.is_mesh() ? render_reference(in.mesh, cam, o)
                      : render_reference(in.mesh.vertices, cam, o);
}

/// The fields every method reports for a frame, then the method's own.
json frame_json(const frame& f, const method_entry& m, float tolerance) {
  json j;
  j.str("method", m.name).num(m.tolerance_key, tolerance).str("effects", f.fx.to_string());
  j.merge(f.extra);
  j.integer("width", f.img.width).integer("height", f.img.height);
  j.integer("nodes_visited", static_cast<long long>(f.st.visited));
  j.integer("culled_frustum", static_cast<long long>(f.st.culled_frustum));
  j.integer("culled_backface", static_cast<long long>(f.st.culled_backface));
  j.integer("nodes_drawn", static_cast<long long>(f.st.emitted_nodes));
  j.integer("leaves_drawn", static_cast<long long>(f.st.emitted_leaves));
  j.integer("points", static_cast<long long>(f.st.points));
  j.integer("triangles", static_cast<long long>(f.st.triangles));
  j.integer("splats", static_cast<long long>(f.st.splats));
  j.integer("covered_pixels", static_cast<long long>(f.img.covered_count()));
  j.num("frame_seconds", f.seconds);
  return j;
}

/// `render FILE.lod`: the camera frames the input's bounds the file records, as for the input.
int render_hierarchy(const std::string& input, const view_args& va, float tolerance,
                     const std::string& output, bool as_json, std::uint64_t seed) {
  const method_entry& m = lod_method(input);
  const auto l = m.load(input);
  const auto [centre, radius] = l->input_bounds();
  const frame f = l->draw({.cam = make_camera(centre, radius, va),
                           .view = va,
                           .tolerance = tolerance,
                           .seed = seed,
                           .time_traversal = false,
                           .host = nullptr,
                           .collect_samples = false,
                           .sample_spacing = 0});
  write_png(output, f.img);
  if (as_json) {
    json j;
    j.str("input", input).str("output", output);
    std::cout << j.merge(frame_json(f, m, tolerance)).text() << "\n";
  } else {
    std::cout << "wrote " << output << ": " << f.st.points << " points, " << f.st.splats
              << " splats and " << f.st.triangles << " triangles at " << m.tolerance_key << " "
              << tolerance << " (" << f.seconds << " s)\n";
  }
  return 0;
}

int cmd_render(const std::string& input, const view_args& va, float tolerance,
               const std::string& output, bool as_json, std::uint64_t seed) {
  if (is_hierarchy_file(input))
    return render_hierarchy(input, va, tolerance, output, as_json, seed);
  progress prog(as_json);
  prog.step("reading " + input);
  const auto in = load(input);
  const camera cam = make_camera(in.mesh.vertices, va);
  const render_options o = make_render_options(in, va);
  prog.step("rendering");
  const auto t0 = clock_type::now();
  const image img = render_input(in, cam, o);
  const double render_s = seconds_since(t0);
  write_png(output, img);
  std::size_t covered = 0;
  for (const float d : img.depth) covered += std::isfinite(d);
  if (as_json) {
    json j;
    j.str("input", input).str("output", output);
    j.str("kind", in.is_gaussians() ? "gaussians" : in.is_mesh() ? "mesh" : "points");
    j.num("tolerance_px", tolerance).str("effects", o.fx.to_string());
    j.integer("width", img.width).integer("height", img.height);
    j.integer("covered_pixels", static_cast<long long>(covered));
    j.integer("primitives",
              static_cast<long long>(in.is_mesh() ? in.mesh.num_faces() : in.mesh.num_vertices()));
    if (in.is_gaussians()) j.integer("gaussians", static_cast<long long>(in.gaussians.size()));
    j.num("read_seconds", in.read_seconds).num("render_seconds", render_s);
    std::cout << j.text() << "\n";
  } else {
    std::cout << "wrote " << output << " (" << img.width << "x" << img.height << ", " << covered
              << " pixels covered, " << render_s << " s)\n";
  }
  return 0;
}

/// `export OUT.lod -o cut.ply`: a Gaussian hierarchy's cut for a view and tolerance (framed as
/// `render` frames it), or its level N, as a standard 3DGS PLY other viewers open.
int cmd_export(const std::string& input, const view_args& va, float tolerance,
               std::optional<int> level, const std::string& output, bool as_json) {
  if (lod_method(input).name != "gaussian-hierarchy")
    throw InvalidArgument(input +
                          ": export writes the cuts of Gaussian hierarchies "
                          "(built with --method gaussian-hierarchy)");
  // Framed by the input's bounds as `render` frames it (a chunked folder records them).
  const auto t0 = clock_type::now();
  std::size_t input_gaussians = 0;
  const auto cut_of = [&](const auto& h, std::pair<vec3d, double> bounds) {
    input_gaussians = h.input_gaussians();
    if (level) return h.level(static_cast<std::size_t>(*level));
    const view v(make_camera(bounds.first, bounds.second, va), h.origin());
    return h.cut(v, {.tolerance_px = tolerance},
                 gaussian_policy{.merged_lowpass_px2 = va.merged_lowpass});
  };
  gaussian_cloud cut;
  if (is_chunked_gaussian_hierarchy(input)) {
    const auto h = chunked_gaussian_hierarchy::open(input);
    cut = cut_of(h, {h.origin() + h.input_sphere().centre.cast<double>(), h.input_sphere().radius});
  } else {
    const auto h = gaussian_hierarchy::load(input);
    const auto& p = h.store().positions;
    cut = cut_of(h, bounds_of(h.origin(), std::span<const vec3f>(p.data(), h.input_gaussians())));
  }
  write_gaussians_ply(cut, output);
  const double seconds = seconds_since(t0);
  if (as_json) {
    json j;
    j.str("input", input).str("output", output);
    if (level)
      j.integer("level", *level);
    else
      j.str("view", va.view).num("tolerance_px", tolerance);
    j.integer("gaussians", static_cast<long long>(cut.size()));
    j.integer("input_gaussians", static_cast<long long>(input_gaussians));
    j.num("seconds", seconds);
    std::cout << j.text() << "\n";
  } else {
    std::cout << "wrote " << output << ": " << cut.size() << " of " << input_gaussians
              << " Gaussians (" << (level ? "level " + std::to_string(*level) : "the view's cut")
              << ")\n";
  }
  return 0;
}

bool is_copc_export(const std::string& format, const std::string& output) {
  if (format != "auto") return format == "copc";
  return output.size() >= 4 && output.compare(output.size() - 4, 4, ".laz") == 0;
}

/// `export OUT.lod --format copc -o out.copc.laz`: every point the hierarchy's nodes hold, by
/// level, as COPC (io/copc.hpp, docs/io.md).
int cmd_export_copc(const std::string& input, const std::string& output, const std::string& crs,
                    std::uint32_t node_points, bool snap, bool as_json) {
  const method_entry& m = lod_method(input);
  if (m.name == "gaussian-hierarchy")
    throw InvalidArgument(input +
                          ": a Gaussian hierarchy exports its cuts as 3DGS PLY (--format ply)");
  const auto t0 = clock_type::now();
  const levelled_points pts = m.load(input)->points_by_level(input, snap);
  pbr_lod::copc_options o{.node_points = node_points};
  if (!crs.empty()) {
    o.wkt = pbr_lod::las_wkt(crs);
    if (o.wkt.empty())
      throw InvalidArgument(crs + ": --crs-from: the file has no spatial reference in WKT");
  }
  const pbr_lod::copc_summary s = pbr_lod::write_copc(output, pts.cloud, pts.levels, o);
  const double seconds = seconds_since(t0);
  const int deepest =
      pts.levels.empty() ? 0 : *std::max_element(pts.levels.begin(), pts.levels.end());
  if (as_json) {
    json j;
    j.str("input", input).str("output", output).str("format", "copc");
    j.integer("points", static_cast<long long>(s.points));
    j.integer("hierarchy_nodes", static_cast<long long>(pts.nodes));
    j.integer("hierarchy_levels", deepest + 1);
    j.integer("leaf_samples", static_cast<long long>(pts.leaf_samples));
    j.str("coarse_points", snap ? "samples" : "representatives");
    j.integer("copc_nodes", static_cast<long long>(s.nodes));
    j.integer("copc_empty_nodes", static_cast<long long>(s.empty_nodes));
    j.integer("copc_levels", s.max_level + 1);
    j.integer("level_shift", s.shift);
    j.str("attributes", pts.cloud.present().to_string());
    j.num("scale", s.scale).num("halfsize", s.halfsize).num("spacing", s.spacing);
    json c;
    c.num("x", s.centre.x()).num("y", s.centre.y()).num("z", s.centre.z());
    j.object("centre", c);
    j.boolean("spatial_reference", !o.wkt.empty());
    j.integer("bytes", static_cast<long long>(s.bytes));
    j.num("seconds", seconds);
    std::cout << j.text() << "\n";
  } else {
    std::cout << "wrote " << output << ": " << s.points << " points of " << pts.nodes
              << " hierarchy nodes in " << s.nodes
              << " COPC nodes (hierarchy level l at COPC level "
              << "max(0, l - " << s.shift << ")), " << s.bytes << " bytes\n";
  }
  return 0;
}

int cmd_stats(const std::string& input, bool as_json) {
  if (is_hierarchy_file(input)) {
    const json j = lod_method(input).load(input)->stats(input);
    std::cout << (as_json ? "" : input + ": ") << j.text() << "\n";
    return 0;
  }
  const auto in = load(input);
  const auto& c = in.mesh.vertices;
  const auto [centre, radius] = world_bounds(c);
  const attributes a = c.present();
  // Bytes per point as pbr_lod stores the input (point_set with exactly these attributes).
  const std::size_t bpp = a.bytes_per_point();
  if (as_json) {
    json j;
    j.str("input", input).str("kind", in.is_mesh() ? "mesh" : "points");
    j.integer("points", static_cast<long long>(c.size()));
    j.integer("faces", static_cast<long long>(in.mesh.num_faces()));
    j.integer("points_in_file", static_cast<long long>(in.report.points_read));
    j.integer("dropped_non_finite", static_cast<long long>(in.report.dropped_non_finite));
    j.integer("faces_dropped", static_cast<long long>(in.report.faces_dropped));
    j.str("attributes", a.to_string());
    j.boolean("textured", in.mesh.texture != nullptr && !in.mesh.face_texcoords.empty());
    j.integer("bytes_per_point", static_cast<long long>(bpp));
    j.num("bits_per_point", 8.0 * static_cast<double>(bpp));
    json o;
    o.num("x", c.origin.x()).num("y", c.origin.y()).num("z", c.origin.z());
    j.object("origin", o);
    json s;
    s.num("x", centre.x()).num("y", centre.y()).num("z", centre.z()).num("radius", radius);
    j.object("bounding_sphere", s);
    j.num("read_seconds", in.read_seconds);
    std::cout << j.text() << "\n";
  } else {
    std::cout << input << ": " << (in.is_mesh() ? "mesh" : "point cloud") << ", " << c.size()
              << " points, " << in.mesh.num_faces() << " faces, attributes " << a.to_string()
              << ", " << bpp << " bytes/point, bounding sphere centre (" << centre.transpose()
              << ") radius " << radius << ", read in " << in.read_seconds << " s\n";
  }
  return 0;
}

int cmd_compare(const std::string& a, const std::string& b, bool as_json) {
  const image ia = image_from_texture(read_png_texture(a)),
              ib = image_from_texture(read_png_texture(b));
  if (ia.width != ib.width || ia.height != ib.height)
    throw InvalidArgument("compare: " + a + " is " + std::to_string(ia.width) + "x" +
                          std::to_string(ia.height) + " but " + b + " is " +
                          std::to_string(ib.width) + "x" + std::to_string(ib.height));
  const image_error e = compare_images(ia, ib);
  // With A the input's own render: what the user sees (its interior, its silhouette).
  const input_likeness l = compare_to_input(ia, ib);
  if (as_json) {
    json j = error_json(e);
    j.num("psnr_interior", l.psnr_interior)
        .num("silhouette_iou", l.silhouette_iou)
        .integer("interior_pixels", static_cast<long long>(l.interior_pixels))
        .integer("interior_holes", static_cast<long long>(l.interior_holes));
    j.str("reference", a).str("test", b);
    std::cout << j.text() << "\n";
  } else {
    std::cout << "RMSE " << e.rmse << ", PSNR " << e.psnr << " dB, hole fraction "
              << e.hole_fraction << " (" << e.holes << " of " << e.reference_covered
              << " reference pixels); interior PSNR " << l.psnr_interior << " dB, silhouette IoU "
              << l.silhouette_iou << "\n";
  }
  return 0;
}

int cmd_build(const std::string& method, const std::string& input, const std::string& output,
              const std::vector<std::string>& params, bool as_json) {
  const auto& all = methods();
  const auto it =
      std::find_if(all.begin(), all.end(), [&](const auto& m) { return m.name == method; });
  if (it == all.end()) {
    std::string names;
    for (const auto& m : all) names += (names.empty() ? "" : ", ") + m.name;
    std::cerr << "pbrlod build: unknown method '" << method << "' (expected one of " << names
              << ")\n";
    return 2;
  }
  if (!it->build) {
    std::cerr << "pbrlod build: method '" << method << "' (" << it->paper
              << ") is not available in pbr_lod " << version() << " yet\n";
    return 2;
  }
  if (wants_chunked_build(params)) {
    if (!it->build_chunked) {
      std::string have;
      for (const auto& m : methods())
        if (m.build_chunked) have += (have.empty() ? "" : ", ") + m.name;
      throw InvalidArgument("pbrlod build: method '" + method +
                            "' has no chunked build (memory=, chunk_points=); these have: " + have);
    }
    json report;
    const auto l = it->build_chunked(params, input, output, interactive(as_json), report, nullptr);
    std::cout << (as_json ? "" : "wrote " + output + "/: ") << l->stats(output).merge(report).text()
              << "\n";
    return 0;
  }
  const auto l = it->build(params, build_input(input), interactive(as_json));
  l->save(output);
  std::cout << (as_json ? "" : "wrote " + output + ": ") << l->stats(output).text() << "\n";
  return 0;
}

/// Points the demo samples from a mesh: one per vertex, at least 20,000.
std::size_t demo_samples(const triangle_mesh& m) {
  return std::max<std::size_t>(m.num_vertices(), 20000);
}

/// One line of the demo's summary table.
struct demo_row {
  std::string method, setting;
  /// Against the input's own render: interior PSNR and silhouette IoU (compare_to_input) lead;
  /// the whole-frame PSNR and hole fraction follow.
  double psnr_interior = 0, silhouette_iou = 0;
  double psnr = 0, hole_fraction = 0, frame_ms = 0, build_s = 0, bytes_per_sample = 0;
  std::size_t primitives = 0;
  std::string note;  ///< why a builder has no frames
};

std::string fixed(double v, int digits) {
  std::ostringstream o;
  o.setf(std::ios::fixed);
  o.precision(digits);
  o << v;
  return o.str();
}

/// "tolerance 4 px" or "factor 4": the setting as `render` names it.
std::string setting_text(const method_entry& m, float tolerance) {
  const std::string v = fixed(tolerance, tolerance == std::floor(tolerance) ? 0 : 1);
  return m.tolerance_key == "tolerance_px" ? "tol " + v + " px" : m.tolerance_key + " " + v;
}

/// Builds one method from `in` with its defaults and draws it at its demo tolerances: one PNG,
/// one contact-sheet tile and one table row each. A method that cannot build from this input
/// (POP from a point cloud) gets a row saying why.
json demo_method(const method_entry& m, const build_input& in, const camera& cam,
                 const view_args& va, const image& ref, const std::string& dir, progress& prog,
                 std::vector<sheet_tile>& tiles, std::vector<demo_row>& table) {
  json j;
  prog.step("building " + m.name);
  const auto t0 = clock_type::now();
  std::unique_ptr<lod> l;
  try {
    l = m.build({}, in, false);
  } catch (const InvalidArgument& e) {
    demo_row skipped;
    skipped.method = m.name;
    skipped.note = e.what();
    table.push_back(skipped);
    return j.str("skipped", e.what());
  }
  const double build_s = seconds_since(t0);
  const double bps = static_cast<double>(l->file_bytes()) / static_cast<double>(l->samples());
  j.num("build_seconds", build_s).integer("file_bytes", static_cast<long long>(l->file_bytes()));
  j.num("bytes_per_sample", bps);
  std::string frames;
  for (const float tol : m.demo_tolerances) {
    const std::string setting = setting_text(m, tol);
    prog.step("rendering " + m.name + " at " + setting);
    const frame f = l->draw({.cam = cam,
                             .view = va,
                             .tolerance = tol,
                             .seed = 1,
                             .time_traversal = false,
                             .host = nullptr,
                             .collect_samples = false,
                             .sample_spacing = 0});
    const image_error e = compare_images(ref, f.img);
    const input_likeness like = compare_to_input(ref, f.img);
    const std::string png =
        (fs::path(dir) / (m.name + "_" + fixed(tol, tol == std::floor(tol) ? 0 : 1) + ".png"))
            .string();
    write_png(png, f.img);
    json fj;
    fj.num("psnr_interior", like.psnr_interior).num("silhouette_iou", like.silhouette_iou);
    fj.merge(error_json(e));
    fj.num(m.tolerance_key, tol).str("png", png).num("frame_seconds", f.seconds);
    fj.integer("primitives", static_cast<long long>(f.st.primitives()));
    frames += (frames.empty() ? "" : ",") + fj.text();
    table.push_back({m.name, setting, like.psnr_interior, like.silhouette_iou, e.psnr,
                     e.hole_fraction, 1e3 * f.seconds, build_s, bps, f.st.primitives(), ""});
    tiles.push_back(
        {shrink(f.img, 2),
         {m.name + "  " + setting,
          fixed(like.psnr_interior, 1) + " dB  IoU " + fixed(like.silhouette_iou, 3),
          std::to_string(f.st.primitives()) + " prim  " + fixed(1e3 * f.seconds, 1) + " ms"}});
  }
  return j.raw("frames", "[" + frames + "]");
}

void print_demo_table(const std::vector<demo_row>& rows) {
  std::printf("%-12s %-15s %9s %6s %8s %7s %11s %9s %8s %9s\n", "builder", "setting", "inner dB",
              "IoU", "PSNR dB", "holes%", "primitives", "frame ms", "build s", "B/sample");
  for (const demo_row& r : rows) {
    if (!r.note.empty()) {
      std::printf("%-12s %s\n", r.method.c_str(), r.note.c_str());
      continue;
    }
    std::printf("%-12s %-15s %9.2f %6.3f %8.2f %7.2f %11zu %9.1f %8.2f %9.2f\n", r.method.c_str(),
                r.setting.c_str(), r.psnr_interior, r.silhouette_iou, r.psnr, 100 * r.hole_fraction,
                r.primitives, r.frame_ms, r.build_s, r.bytes_per_sample);
  }
}

/// The demo's splat quality (not LOD): the mesh's sampled points drawn as splats, without and
/// with hole filling, against the mesh reference; and the reference again with shadows.
json demo_splats(const loaded_input& mesh, const loaded_input& pts, const camera& cam,
                 const render_options& o, const image& ref, const std::string& dir,
                 progress& prog) {
  json report;
  // The samples as splats: plain, with hole filling, and blended (splat quality against the
  // mesh, not LOD).
  struct variant {
    const char* key;
    const char* png;
    const char* step;
    effects fx;
  };
  const variant variants[] = {
      {"splats", "points.png", "rendering splats", no_effects},
      {"splats_hole_filled", "points_hole_filled.png", "rendering splats with hole filling",
       effects{.colour = false, .hole_filling = true}},
      {"splats_blended", "points_blended.png", "rendering blended splats",
       effects{.colour = false, .blending = true}},
  };
  for (const variant& var : variants) {
    render_options po = o;
    po.fx = po.fx | var.fx;
    prog.step(var.step);
    const auto t0 = clock_type::now();
    const image img = render_input(pts, cam, po);
    const double secs = seconds_since(t0);
    const std::string png = (fs::path(dir) / var.png).string();
    write_png(png, img);
    json j = error_json(compare_images(ref, img));
    j.str("png", png).num("seconds", secs);
    report.object(var.key, j);
  }
  render_options so = o;
  so.fx.shadows = true;
  prog.step("rendering with shadows");
  const auto t0 = clock_type::now();
  const image shadowed = render_input(mesh, cam, so);
  const std::string png = (fs::path(dir) / "reference_shadows.png").string();
  write_png(png, shadowed);
  json j;
  j.str("png", png).num("seconds", seconds_since(t0));
  return report.object("shadows", j);
}

int cmd_demo(const std::string& input, const std::string& dir, bool as_json) {
  progress prog(as_json);
  fs::create_directories(dir);
  loaded_input in;
  std::string name = input;
  if (input.empty()) {
    prog.step("generating the demo scene");
    in.mesh = make_demo_scene(64);
    name = "generated demo scene";
  } else {
    prog.step("reading " + input);
    in = load(input);
  }
  json report;
  report.str("input", name).integer("vertices", static_cast<long long>(in.mesh.num_vertices()));
  report.integer("faces", static_cast<long long>(in.mesh.num_faces()));
  view_args va;
  va.size = "768x768";
  const camera cam = make_camera(in.mesh.vertices, va);
  render_options o = make_render_options(in, va);
  o.fx.shading = true;  // a mesh has face normals; a cloud without normals falls back to flat
  o.fx.colour = !in.mesh.vertices.colours.empty();

  // 1. The full-detail reference: the mesh's triangles, or every point as its own splat.
  prog.step("rendering the full-detail reference");
  auto t0 = clock_type::now();
  const image ref = render_input(in, cam, o);
  report.num("reference_seconds", seconds_since(t0));
  const std::string ref_png = (fs::path(dir) / "reference.png").string();
  write_png(ref_png, ref);
  report.str("reference_png", ref_png);

  // 2. For a mesh: the same surface as a point cloud (one sample per vertex, at least 20,000),
  //    which the point builders build from.
  loaded_input pts;
  if (in.is_mesh()) {
    prog.step("sampling the surface into points");
    pts.mesh.vertices = sample_surface(in.mesh, demo_samples(in.mesh), 1);
    report.integer("samples", static_cast<long long>(pts.mesh.num_vertices()));
    report.merge(demo_splats(in, pts, cam, o, ref, dir, prog));
  }
  // 3. Every builder this version has, built with its defaults (the point builders from the
  //    points, the mesh builders from the mesh), drawn from the same camera at its demo
  //    tolerances and compared with the full-detail reference.
  const build_input mesh_in(in, name);
  const build_input points_in =
      in.is_mesh() ? build_input(std::move(pts), name + " (sampled points)") : mesh_in;
  std::vector<std::vector<sheet_tile>> sheet;
  std::vector<demo_row> table;
  json builders;
  for (const method_entry& m : methods()) {
    if (!m.build) continue;
    sheet.emplace_back();
    builders.object(m.name, demo_method(m, m.builds_from_mesh ? mesh_in : points_in, cam, va, ref,
                                        dir, prog, sheet.back(), table));
  }
  report.object("builders", builders);
  const std::string sheet_png = (fs::path(dir) / "contact_sheet.png").string();
  prog.step("writing the contact sheet");
  write_png(sheet_png, contact_sheet(sheet));
  report.str("contact_sheet_png", sheet_png);
  if (as_json) {
    std::cout << report.text() << "\n";
  } else {
    std::cout << "pbrlod demo: " << name << " (" << in.mesh.num_vertices() << " points, "
              << in.mesh.num_faces() << " faces) -> " << dir << "/\n";
    print_demo_table(table);
    std::cout << "contact sheet: " << sheet_png << "\n";
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"pbrlod: level-of-detail hierarchies for point-based rendering (pbr_lod " +
               std::string(version()) + ")"};
  app.require_subcommand(1);
  bool as_json = false;

  std::string method, build_input, build_output;
  std::vector<std::string> params;
  auto* build = app.add_subcommand("build", "build a LOD hierarchy from a mesh or point cloud");
  std::string method_names;
  for (const auto& m : methods()) method_names += (method_names.empty() ? "" : ", ") + m.name;
  build->add_option("--method", method, method_names)->required();
  build
      ->add_option("--param", params,
                   "k=v builder parameter (repeatable); memory=SIZE (K/M/G/T) or chunk_points=N "
                   "build out of core into a folder, memory being the whole build's budget "
                   "(docs/scale.md)")
      ->allow_extra_args(false)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  build->add_option("input", build_input, "mesh or point cloud file")->required();
  build->add_option("-o,--output", build_output, "hierarchy file to write (.lod)")->required();
  build->add_flag("--json", as_json, "print one JSON object");
  bool distributed = false;
  build->add_flag(
      "--distributed", distributed,
      "share a chunked build (point-octree, pca-octree, pmr) among MPI ranks (run under mpirun)");

  std::string render_input_path, render_output = "render.png";
  float tolerance = 1;
  view_args va;
  auto* render = app.add_subcommand("render", "render a hierarchy or an input file (full detail)");
  render->add_option("input", render_input_path, "OUT.lod or a mesh/point cloud file")->required();
  render->add_option("-o,--output", render_output, "PNG to write")->capture_default_str();
  std::string tolerance_help = "what a hierarchy's cut is drawn at; per method:";
  for (const auto& m : methods()) tolerance_help += "\n  " + m.name + ": " + m.tolerance_means;
  render->add_option("--tolerance", tolerance, tolerance_help)->capture_default_str();
  std::uint64_t seed = 1;
  render->add_option("--seed", seed, "random stream of methods that generate points (pca-octree)")
      ->capture_default_str();
  add_view_options(render, va);
  const std::string lowpass_help =
      "gaussian-hierarchy: square pixels added to the large axes of each merged Gaussian the cut "
      "draws (0: as stored, the paper's; docs/gaussian-hierarchy.md)";
  render->add_option("--merged-lowpass", va.merged_lowpass, lowpass_help)
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  render->add_flag("--json", as_json, "print one JSON object");

  std::string stats_input;
  auto* stats = app.add_subcommand("stats", "statistics of a hierarchy or an input file");
  stats->add_option("input", stats_input, "OUT.lod or a mesh/point cloud file")->required();
  stats->add_flag("--json", as_json, "print one JSON object");

  std::string export_input, export_output, export_format = "auto", export_crs,
                                           export_coarse = "samples";
  int export_level = -1;
  std::uint32_t export_node_points = pbr_lod::copc_options{}.node_points;
  auto* exporter = app.add_subcommand(
      "export",
      "write a Gaussian hierarchy's cut (a view and tolerance, or a level) as a 3DGS PLY, or a "
      "point hierarchy's levels as COPC (a LAZ 1.4 octree other tools open)");
  exporter->add_option("input", export_input, "a hierarchy (.lod or chunked folder)")->required();
  exporter->add_option("-o,--output", export_output, "the .ply or .copc.laz to write")->required();
  exporter
      ->add_option("--format", export_format,
                   "ply (a Gaussian hierarchy's cut) or copc (a point hierarchy's levels); auto: "
                   "copc when the output ends in .laz")
      ->check(CLI::IsMember({"auto", "ply", "copc"}))
      ->capture_default_str();
  exporter
      ->add_option("--coarse-points", export_coarse,
                   "copc: what an inner node stores: its subtree's sample nearest its "
                   "representative (samples: every point lies on the input), or the "
                   "representative itself (representatives: the hierarchy's own nodes)")
      ->check(CLI::IsMember({"samples", "representatives"}))
      ->capture_default_str();
  exporter->add_option("--crs-from", export_crs,
                       "copc: a LAS/LAZ file whose spatial reference (WKT) the output carries");
  exporter
      ->add_option("--node-points", export_node_points,
                   "copc: the mean points per octree node that chooses how hierarchy levels map "
                   "onto COPC levels")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  exporter->add_option("--tolerance", tolerance, "pixels (as render --tolerance)")
      ->capture_default_str();
  exporter
      ->add_option("--level", export_level,
                   "a view-independent cut: every node at this tree depth (and the leaves "
                   "above it) instead of the view's cut")
      ->check(CLI::NonNegativeNumber);
  add_view_options(exporter, va);
  exporter->add_option("--merged-lowpass", va.merged_lowpass, lowpass_help)
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  exporter->add_flag("--json", as_json, "print one JSON object");

  std::string cmp_a, cmp_b;
  auto* compare = app.add_subcommand("compare", "image error of B against reference A");
  compare->add_option("reference", cmp_a, "reference PNG")->required();
  compare->add_option("test", cmp_b, "PNG to compare")->required();
  compare->add_flag("--json", as_json, "print one JSON object");

  std::string demo_input, demo_dir = "pbrlod-demo";
  auto* demo = app.add_subcommand("demo", "render a generated scene (or INPUT) and report");
  demo->add_option("input", demo_input, "optional mesh or point cloud file");
  demo->add_option("-o,--output", demo_dir, "folder for the images")->capture_default_str();
  demo->add_flag("--json", as_json, "print one JSON object");

  std::vector<std::string> sweep_inputs;
  std::string sweep_dir = "pbrlod-sweep", sweep_size = "small";
  bool sweep_check = false;
  auto* sweep = app.add_subcommand(
      "sweep", "every builder over the same inputs, views and tolerances: sweep.csv, sweep.json");
  sweep->add_option("inputs", sweep_inputs,
                    "mesh or point cloud files (default: the generated scene; with --size full "
                    "the scans in PBR_LOD_DATA and a large generated scene)");
  sweep->add_option("-o,--output", sweep_dir, "folder for the results")->capture_default_str();
  sweep->add_option("--size", sweep_size, "small (seconds: 3 views, 128 px) or full")
      ->check(CLI::IsMember({"small", "full"}))
      ->capture_default_str();
  sweep->add_flag("--check", sweep_check,
                  "exit 1 when a builder has no rows or a series' error grows as its tolerance "
                  "tightens");
  sweep->add_flag("--json", as_json, "print one JSON object");

  std::string papers_data, papers_dir = "docs/data/papers", papers_out = "pbrlod-papers",
                           papers_view = "30,20,3";
  int papers_repeats = 3;
  auto* papers = app.add_subcommand(
      "papers",
      "the papers' own curves (PMR Table 2, POP Fig. 6, SPG Table 1, Pajarola Fig. 1) "
      "beside our measured analogue");
  papers->add_option("--data", papers_data,
                     "folder with happy_vrip_res3.ply and bun_zipper.ply "
                     "(default: $PBR_LOD_DATA)");
  papers->add_option("--papers", papers_dir, "the transcribed tables")->capture_default_str();
  papers->add_option("-o,--output", papers_out, "folder for the results")->capture_default_str();
  papers->add_option("--view", papers_view, "AZ,EL,DIST (distance in radii)")
      ->capture_default_str();
  papers->add_option("--repeats", papers_repeats, "frames timed (the median)")
      ->capture_default_str();

  // One build of a sweep in a process of its own (child_build.hpp); not for users: no group.
  std::string sb_method, sb_input, sb_output;
  int sb_touch_mib = 0;
  auto* sweep_build = app.add_subcommand("sweep-build", "");
  sweep_build->group("");
  sweep_build->add_option("--method", sb_method);
  sweep_build->add_option("--input", sb_input);
  sweep_build->add_option("--out", sb_output);
  sweep_build->add_option("--touch-mib", sb_touch_mib);

  CLI11_PARSE(app, argc, argv);
  try {
    if (*build && distributed)
      return cmd_build_distributed(method, build_input, build_output, params, as_json);
    if (*build) return cmd_build(method, build_input, build_output, params, as_json);
    if (*render) return cmd_render(render_input_path, va, tolerance, render_output, as_json, seed);
    if (*stats) return cmd_stats(stats_input, as_json);
    if (*exporter && is_copc_export(export_format, export_output))
      return cmd_export_copc(export_input, export_output, export_crs, export_node_points,
                             export_coarse == "samples", as_json);
    if (*exporter)
      return cmd_export(export_input, va, tolerance,
                        export_level >= 0 ? std::optional<int>(export_level) : std::nullopt,
                        export_output, as_json);
    if (*compare) return cmd_compare(cmp_a, cmp_b, as_json);
    if (*demo) return cmd_demo(demo_input, demo_dir, as_json);
    if (*sweep) return cmd_sweep(sweep_inputs, sweep_dir, sweep_size, sweep_check, as_json);
    if (*papers)
      return cmd_papers(papers_data, papers_dir, papers_out, papers_view, papers_repeats);
    if (*sweep_build) return cmd_sweep_build(sb_method, sb_input, sb_output, sb_touch_mib);
  } catch (const pbr_lod::Error& e) {
    std::cerr << "pbrlod: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "pbrlod: unexpected error: " << e.what() << "\n";
    return 1;
  }
  return 2;
}
