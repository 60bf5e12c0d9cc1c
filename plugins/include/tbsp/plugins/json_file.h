#pragma once
/// \file json_file.h
/// \brief Reads a JSON document from a file; errors name the file (and nlohmann's line/column).

#include <Eigen/Core>
#include <initializer_list>
#include <nlohmann/json.hpp>
#include <string>

namespace tbsp {

/// \throws FileError when the file cannot be opened or is not valid JSON (syntax errors with
/// nlohmann's line/column; numbers outside the range of a double, e.g. 1e309, are named too).
nlohmann::json load_json_file(const std::string& path);

/// Safety net of the JSON front ends (constraints, markers, ROI, tet handles/rigid/stiffness,
/// texture constraints): a value of an unexpected kind that no explicit check names becomes a
/// FileError naming the file and nlohmann's description, so the CLI exits 2, never 1.
[[noreturn]] void throw_json_structure_error(const std::string& source, const nlohmann::json::exception& e);

/// Reading helpers shared by every JSON front end (constraints, markers, ROI, tet handles /
/// rigid / stiffness, texture constraints). Each failure is a FileError "SOURCE: WHERE: what is
/// wrong", WHERE being the item's path in the document (e.g. `constraints[3].target`).
class JsonReader {
public:
  explicit JsonReader(std::string source) : source_(std::move(source)) {}
  const std::string& source() const { return source_; }
  [[noreturn]] void fail(const std::string& where, const std::string& msg) const;
  /// A finite number within ±1e150 (the solvers square lengths and weights).
  double number(const nlohmann::json& j, const std::string& where) const;
  /// A finite number > 0, within 1e150.
  double positive(const nlohmann::json& j, const std::string& where) const;
  /// Three finite numbers within ±1e150, [x, y, z].
  Eigen::Vector3d vec3(const nlohmann::json& j, const std::string& where) const;
  /// An integer (any range of long long).
  long long integer(const nlohmann::json& j, const std::string& where) const;
  /// An index into `count` items named `kind` ("vertex", "face"): 0 <= i < count.
  int index(const nlohmann::json& j, const std::string& where, Eigen::Index count, const std::string& kind) const;
  /// true or false.
  bool boolean(const nlohmann::json& j, const std::string& where) const;
  /// Fails on the first key of the object `j` that is not in `allowed`, listing the known ones.
  void check_keys(const nlohmann::json& j, std::initializer_list<const char*> allowed, const std::string& where) const;

private:
  std::string source_;
};

}  // namespace tbsp
