// gl_viewer — an OpenGL 3.3 core host renderer for pbr_lod (docs/gl_viewer.md).
//
//   gl_viewer [FILE] [--method NAME [--param k=v]...] [--view AZ,EL,DIST] [--tolerance PX]
//             [--size WxH] [--effects LIST] [--up y|z] [--seed N]
//             [--headless -o OUT.png [--cpu CPU.png] [--json]]
//
// FILE is a .lod file or an input (mesh or point cloud; drawn at full detail, as `pbrlod render
// INPUT`); without FILE, the generated scene of `pbrlod demo`. --method builds FILE first (as
// `pbrlod build`). --view, --tolerance, --size, --effects, --up and --seed mean what they mean
// to `pbrlod render`. Window: drag with the left button to orbit (azimuth, elevation), the wheel
// to zoom (distance), +/- to change the tolerance, Esc to quit; the title shows the tolerance,
// the primitives drawn and the frame time. --headless: one frame offscreen (EGL), written to
// OUT.png; --cpu also writes the CPU rasteriser's image of the same cut and, with --json,
// prints how the two differ (PSNR, holes, extra pixels, SSIM).
//
// Exit codes: 0 success, 1 bad input or a failed OpenGL set-up (message on stderr), 2 usage.
#include <CLI/CLI.hpp>

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <sstream>

#include "contexts.hpp"
#include "gl_renderer.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/png.hpp"
#include "scene.hpp"

namespace {
using namespace gl_viewer;

struct options {
  std::string file, method, output, cpu_output;
  std::vector<std::string> params;
  frame_settings frame;
  bool headless = false, as_json = false;
};

/// Effects the GL renderer does not draw: said once, not silently dropped.
void warn_unsupported(const pbr_lod::render_options& o) {
  if (o.fx.shadows || o.fx.hole_filling)
    std::cerr << "gl_viewer: shadows and hole filling are drawn by the CPU rasteriser only; the "
                 "OpenGL image leaves them out\n";
}

int run_headless(const options& opt, const scene& sc) {
  if (opt.output.empty()) {
    std::cerr << "gl_viewer: --headless needs -o OUT.png\n";
    return 2;
  }
  const auto sz = pbrlod_tool::parse_numbers(opt.frame.view.size, 'x', 2, "--size");
  headless_context ctx(static_cast<int>(sz[0]), static_cast<int>(sz[1]));
  gl_renderer gl;
  const selection sel = sc.draw(gl, opt.frame);
  const double gl_seconds = gl.draw();
  const pbr_lod::image img = gl.read_image();
  pbr_lod::write_png(opt.output, img);
  pbrlod_tool::json j;
  j.str("input", sc.name()).str("output", opt.output).str("context", ctx.description());
  j.num(sc.tolerance_key(), opt.frame.tolerance);
  j.integer("points", static_cast<long long>(gl.counts().points));
  j.integer("splats", static_cast<long long>(gl.counts().splats));
  j.integer("triangles", static_cast<long long>(gl.counts().triangles));
  j.integer("gaussians", static_cast<long long>(gl.counts().gaussians));
  j.integer("covered_pixels", static_cast<long long>(img.covered_count()));
  j.num("select_seconds", sel.seconds).num("gl_seconds", gl_seconds);
  if (!opt.cpu_output.empty()) {
    const pbr_lod::image cpu = sc.draw_cpu(opt.frame);
    pbr_lod::write_png(opt.cpu_output, cpu);
    const pbr_lod::image_error e = pbr_lod::compare_images(cpu, img);
    // Pixels the GL image covers and the CPU image does not (compare_images counts the other
    // way round as holes).
    const std::size_t extra = e.covered_either - e.reference_covered;
    pbrlod_tool::json c;
    c.num("psnr", e.psnr).num("rmse", e.rmse).num("ssim", pbr_lod::ssim(cpu, img));
    c.integer("cpu_covered", static_cast<long long>(e.reference_covered));
    c.integer("holes", static_cast<long long>(e.holes));
    c.integer("extra", static_cast<long long>(extra));
    c.str("cpu_output", opt.cpu_output);
    j.object("vs_cpu", c);
  }
  if (opt.as_json)
    std::cout << j.text() << "\n";
  else
    std::cout << "wrote " << opt.output << " (" << gl.counts().total() << " primitives, "
              << ctx.description() << ")\n";
  return 0;
}

// ---- the window

struct window_state {
  const scene* sc = nullptr;
  options* opt = nullptr;
  gl_renderer* gl = nullptr;
  double az = 30, el = 20, dist = 3;
  bool dragging = false, dirty = true;
  double last_x = 0, last_y = 0;
};

void apply_view(window_state& s, int width, int height) {
  std::ostringstream v;
  v.precision(10);
  v << s.az << "," << s.el << "," << s.dist;
  s.opt->frame.view.view = v.str();
  s.opt->frame.view.size =
      std::to_string(std::max(width, 1)) + "x" + std::to_string(std::max(height, 1));
}

window_state& state_of(GLFWwindow* w) {
  return *static_cast<window_state*>(glfwGetWindowUserPointer(w));
}

void on_key(GLFWwindow* w, int key, int, int action, int) {
  if (action != GLFW_PRESS && action != GLFW_REPEAT) return;
  window_state& s = state_of(w);
  float& tol = s.opt->frame.tolerance;
  if (key == GLFW_KEY_EQUAL || key == GLFW_KEY_KP_ADD || key == GLFW_KEY_RIGHT_BRACKET) {
    tol = std::min(tol * 1.25f, 1e4f);
    s.dirty = true;
  } else if (key == GLFW_KEY_MINUS || key == GLFW_KEY_KP_SUBTRACT || key == GLFW_KEY_LEFT_BRACKET) {
    tol = std::max(tol / 1.25f, 0.01f);
    s.dirty = true;
  } else if (key == GLFW_KEY_ESCAPE || key == GLFW_KEY_Q) {
    glfwSetWindowShouldClose(w, GLFW_TRUE);
  }
}

void on_button(GLFWwindow* w, int button, int action, int) {
  window_state& s = state_of(w);
  if (button != GLFW_MOUSE_BUTTON_LEFT) return;
  s.dragging = action == GLFW_PRESS;
  glfwGetCursorPos(w, &s.last_x, &s.last_y);
}

void on_cursor(GLFWwindow* w, double x, double y) {
  window_state& s = state_of(w);
  if (!s.dragging) return;
  s.az -= 0.3 * (x - s.last_x);
  s.el = std::clamp(s.el + 0.3 * (y - s.last_y), -89.0, 89.0);
  s.last_x = x;
  s.last_y = y;
  s.dirty = true;
}

void on_scroll(GLFWwindow* w, double, double dy) {
  window_state& s = state_of(w);
  s.dist = std::clamp(s.dist * std::pow(0.9, dy), 1.05, 1e3);
  s.dirty = true;
}

int run_window(options& opt, const scene& sc) {
  const auto sz = pbrlod_tool::parse_numbers(opt.frame.view.size, 'x', 2, "--size");
  const auto v = pbrlod_tool::parse_numbers(opt.frame.view.view, ',', 3, "--view");
  if (!glfwInit()) {
    std::cerr << "gl_viewer: no window system (GLFW could not start); use --headless -o OUT.png\n";
    return 1;
  }
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  GLFWwindow* w = glfwCreateWindow(static_cast<int>(sz[0]), static_cast<int>(sz[1]), "gl_viewer",
                                   nullptr, nullptr);
  if (!w) {
    glfwTerminate();
    std::cerr << "gl_viewer: no OpenGL 3.3 core window; use --headless -o OUT.png\n";
    return 1;
  }
  glfwMakeContextCurrent(w);
  glfwSwapInterval(1);
  int status = 0;
  try {
    gl_renderer gl;
    window_state s{.sc = &sc, .opt = &opt, .gl = &gl, .az = v[0], .el = v[1], .dist = v[2]};
    glfwSetWindowUserPointer(w, &s);
    glfwSetKeyCallback(w, on_key);
    glfwSetMouseButtonCallback(w, on_button);
    glfwSetCursorPosCallback(w, on_cursor);
    glfwSetScrollCallback(w, on_scroll);
    glfwSetFramebufferSizeCallback(w,
                                   [](GLFWwindow* win, int, int) { state_of(win).dirty = true; });
    while (!glfwWindowShouldClose(w)) {
      if (s.dirty) {
        int fw = 0, fh = 0;
        glfwGetFramebufferSize(w, &fw, &fh);
        apply_view(s, fw, fh);
        const selection sel = sc.draw(gl, opt.frame);
        const double gpu = gl.draw();
        glfwSwapBuffers(w);
        char title[512];
        std::snprintf(title, sizeof title,
                      "gl_viewer %s | %s %.3g | %zu points, %zu splats, %zu triangles | select "
                      "%.1f ms, draw %.1f ms",
                      sc.name().c_str(), sc.tolerance_key().c_str(),
                      static_cast<double>(opt.frame.tolerance), gl.counts().points,
                      gl.counts().splats, gl.counts().triangles, 1e3 * sel.seconds, 1e3 * gpu);
        glfwSetWindowTitle(w, title);
        s.dirty = false;
      }
      glfwWaitEvents();
    }
  } catch (...) {
    glfwDestroyWindow(w);
    glfwTerminate();
    throw;
  }
  glfwDestroyWindow(w);
  glfwTerminate();
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"gl_viewer: an OpenGL 3.3 host renderer for pbr_lod hierarchies"};
  options opt;
  app.add_option("file", opt.file,
                 "a .lod file, or a mesh / point cloud (full detail); none: the generated demo "
                 "scene");
  app.add_option("--method", opt.method, "build FILE with this method first (as pbrlod build)");
  app.add_option("--param", opt.params, "k=v builder parameter of --method (repeatable)");
  app.add_option("--view", opt.frame.view.view,
                 "AZ,EL,DIST: azimuth and elevation in degrees around the model's bounding-sphere "
                 "centre, distance in radii")
      ->capture_default_str();
  app.add_option("--size", opt.frame.view.size, "WxH window / image size in pixels")
      ->capture_default_str();
  app.add_option("--up", opt.frame.view.up, "up axis: y (scans) or z (LiDAR)")
      ->check(CLI::IsMember({"y", "z"}))
      ->capture_default_str();
  app.add_option("--effects", opt.frame.view.effects_list,
                 "as pbrlod render: shading, colour, backface_cull, blending (the default blends "
                 "splats and points; shadows and hole_filling are CPU-only)");
  app.add_option("--tolerance", opt.frame.tolerance, "the method's tolerance, as pbrlod render")
      ->capture_default_str();
  app.add_option("--seed", opt.frame.seed, "random stream of methods that generate points")
      ->capture_default_str();
  app.add_flag("--headless", opt.headless, "render one frame offscreen (EGL) to -o");
  app.add_option("-o,--output", opt.output, "PNG the headless frame is written to");
  app.add_option("--cpu", opt.cpu_output,
                 "headless: also write the CPU rasteriser's image of the same cut, and compare");
  app.add_flag("--json", opt.as_json, "headless: print one JSON object");
  CLI11_PARSE(app, argc, argv);
  try {
    const scene sc(opt.file, opt.method, opt.params);
    warn_unsupported(pbrlod_tool::lod_render_options(opt.frame.view, true));
    return opt.headless ? run_headless(opt, sc) : run_window(opt, sc);
  } catch (const pbr_lod::Error& e) {
    std::cerr << "gl_viewer: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "gl_viewer: " << e.what() << "\n";
    return 1;
  }
}
