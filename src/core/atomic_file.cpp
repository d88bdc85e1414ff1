// Outputs that appear whole or not at all: see include/pbr_lod/core/atomic_file.hpp.
#include "pbr_lod/core/atomic_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <utility>

#include "pbr_lod/core/error.hpp"

namespace pbr_lod {
namespace {

std::string temp_name(const std::string& target) {
  static std::atomic<unsigned long> counter{0};
  return target + ".partial-" + std::to_string(::getpid()) + "-" + std::to_string(counter++);
}

[[noreturn]] void fail(const std::string& target, const std::string& step, int err) {
  throw IoError(target + ": " + step + " failed: " + std::strerror(err));
}

/// fsync of the file or directory at `path`; returns errno, 0 on success.
int sync_path(const std::string& path, bool directory) {
  const int fd = ::open(path.c_str(), directory ? O_RDONLY | O_DIRECTORY : O_RDONLY);
  if (fd < 0) return errno;
  const int r = ::fsync(fd) == 0 ? 0 : errno;
  ::close(fd);
  return r;
}

}  // namespace

atomic_output::atomic_output(std::string target)
    : target_(std::move(target)), temp_(temp_name(target_)) {}

atomic_output::~atomic_output() {
  if (!done_) {
    std::error_code ec;
    std::filesystem::remove(temp_, ec);  // nothing to do when it was never created
  }
}

void atomic_output::commit() {
  if (done_) return;
  // Replacing a file: its data reaches the disk before the rename, so that not even a power
  // loss can leave the target empty where the old file was. A new file (a build's scratch
  // files, most first outputs) has nothing to lose and skips the flush, which costs
  // milliseconds per file.
  std::error_code ec;
  const bool replaces = std::filesystem::exists(target_, ec);
  if (replaces)
    if (const int e = sync_path(temp_, false)) fail(target_, "flushing " + temp_, e);
  if (std::rename(temp_.c_str(), target_.c_str()) != 0)
    fail(target_, "renaming " + temp_ + " to it", errno);
  done_ = true;
  if (replaces) {  // the rename itself is durable once the directory is (best effort)
    const std::filesystem::path dir = std::filesystem::path(target_).parent_path();
    (void)sync_path(dir.empty() ? std::string(".") : dir.string(), true);
  }
}

void write_file_atomically(const std::string& path, const void* data, std::size_t size) {
  atomic_output out(path);
  const int fd = ::open(out.temp_path().c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
  if (fd < 0) fail(path, "opening " + out.temp_path() + " for writing", errno);
  const auto* p = static_cast<const unsigned char*>(data);
  std::size_t left = size;
  while (left > 0) {
    const ssize_t n = ::write(fd, p, left);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int e = n < 0 ? errno : EIO;
      ::close(fd);
      fail(path, "writing", e);
    }
    p += n;
    left -= static_cast<std::size_t>(n);
  }
  if (::close(fd) != 0) fail(path, "closing " + out.temp_path(), errno);
  out.commit();
}

}  // namespace pbr_lod
