// pbrlod sweep — each build in a child process of its own, so that its peak resident memory
// can be measured (child_build.cpp).
//
// Why a fresh process (posix_spawn of this executable), read from the child's own VmHWM: the
// sweep process holds every input, reference image and hierarchy, and its high-water mark
// cannot go down, so in-process numbers would mix builds. A forked child (with or without
// exec) would not do either: Linux's rusage ru_maxrss of a child keeps the high-water mark of
// the memory it started with (fork copies the parent's page tables; exec records the old
// mm's peak into the child's maxrss), so a large sweep process would inflate every build. The
// VmHWM of /proc/self/status is per address space and starts afresh at exec.
#pragma once

#include <memory>
#include <string>

#include "lod.hpp"

namespace pbrlod_tool {

/// A sweep input the child can produce on its own: a file path, "generated:N" for
/// make_demo_scene(N), or "generated-hard:N" for make_hard_cases_scene(N).
loaded_input load_sweep_input(const std::string& spec);

/// What a child build reports.
struct child_build {
  std::unique_ptr<lod> l;  ///< loaded from the file the child saved; empty when skipped
  std::string skipped;     ///< the builder's InvalidArgument message, when it cannot build
  double build_seconds = 0, build_cpu_seconds = 0;  ///< wall and CPU (user + system) time
  double peak_mib = 0;          ///< the child's VmHWM: the program, the input and the build
  double before_build_mib = 0;  ///< its VmRSS once the input was loaded, before the build
};

/// Builds method `m` (default options) from `spec` in a child process, which saves the
/// hierarchy to `scratch` (removed again here once loaded back). Point builders get a mesh's
/// vertices, as the sweep gives them. Throws IoError when the child cannot be started or fails.
child_build build_in_child(const method_entry& m, const std::string& spec,
                           const std::string& scratch);

/// The child side (`pbrlod sweep-build`, not listed in --help): loads `spec`, touches
/// `touch_mib` MiB first when > 0 (the measurement's test), builds `method` (none: nothing)
/// and saves it to `out`, then prints `key value` lines: build_seconds, build_cpu_seconds,
/// before_build_mib, peak_mib (or `skipped <message>`).
int cmd_sweep_build(const std::string& method, const std::string& spec, const std::string& out,
                    int touch_mib);

}  // namespace pbrlod_tool
