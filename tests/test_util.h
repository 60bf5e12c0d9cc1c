#pragma once
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "tbsp/core/error.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp::test {

inline std::string shared(const std::string& rel) { return std::string(TBSP_SHARED_DATA_DIR) + "/" + rel; }
inline std::string sample(const std::string& rel) { return std::string(TBSP_SAMPLE_DATA_DIR) + "/" + rel; }

// A test that needs a file of ../shared/data: with the CMake option TBSP_REQUIRE_SHARED_DATA
// (ON in ./scripts/test, so CI cannot pass by skipping) a missing file fails the test and names
// it; without it (users who do not have the data) the test is skipped with the same message.
#ifdef TBSP_REQUIRE_SHARED_DATA
#define TBSP_REQUIRE_FILE(path)                                                                                  \
  do {                                                                                                           \
    if (!std::filesystem::exists(path))                                                                          \
      GTEST_FAIL() << "shared data missing: " << (path)                                                          \
                   << " (TBSP_REQUIRE_SHARED_DATA is ON: put ../shared/data in place, point "                    \
                      "-DTBSP_SHARED_DATA_DIR at it, or configure with -DTBSP_REQUIRE_SHARED_DATA=OFF to skip)"; \
  } while (0)
#else
#define TBSP_REQUIRE_FILE(path)                                                                                 \
  do {                                                                                                          \
    if (!std::filesystem::exists(path))                                                                         \
      GTEST_SKIP() << "shared data missing: " << (path) << " (skipped: TBSP_REQUIRE_SHARED_DATA is OFF)";       \
  } while (0)
#endif

/// Deterministic farthest-point sampling of k vertices (Euclidean), starting at vertex `start`.
inline std::vector<int> farthest_points(const Eigen::MatrixX3d& V, int k, int start = 0) {
  std::vector<int> out{start};
  Eigen::VectorXd d = (V.rowwise() - V.row(start)).rowwise().norm();
  while (int(out.size()) < k) {
    Eigen::Index i;
    d.maxCoeff(&i);
    out.push_back(int(i));
    d = d.cwiseMin((V.rowwise() - V.row(i)).rowwise().norm());
  }
  return out;
}

inline std::filesystem::path temp_dir(const std::string& name) {
  auto p = std::filesystem::temp_directory_path() / ("tbsp_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(p);
  std::filesystem::create_directories(p);
  return p;
}

/// Writes `text` to `p` as it is (binary mode: no newline translation).
inline void write_text(const std::filesystem::path& p, const std::string& text) { std::ofstream(p, std::ios::binary) << text; }

/// The message of the tbsp::FileError that `f` throws ("" when it throws none).
inline std::string file_error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const FileError& e) {
    return e.what();
  }
  return "";
}

}  // namespace tbsp::test
