#include "text_buffer.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace tbsp::detail {

TextBuffer TextBuffer::load(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw FileError("'" + path + "': no such file; check the path");
  if (std::filesystem::is_directory(path, ec)) throw FileError("'" + path + "': is a directory, expected a file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw FileError("'" + path + "': cannot open for reading (" + std::strerror(errno) + ")");
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw FileError("'" + path + "': read error");
  return TextBuffer(path, ss.str());
}

void TextBuffer::fail(const std::string& msg) const {
  throw FileError(path_ + ":" + std::to_string(line_) + ": " + msg);
}
void TextBuffer::failBinary(const std::string& msg) const {
  throw FileError(path_ + " (byte " + std::to_string(pos_) + "): " + msg);
}

bool TextBuffer::nextLine(std::string_view& out) {
  if (atEnd()) return false;
  std::size_t e = data_.find('\n', pos_);
  if (e == std::string::npos) e = data_.size();
  std::size_t len = e - pos_;
  if (len && data_[pos_ + len - 1] == '\r') --len;
  out = std::string_view(data_.data() + pos_, len);
  pos_ = e < data_.size() ? e + 1 : e;
  if (e < data_.size()) ++line_;
  return true;
}

void TextBuffer::skipSpace(bool comments) {
  while (pos_ < data_.size()) {
    const char c = data_[pos_];
    if (c == '\n') { ++line_; ++pos_; }
    else if (c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v') ++pos_;
    else if (comments && c == '#') { while (pos_ < data_.size() && data_[pos_] != '\n') ++pos_; }
    else break;
  }
}

bool TextBuffer::token(std::string_view& out, bool comments) {
  skipSpace(comments);
  if (atEnd()) return false;
  const std::size_t b = pos_;
  while (pos_ < data_.size() && !std::isspace(static_cast<unsigned char>(data_[pos_])) && !(comments && data_[pos_] == '#')) ++pos_;
  out = std::string_view(data_.data() + b, pos_ - b);
  return true;
}

bool parse_double(std::string_view tok, double& out) {
  if (tok.empty() || tok.size() > 64) return false;
  char buf[65];
  std::memcpy(buf, tok.data(), tok.size());
  buf[tok.size()] = 0;
  char* end = nullptr;
  errno = 0;
  out = std::strtod(buf, &end);
  return end == buf + tok.size();
}

bool parse_int(std::string_view tok, long long& out) {
  if (tok.empty()) return false;
  const char* b = tok.data();
  if (*b == '+') ++b;
  auto r = std::from_chars(b, tok.data() + tok.size(), out);
  return r.ec == std::errc() && r.ptr == tok.data() + tok.size();
}

double TextBuffer::readDouble(const std::string& what, bool comments) {
  std::string_view t;
  if (!token(t, comments)) fail("unexpected end of file while reading " + what + " (the file is truncated)");
  double v;
  if (!parse_double(t, v)) fail("expected a number for " + what + ", found '" + std::string(t.substr(0, 40)) + "'");
  return v;
}

long long TextBuffer::readInt(const std::string& what, bool comments) {
  std::string_view t;
  if (!token(t, comments)) fail("unexpected end of file while reading " + what + " (the file is truncated)");
  long long v;
  if (!parse_int(t, v)) {
    double d;
    if (parse_double(t, d) && std::isfinite(d) && d == std::floor(d) && std::abs(d) < 9e18) return (long long)d;
    fail("expected an integer for " + what + ", found '" + std::string(t.substr(0, 40)) + "'");
  }
  return v;
}

void TextBuffer::skipToNextLine() {
  while (pos_ < data_.size() && data_[pos_] != '\n') ++pos_;
  if (pos_ < data_.size()) { ++pos_; ++line_; }
}

int TextBuffer::binarySize(const std::string& t) {
  if (t == "char" || t == "uchar" || t == "int8" || t == "uint8" || t == "unsigned_char") return 1;
  if (t == "short" || t == "ushort" || t == "int16" || t == "uint16" || t == "unsigned_short") return 2;
  if (t == "int" || t == "uint" || t == "int32" || t == "uint32" || t == "float" || t == "float32" ||
      t == "unsigned_int") return 4;
  if (t == "double" || t == "float64" || t == "vtktypeint64" || t == "long") return 8;
  return 0;
}

void TextBuffer::skipBytes(std::size_t n, const std::string& what) {
  if (remaining() < n) failBinary("unexpected end of file in " + what + " (the file is truncated)");
  pos_ += n;
}

double TextBuffer::readBinary(const std::string& t, bool big_endian, const std::string& what) {
  const int n = binarySize(t);
  if (n == 0) failBinary("unknown binary type '" + t + "' for " + what);
  if (remaining() < std::size_t(n)) failBinary("unexpected end of file while reading " + what + " (the file is truncated)");
  unsigned char b[8];
  std::memcpy(b, data_.data() + pos_, std::size_t(n));
  pos_ += std::size_t(n);
  if (big_endian) std::reverse(b, b + n);  // host is little endian (x86-64, aarch64)
  if (t == "char" || t == "int8") { std::int8_t v; std::memcpy(&v, b, 1); return v; }
  if (t == "uchar" || t == "uint8" || t == "unsigned_char") return b[0];
  if (t == "short" || t == "int16") { std::int16_t v; std::memcpy(&v, b, 2); return v; }
  if (t == "ushort" || t == "uint16" || t == "unsigned_short") { std::uint16_t v; std::memcpy(&v, b, 2); return v; }
  if (t == "int" || t == "int32") { std::int32_t v; std::memcpy(&v, b, 4); return v; }
  if (t == "uint" || t == "uint32" || t == "unsigned_int") { std::uint32_t v; std::memcpy(&v, b, 4); return v; }
  if (t == "float" || t == "float32") { float v; std::memcpy(&v, b, 4); return v; }
  if (t == "vtktypeint64" || t == "long") { std::int64_t v; std::memcpy(&v, b, 8); return double(v); }
  double v;
  std::memcpy(&v, b, 8);
  return v;
}

}  // namespace tbsp::detail
