// pbr_lod — outputs that appear whole or not at all. A file is written under a temporary name
// beside its target (the same directory, so the final rename stays on one file system), flushed
// to disk, and renamed over the target only once complete: a write that fails (disk full, a
// file-size limit) or a process killed mid-write leaves the previous file byte for byte, and
// nothing partial under the target's name. A folder (a chunked build's) is built the same way
// under a sibling name and renamed onto its target once complete (atomic_directory).
#pragma once

#include <cstddef>
#include <functional>
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

/// One output folder in the making: written under a sibling name, `<target>.partial`, and renamed
/// onto the target only when complete. A build that fails or is killed leaves the previous
/// folder as it was (byte for byte) and nothing partial under the target's name.
///
///   atomic_directory out(dir, true);
///   out.create();
///   write_files_into(out.staging_path());
///   out.commit();
///
/// Several processes may write into one folder (a distributed build's ranks): the staging name
/// depends only on the target, so each finds it; one of them, the owner, creates it (after the
/// others wait for it) and commits or removes it. Two builds into the same target at once are not
/// supported: the second's create() removes the first's staging folder.
///
/// While it is being built the folder holds a marker file (atomic_directory_marker), removed
/// just before the rename: a folder that holds it is an unfinished build, whatever its
/// name (is_unfinished_directory).
class atomic_directory {
 public:
  /// `target`: the folder to produce (trailing '/' ignored; "." and ".." are refused with
  /// InvalidArgument). `owner`: this process creates, commits and on failure removes the staging
  /// folder; the others only write into it.
  atomic_directory(const std::string& target, bool owner);
  ~atomic_directory();
  atomic_directory(const atomic_directory&) = delete;
  atomic_directory& operator=(const atomic_directory&) = delete;

  [[nodiscard]] const std::string& target() const { return target_; }
  [[nodiscard]] const std::string& staging_path() const { return staging_; }
  /// (Owner.) Removes a staging folder an interrupted build left and makes an empty one holding
  /// the marker. Throws IoError naming it when it cannot.
  void create();
  /// (Owner.) Renames the staging folder onto the target. An existing target is replaced: the
  /// new files are flushed to disk first (fsync), the two folders swapped in one step
  /// (renameat2 RENAME_EXCHANGE) and the old one removed; on a file system without that
  /// exchange the old folder is first renamed aside to `<target>.replaced`, and is found there
  /// should the process die between the two renames. Throws IoError naming the target when a
  /// step fails; the target is then unchanged.
  void commit();

 private:
  std::string target_, staging_;
  bool owner_, done_ = false;
};

/// Name of the marker file inside an unfinished atomic_directory.
inline constexpr const char* atomic_directory_marker = ".pbr_lod-in-progress";

/// Whether `dir` is a folder an unfinished atomic_directory left (it holds the marker).
[[nodiscard]] bool is_unfinished_directory(const std::string& dir);

/// Writes `size` bytes at `data` to `path` whole or not at all (atomic_output); throws IoError
/// naming the file and the reason (e.g. "File too large") when it cannot.
void write_file_atomically(const std::string& path, const void* data, std::size_t size);
/// The same for a file made in pieces: produce(write) calls write(data, size) for each piece in
/// order, so that a large file is never held in memory whole.
void write_file_atomically(
    const std::string& path,
    const std::function<void(const std::function<void(const void*, std::size_t)>&)>& produce);

}  // namespace pbr_lod
