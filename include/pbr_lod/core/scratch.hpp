// pbr_lod — the memory builders keep between builds for their temporaries.
//
// Builders take their large temporary buffers from recycled pages (core/memory.hpp): blocks of
// whole pages kept when a build ends, up to 64 MB in all, so that the next build does not fault
// the same pages in again (docs/core.md, "Recycled temporaries"). These calls let a program see
// that memory and give it back, for example after loading a scene.
#pragma once

#include <cstddef>

#include "pbr_lod/core/memory.hpp"

namespace pbr_lod {

/// Bytes kept now for the temporaries of the next build (0 before any build; at most 64 MB).
[[nodiscard]] inline std::size_t scratch_memory_kept() noexcept {
  return detail::recycled_bytes_kept();
}

/// Returns the kept memory to the system. Safe at any time and from any thread: a build running
/// meanwhile keeps what it holds, and what it gives back at its end is kept again.
inline void release_scratch_memory() noexcept {
  detail::release_recycled_pages();
}

}  // namespace pbr_lod
