#pragma once
/// \file atomic_file.h
/// \brief Crash-safe output: write to a temporary file next to the target, then rename.
/// An existing good output is never clobbered by a failed or interrupted run.

#include <fstream>
#include <string>

namespace tbsp {

/// \code
/// tbsp::AtomicFile out("result.ply", true);
/// out.stream() << ...;
/// out.commit();          // rename over result.ply; without commit() the temp file is removed
/// \endcode
class AtomicFile {
public:
  /// \throws FileError when the target directory does not exist or is not writable.
  explicit AtomicFile(const std::string& path, bool binary = false);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  std::ostream& stream() { return out_; }
  /// Flushes, closes and renames onto the target. \throws FileError on any write error.
  void commit();
  const std::string& path() const { return path_; }
  const std::string& tempPath() const { return tmp_; }

private:
  std::string path_, tmp_;
  std::ofstream out_;
  bool committed_ = false;
};

/// Writes `text` to `path` atomically.
void write_text_file_atomic(const std::string& path, const std::string& text);

}  // namespace tbsp

#include <functional>
namespace tbsp {
/// \brief For writers that insist on opening the file themselves (e.g. PCL's PCDWriter):
/// calls `write(tmp_path)`, which must create the file and return true on success, then renames
/// tmp_path onto `path`. On failure the temp file is removed and FileError thrown.
void atomic_write_with(const std::string& path, const std::function<bool(const std::string& tmp_path)>& write);
}  // namespace tbsp
