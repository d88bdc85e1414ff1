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

/// The target without trailing separators; InvalidArgument when it names no folder of its own.
std::string folder_name(const std::string& target) {
  std::string t = target;
  while (t.size() > 1 && t.back() == '/') t.pop_back();
  const std::string leaf = std::filesystem::path(t).filename().string();
  if (leaf.empty() || leaf == "." || leaf == ".." || t == "/")
    throw InvalidArgument("'" + target + "': name the output folder (not '.', '..' or '/')");
  return t;
}

/// fsync of every file under `dir`, then of its folders; returns errno, 0 on success.
int sync_tree(const std::string& dir) {
  std::error_code ec;
  for (auto it = std::filesystem::recursive_directory_iterator(dir, ec);
       !ec && it != std::filesystem::recursive_directory_iterator(); it.increment(ec)) {
    const bool folder = it->is_directory(ec);
    if (const int e = sync_path(it->path().string(), folder)) return e;
  }
  if (ec) return ec.value();
  return sync_path(dir, true);
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

atomic_directory::atomic_directory(const std::string& target, bool owner)
    : target_(folder_name(target)), staging_(target_ + ".partial"), owner_(owner) {}

atomic_directory::~atomic_directory() {
  if (owner_ && !done_) {
    std::error_code ec;
    std::filesystem::remove_all(staging_, ec);  // best effort: a destructor cannot throw
  }
}

void atomic_directory::create() {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::remove_all(staging_, ec);
  if (ec)
    throw IoError(staging_ + ": cannot remove an interrupted build's folder: " + ec.message());
  if (!fs::create_directory(staging_, ec) || ec)
    throw IoError(staging_ + ": cannot create: " + (ec ? ec.message() : "it exists"));
  const std::string note =
      "An unfinished build of " + target_ +
      ": the process writing it failed or was killed before it finished. Remove this folder.\n";
  write_file_atomically((fs::path(staging_) / atomic_directory_marker).string(), note.data(),
                        note.size());
}

void atomic_directory::commit() {
  namespace fs = std::filesystem;
  if (done_) return;
  std::error_code ec;
  const bool replaces = fs::exists(fs::symlink_status(target_, ec));
  if (!fs::remove(fs::path(staging_) / atomic_directory_marker, ec) || ec)
    throw IoError(target_ + ": the marker in " + staging_ +
                  " cannot be removed: " + (ec ? ec.message() : "it is missing"));
  if (!replaces) {
    if (std::rename(staging_.c_str(), target_.c_str()) != 0)
      fail(target_, "renaming " + staging_ + " to it", errno);
  } else {
    // The new files reach the disk before the old folder goes: not even a power loss leaves the
    // target without one of the two.
    if (const int e = sync_tree(staging_)) fail(target_, "flushing " + staging_, e);
    if (::renameat2(AT_FDCWD, staging_.c_str(), AT_FDCWD, target_.c_str(), RENAME_EXCHANGE) != 0) {
      if (errno != EINVAL && errno != ENOSYS)
        fail(target_, "swapping " + staging_ + " with it", errno);
      // No exchange on this file system: the old folder aside, the new one in, the old removed.
      const std::string aside = target_ + ".replaced";
      fs::remove_all(aside, ec);
      if (std::rename(target_.c_str(), aside.c_str()) != 0)
        fail(target_, "renaming it to " + aside, errno);
      if (std::rename(staging_.c_str(), target_.c_str()) != 0) {
        const int e = errno;
        (void)std::rename(aside.c_str(), target_.c_str());
        fail(target_, "renaming " + staging_ + " to it", e);
      }
      fs::remove_all(aside, ec);
    } else {
      fs::remove_all(staging_, ec);  // now the old folder
    }
  }
  done_ = true;
  const fs::path parent = fs::path(target_).parent_path();
  (void)sync_path(parent.empty() ? std::string(".") : parent.string(), true);
}

bool is_unfinished_directory(const std::string& dir) {
  std::error_code ec;
  return std::filesystem::is_directory(dir, ec) &&
         std::filesystem::exists(std::filesystem::path(dir) / atomic_directory_marker, ec);
}

void write_file_atomically(const std::string& path, const void* data, std::size_t size) {
  write_file_atomically(path, [&](const auto& write) { write(data, size); });
}

void write_file_atomically(
    const std::string& path,
    const std::function<void(const std::function<void(const void*, std::size_t)>&)>& produce) {
  atomic_output out(path);
  const int fd = ::open(out.temp_path().c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
  if (fd < 0) fail(path, "opening " + out.temp_path() + " for writing", errno);
  const auto write = [&](const void* data, std::size_t size) {
    const auto* p = static_cast<const unsigned char*>(data);
    std::size_t left = size;
    while (left > 0) {
      const ssize_t n = ::write(fd, p, left);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) fail(path, "writing", n < 0 ? errno : EIO);  // the fd is closed below
      p += n;
      left -= static_cast<std::size_t>(n);
    }
  };
  try {
    produce(write);
  } catch (...) {
    ::close(fd);
    throw;
  }
  if (::close(fd) != 0) fail(path, "closing " + out.temp_path(), errno);
  out.commit();
}

}  // namespace pbr_lod
