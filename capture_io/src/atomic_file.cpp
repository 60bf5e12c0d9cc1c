#include "tbsp/io/atomic_file.h"

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <unistd.h>

#include "tbsp/core/error.h"

namespace tbsp {

namespace fs = std::filesystem;

AtomicFile::AtomicFile(const std::string& path, bool binary) : path_(path) {
  static std::atomic<unsigned> counter{0};
  const fs::path p(path);
  const fs::path dir = p.has_parent_path() ? p.parent_path() : fs::path(".");
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw FileError("cannot write '" + path + "': directory '" + dir.string() + "' does not exist; create it first");
  if (fs::is_directory(p, ec)) throw FileError("cannot write '" + path + "': it is a directory; give a file name");
  tmp_ = (dir / ("." + p.filename().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
                 std::to_string(counter++))).string();
  out_.open(tmp_, binary ? std::ios::out | std::ios::binary | std::ios::trunc : std::ios::out | std::ios::trunc);
  if (!out_)
    throw FileError("cannot write '" + path + "': cannot create temporary file in '" + dir.string() + "' (" +
                    std::strerror(errno) + "); check permissions and free space");
}

AtomicFile::~AtomicFile() {
  if (!committed_) {
    out_.close();
    std::remove(tmp_.c_str());
  }
}

void AtomicFile::commit() {
  out_.flush();
  const bool ok = bool(out_);
  out_.close();
  if (!ok || out_.fail()) {
    std::remove(tmp_.c_str());
    committed_ = true;
    throw FileError("cannot write '" + path_ + "': write error (disk full?); the previous file, if any, is untouched");
  }
  std::error_code ec;
  fs::rename(tmp_, path_, ec);
  committed_ = true;
  if (ec) {
    std::remove(tmp_.c_str());
    throw FileError("cannot write '" + path_ + "': rename failed (" + ec.message() + ")");
  }
}

void write_text_file_atomic(const std::string& path, const std::string& text) {
  AtomicFile f(path);
  f.stream() << text;
  f.commit();
}

}  // namespace tbsp

namespace tbsp {
void atomic_write_with(const std::string& path, const std::function<bool(const std::string&)>& write) {
  std::string tmp;
  {
    AtomicFile probe(path);  // validates the directory and picks a unique temp name
    tmp = probe.tempPath() + "w";
  }
  bool ok = false;
  try {
    ok = write(tmp);
  } catch (...) {
    std::remove(tmp.c_str());
    throw;
  }
  std::error_code ec;
  if (ok && std::filesystem::exists(tmp, ec)) {
    std::filesystem::rename(tmp, path, ec);
    if (!ec) return;
  }
  std::remove(tmp.c_str());
  throw FileError("cannot write '" + path + "'" + (ec ? ": " + ec.message() : std::string()) +
                  "; the previous file, if any, is untouched");
}
}  // namespace tbsp
