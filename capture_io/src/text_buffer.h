#pragma once
// Internal: a whole file in memory with ASCII token and binary readers that report errors as
// "FILE:LINE: message" (ASCII) or "FILE (byte OFFSET): message" (binary).
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

#include "tbsp/core/error.h"

namespace tbsp::detail {

class TextBuffer {
public:
  TextBuffer(std::string path, std::string data) : path_(std::move(path)), data_(std::move(data)) {}
  static TextBuffer load(const std::string& path);

  const std::string& path() const { return path_; }
  const std::string& data() const { return data_; }
  bool atEnd() const { return pos_ >= data_.size(); }
  std::size_t pos() const { return pos_; }
  std::size_t remaining() const { return data_.size() - pos_; }
  int line() const { return line_; }

  [[noreturn]] void fail(const std::string& msg) const;
  [[noreturn]] void failBinary(const std::string& msg) const;

  /// Next line without the newline (and without '\r'); false at end of file.
  bool nextLine(std::string_view& out);
  /// Skips whitespace (counting lines). If `comments`, '#'-to-end-of-line is whitespace too.
  void skipSpace(bool comments = false);
  /// Next whitespace-separated token; false at end.
  bool token(std::string_view& out, bool comments = false);
  /// Next token as a number; fails with "expected <what>" at end of file or on garbage.
  double readDouble(const std::string& what, bool comments = false);
  long long readInt(const std::string& what, bool comments = false);
  /// Skips exactly one line break after a header keyword line in binary formats.
  void skipToNextLine();

  /// Binary scalar read (PLY / VTK types by name: char uchar short ushort int uint float double
  /// and their int8.. float64 aliases). Fails if the data ends early.
  double readBinary(const std::string& type, bool big_endian, const std::string& what);
  static int binarySize(const std::string& type);  // 0 if unknown
  void skipBytes(std::size_t n, const std::string& what);

private:
  std::string path_;
  std::string data_;
  std::size_t pos_ = 0;
  int line_ = 1;
};

bool parse_double(std::string_view tok, double& out);
bool parse_int(std::string_view tok, long long& out);

}  // namespace tbsp::detail
