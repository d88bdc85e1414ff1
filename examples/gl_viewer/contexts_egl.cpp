// gl_viewer — the headless context (contexts.hpp). EGL, not OSMesa: Debian 12's Mesa gives a
// 4.5 core profile on llvmpipe through EGL_MESA_platform_surfaceless with no display server and
// no extra package beyond libegl-dev (libegl-mesa0 is the driver), and the same GL entry points
// (libOpenGL) serve the windowed and the headless path; OSMesa would be a second GL library.
#define GL_GLEXT_PROTOTYPES 1
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GL/glcorearb.h>

#include <cstdio>
#include <stdexcept>
#include <string>

#include "contexts.hpp"

namespace gl_viewer {

struct headless_context::impl {
  EGLDisplay display = EGL_NO_DISPLAY;
  EGLContext context = EGL_NO_CONTEXT;
  GLuint fbo = 0, colour = 0, depth = 0;
  std::string description;
};

namespace {
[[noreturn]] void fail(const char* step) {
  char code[16];
  std::snprintf(code, sizeof code, "0x%04x", static_cast<unsigned>(eglGetError()));
  throw std::runtime_error(std::string("gl_viewer --headless: ") + step + " failed (EGL error " +
                           code +
                           "); needs Mesa's EGL (libegl-mesa0) with the surfaceless platform");
}
}  // namespace

headless_context::headless_context(int width, int height) : d_(std::make_unique<impl>()) {
  const auto get_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(
      eglGetProcAddress("eglGetPlatformDisplayEXT"));
  if (!get_display) fail("eglGetPlatformDisplayEXT");
  d_->display = get_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
  if (d_->display == EGL_NO_DISPLAY) fail("the surfaceless EGL display");
  EGLint major = 0, minor = 0;
  if (!eglInitialize(d_->display, &major, &minor)) fail("eglInitialize");
  if (!eglBindAPI(EGL_OPENGL_API)) fail("eglBindAPI(OpenGL)");
  const EGLint attributes[] = {EGL_CONTEXT_MAJOR_VERSION,
                               3,
                               EGL_CONTEXT_MINOR_VERSION,
                               3,
                               EGL_CONTEXT_OPENGL_PROFILE_MASK,
                               EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                               EGL_NONE};
  // No config and no surface (EGL_KHR_no_config_context, EGL_KHR_surfaceless_context): the
  // frame goes to a framebuffer object.
  d_->context = eglCreateContext(d_->display, EGL_NO_CONFIG_KHR, EGL_NO_CONTEXT, attributes);
  if (d_->context == EGL_NO_CONTEXT) fail("eglCreateContext (OpenGL 3.3 core)");
  if (!eglMakeCurrent(d_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, d_->context))
    fail("eglMakeCurrent");
  d_->description = std::string("OpenGL ") +
                    reinterpret_cast<const char*>(glGetString(GL_VERSION)) + " on " +
                    reinterpret_cast<const char*>(glGetString(GL_RENDERER));

  glGenFramebuffers(1, &d_->fbo);
  glBindFramebuffer(GL_FRAMEBUFFER, d_->fbo);
  glGenRenderbuffers(1, &d_->colour);
  glBindRenderbuffer(GL_RENDERBUFFER, d_->colour);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, width, height);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, d_->colour);
  glGenRenderbuffers(1, &d_->depth);
  glBindRenderbuffer(GL_RENDERBUFFER, d_->depth);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT32F, width, height);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, d_->depth);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    throw std::runtime_error("gl_viewer --headless: the offscreen framebuffer is incomplete");
}

headless_context::~headless_context() {
  glDeleteFramebuffers(1, &d_->fbo);
  glDeleteRenderbuffers(1, &d_->colour);
  glDeleteRenderbuffers(1, &d_->depth);
  eglMakeCurrent(d_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  eglDestroyContext(d_->display, d_->context);
  eglTerminate(d_->display);
}

const char* headless_context::description() const {
  return d_->description.c_str();
}

}  // namespace gl_viewer
