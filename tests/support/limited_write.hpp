// Test support: run a write in a child process under a file-size limit (RLIMIT_FSIZE), the way
// the atomic-output tests provoke a failed or killed write (core/atomic_file.hpp).
#pragma once

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstdlib>
#include <functional>
#include <string>

#include "pbr_lod/core/error.hpp"

namespace pbr_lod::test {

/// Runs `write` in a child whose files may not exceed `limit` bytes. With `ignore_signal`, the
/// write gets EFBIG (SIGXFSZ ignored) and the child exits 7 when it threw IoError naming
/// `target`, 9 on an IoError not naming it, 8 on another exception, 0 when nothing threw;
/// otherwise SIGXFSZ kills it mid-write. Returns the wait status.
inline int run_limited(std::size_t limit, bool ignore_signal, const std::string& target,
                       const std::function<void()>& write) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (ignore_signal) std::signal(SIGXFSZ, SIG_IGN);
    const rlimit r{limit, limit};
    ::setrlimit(RLIMIT_FSIZE, &r);
    int code = 0;
    try {
      write();
    } catch (const IoError& e) {
      code = std::string(e.what()).find(target) != std::string::npos ? 7 : 9;
    } catch (...) {
      code = 8;
    }
    std::_Exit(code);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  return status;
}

}  // namespace pbr_lod::test
