// gl_viewer — the two places an OpenGL 3.3 core context comes from: a headless EGL context with
// an offscreen framebuffer (contexts_egl.cpp), and a GLFW window (main.cpp).
#pragma once

#include <memory>

namespace gl_viewer {

/// A current OpenGL 3.3 core context without a window: EGL on Mesa's surfaceless platform
/// (llvmpipe when there is no GPU), rendering into a framebuffer object of w×h pixels (RGBA8,
/// 32-bit float depth) that stays bound. Throws std::runtime_error naming the EGL step that
/// failed.
class headless_context {
 public:
  headless_context(int width, int height);
  ~headless_context();
  headless_context(const headless_context&) = delete;
  headless_context& operator=(const headless_context&) = delete;
  /// "OpenGL <version> on <renderer>".
  [[nodiscard]] const char* description() const;

 private:
  struct impl;
  std::unique_ptr<impl> d_;
};

}  // namespace gl_viewer
