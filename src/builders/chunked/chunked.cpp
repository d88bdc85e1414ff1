// What every chunked build shares: the budget rule and the folder checks of builders/chunked.hpp.
#include "pbr_lod/builders/chunked.hpp"

#include <algorithm>
#include <filesystem>

#include "pbr_lod/core/atomic_file.hpp"
#include "pbr_lod/core/error.hpp"

namespace pbr_lod {

namespace fs = std::filesystem;

std::uint64_t chunk_points_for(std::uint64_t memory_bytes, std::uint64_t chunk_points,
                               const chunk_cost& cost) {
  const std::uint64_t per_chunk =
      std::max<std::uint64_t>(1, cost.bytes_per_point * std::max(1u, cost.chunks_at_once));
  const std::uint64_t n =
      chunk_points ? chunk_points : std::max<std::uint64_t>(1, memory_bytes / per_chunk);
  return std::clamp<std::uint64_t>(n, cost.least, (1u << 31) - 1);
}

std::string chunk_file(std::uint32_t c, const char* extension) {
  const std::string s = std::to_string(c);
  return "chunk-" + std::string(s.size() < 6 ? 6 - s.size() : 0, '0') + s + "." + extension;
}

bool is_chunked_folder(const std::string& dir, const detail::file_format& top) {
  std::error_code ec;
  const fs::path path = fs::path(dir) / chunked_top_file;
  if (!fs::is_directory(dir, ec) || !fs::is_regular_file(path, ec)) return false;
  const auto head = detail::load_file_prefix(path.string(), 8);
  return head.size() == 8 && std::equal(head.begin(), head.end(), top.magic);
}

bool chunked_folder_has_colours(const std::string& dir) {
  check_chunked_folder(dir);
  const std::string path = (fs::path(dir) / chunked_top_file).string();
  const auto head = detail::load_file_prefix(path, 16);
  if (head.size() < 16) throw FormatError(path + ": truncated while reading flags");
  return (head[12] & 1u) != 0;
}

void check_chunked_folder(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return;
  if (is_unfinished_directory(dir))
    throw FormatError(dir +
                      ": an interrupted chunked build (its staging folder: the build writing it "
                      "failed or was killed before it finished); build again, and remove this "
                      "folder");
  if (fs::exists(fs::path(dir) / chunked_top_file, ec)) return;
  bool chunks = false;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    chunks = chunks || name.rfind("chunk-", 0) == 0 || name == "tmp-build";
  }
  if (chunks)
    throw FormatError(dir + ": an incomplete chunked build (chunk files but no " +
                      chunked_top_file +
                      ", which a build writes last: the build did not finish); build again");
  throw FormatError(dir + ": a folder, but not a chunked build (no " + chunked_top_file + ")");
}

void check_chunked_output(const std::string& dir) {
  std::error_code ec;
  const fs::file_status st = fs::symlink_status(dir, ec);
  if (!fs::exists(st)) return;
  if (!fs::is_directory(st))
    throw IoError(dir +
                  ": exists and is not a folder (a file or a link); a chunked build writes a "
                  "folder: remove it or choose another output");
  if (fs::exists(fs::path(dir) / chunked_top_file, ec) || fs::is_empty(dir, ec)) return;
  throw IoError(dir + ": a folder that is not a chunked build (no " + chunked_top_file +
                "); a chunked build replaces only an empty folder or an earlier build: remove it "
                "or choose another output");
}

}  // namespace pbr_lod
