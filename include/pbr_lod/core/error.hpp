// pbr_lod — the exception hierarchy.
//
// Every error the library reports on user data derives from pbr_lod::Error. Messages name the
// file (when there is one), the element and what was expected, so that a user can fix the input
// without reading our source. Nothing in the library aborts or asserts on user data.
#pragma once

#include <stdexcept>
#include <string>

namespace pbr_lod {

/// Root of all exceptions thrown by pbr_lod.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A file could not be opened, read or written (I/O level).
class IoError : public Error {
 public:
  using Error::Error;
};

/// A file was opened but its content is malformed: wrong magic, counts that do not match the
/// data, truncation, out-of-range indices, unsupported encodings.
class FormatError : public Error {
 public:
  using Error::Error;
};

/// The caller passed an argument that cannot be used (empty input, NaN coordinates, a view with
/// a zero-size viewport, an attribute the data does not have, ...).
class InvalidArgument : public Error {
 public:
  using Error::Error;
};

/// A long operation was cancelled through its progress callback.
class Cancelled : public Error {
 public:
  using Error::Error;
};

}  // namespace pbr_lod
