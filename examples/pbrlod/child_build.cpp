// pbrlod sweep — builds in child processes, with their peak resident memory (child_build.hpp).
#include "child_build.hpp"

#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <vector>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/synthetic.hpp"

extern char** environ;

namespace pbrlod_tool {
namespace {

/// A field of /proc/self/status in MiB (it is given in kB); 0 where there is none.
double status_mib(const std::string& key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(key + ":", 0) == 0) return std::stod(line.substr(key.size() + 1)) / 1024.0;
  return 0;
}

double cpu_seconds() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  const auto s = [](const timeval& t) {
    return static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_usec);
  };
  return s(ru.ru_utime) + s(ru.ru_stime);
}

/// Runs this executable with `args`, returns what it printed on stdout; throws IoError when it
/// cannot start or exits with a failure.
std::string run_self(const std::vector<std::string>& args) {
  int fd[2];
  if (pipe(fd) != 0) throw IoError("sweep: pipe() failed");
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_adddup2(&fa, fd[1], STDOUT_FILENO);
  posix_spawn_file_actions_addclose(&fa, fd[0]);
  posix_spawn_file_actions_addclose(&fa, fd[1]);
  std::vector<std::string> all{"/proc/self/exe"};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  const int err = posix_spawn(&pid, "/proc/self/exe", &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  close(fd[1]);
  if (err != 0) {
    close(fd[0]);
    throw IoError("sweep: cannot start a build process (posix_spawn error " + std::to_string(err) +
                  ")");
  }
  std::string out;
  char buf[4096];
  for (ssize_t n; (n = read(fd[0], buf, sizeof buf)) != 0;) {
    if (n < 0) break;
    out.append(buf, static_cast<std::size_t>(n));
  }
  close(fd[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    throw IoError("sweep: the build process `pbrlod sweep-build " + args.front() + " ...` failed");
  return out;
}

}  // namespace

loaded_input load_sweep_input(const std::string& spec) {
  return load(spec);  // files and the generated scenes alike (tool.hpp)
}

child_build build_in_child(const method_entry& m, const std::string& spec,
                           const std::string& scratch) {
  std::istringstream out(
      run_self({"sweep-build", "--method", m.name, "--input", spec, "--out", scratch}));
  child_build b;
  std::map<std::string, double> v;
  for (std::string key; out >> key;) {
    if (key == "skipped") {
      std::getline(out >> std::ws, b.skipped);
      return b;
    }
    out >> v[key];
  }
  b.build_seconds = v["build_seconds"];
  b.build_cpu_seconds = v["build_cpu_seconds"];
  b.peak_mib = v["peak_mib"];
  b.before_build_mib = v["before_build_mib"];
  b.l = m.load(scratch);
  std::error_code ec;
  std::filesystem::remove(scratch, ec);
  std::filesystem::remove(scratch + ".build-seconds", ec);  // PMR keeps its build time beside
  return b;
}

int cmd_sweep_build(const std::string& method, const std::string& spec, const std::string& out,
                    int touch_mib) {
  std::optional<loaded_input> in;
  if (!spec.empty()) in = load_sweep_input(spec);
  std::vector<unsigned char> touched;
  if (touch_mib > 0) {
    touched.assign(static_cast<std::size_t>(touch_mib) << 20, 1);  // written: resident
    unsigned sum = 0;
    for (std::size_t i = 0; i < touched.size(); i += 4096) sum += touched[i];
    std::cout << "touched_pages " << sum << "\n";  // read back: the writes cannot be elided
  }
  const double before = status_mib("VmRSS");
  if (!method.empty()) {
    if (!in) throw InvalidArgument("sweep-build: --method needs --input");
    const auto it = std::find_if(methods().begin(), methods().end(),
                                 [&](const method_entry& e) { return e.name == method; });
    if (it == methods().end() || !it->build)
      throw InvalidArgument("sweep-build: unknown method '" + method + "'");
    // Point builders take the mesh's vertices (with their normals and colours), as in the sweep;
    // one that draws a mesh's vertices as splats from its faces takes the mesh.
    loaded_input points;
    const bool as_mesh = it->builds_from_mesh || it->splats_from_mesh || !in->is_mesh();
    if (!as_mesh) points.mesh.vertices = in->mesh.vertices;
    const build_input bi(as_mesh ? std::move(*in) : std::move(points), spec);
    in.reset();
    const double cpu0 = cpu_seconds();
    const auto t0 = clock_type::now();
    std::unique_ptr<lod> l;
    try {
      l = it->build({}, bi, false);
    } catch (const InvalidArgument& e) {
      std::cout << "skipped " << e.what() << "\n";
      return 0;
    }
    const double wall = seconds_since(t0), cpu = cpu_seconds() - cpu0;
    l->save(out);
    std::cout << "build_seconds " << wall << "\nbuild_cpu_seconds " << cpu << "\n";
  }
  std::cout << "before_build_mib " << before << "\npeak_mib " << status_mib("VmHWM") << "\n";
  return 0;
}

}  // namespace pbrlod_tool
