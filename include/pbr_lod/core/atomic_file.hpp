// pbr_lod — outputs that appear whole or not at all. A file is written under a temporary name
// beside its target (the same directory, so the final rename stays on one file system), flushed
// to disk, and renamed over the target only once complete: a write that fails (disk full, a
// file-size limit) or a process killed mid-write leaves the previous file byte for byte, and
// nothing partial under the target's name.
#pragma once

#include <cstddef>
#include <string>

namespace pbr_lod {

/// One output file in the making. Write to temp_path(), then commit(); destroyed without
/// commit() (an exception on the way), the temporary file is removed and the target untouched.
///
///   atomic_output out(path);
///   write_everything(out.temp_path());
///   out.commit();
///
/// The temporary name is `<target>.partial-<pid>-<n>`: a process killed before commit() leaves
/// that file, never a partial target. Not thread-safe per object; distinct objects are.
class atomic_output {
 public:
  explicit atomic_output(std::string target);
  ~atomic_output();
  atomic_output(const atomic_output&) = delete;
  atomic_output& operator=(const atomic_output&) = delete;

  [[nodiscard]] const std::string& temp_path() const { return temp_; }
  [[nodiscard]] const std::string& target() const { return target_; }
  /// Renames the temporary file over the target; when that replaces an existing file, the new
  /// data is flushed to disk first (fsync) and the directory after. Throws IoError naming the
  /// target when any step fails; the target is then unchanged and the temporary file removed.
  void commit();

 private:
  std::string target_, temp_;
  bool done_ = false;
};

/// Writes `size` bytes at `data` to `path` whole or not at all (atomic_output); throws IoError
/// naming the file and the reason (e.g. "File too large") when it cannot.
void write_file_atomically(const std::string& path, const void* data, std::size_t size);

}  // namespace pbr_lod
