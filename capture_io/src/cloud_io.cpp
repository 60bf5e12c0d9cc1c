#include "tbsp/io/cloud_io.h"

#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>
#include <limits>

#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/mesh_io.h"

namespace tbsp {

namespace {
std::string ext_of(const std::string& path) {
  const auto dot = path.find_last_of('.');
  std::string e = dot == std::string::npos ? "" : path.substr(dot + 1);
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return e;
}
bool has_field(const pcl::PCLPointCloud2& c, const std::string& n) {
  return std::any_of(c.fields.begin(), c.fields.end(), [&](const pcl::PCLPointField& f) { return f.name == n; });
}

// PCL 1.13's PCDReader dereferences past the end of truncated binary files (segfault), so the
// header and the data size are checked here first; errors name the file and the item.
void prevalidate_pcd(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw FileError("'" + path + "': cannot open for reading");
  in.seekg(0, std::ios::end);
  const std::uint64_t file_size = std::uint64_t(in.tellg());
  in.seekg(0);
  std::vector<std::string> fields, types;
  std::vector<long long> sizes, counts;
  long long width = -1, height = 1, points = -1;
  std::string data, line;
  int lineno = 0;
  auto fail = [&](const std::string& m) { throw FileError(path + ":" + std::to_string(lineno) + ": " + m); };
  while (data.empty() && std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ls(line);
    std::string key;
    ls >> key;
    std::vector<std::string> vals;
    for (std::string v; ls >> v;) vals.push_back(v);
    auto integer = [&](const std::string& v) {
      long long x;
      try { std::size_t used; x = std::stoll(v, &used); if (used != v.size()) throw 0; } catch (...) { fail(key + ": '" + v + "' is not an integer"); }
      return x;
    };
    if (key == "VERSION" || key == "VIEWPOINT") continue;
    if (key == "TYPE") types = vals;
    else if (key == "FIELDS" || key == "COLUMNS") fields = vals;
    else if (key == "SIZE") for (auto& v : vals) sizes.push_back(integer(v));
    else if (key == "COUNT") for (auto& v : vals) counts.push_back(integer(v));
    else if (key == "WIDTH" && vals.size() == 1) width = integer(vals[0]);
    else if (key == "HEIGHT" && vals.size() == 1) height = integer(vals[0]);
    else if (key == "POINTS" && vals.size() == 1) points = integer(vals[0]);
    else if (key == "DATA" && vals.size() == 1) data = vals[0];
    else fail("unexpected PCD header line '" + line.substr(0, 60) + "' (is this a PCD file?)");
  }
  if (data.empty()) fail("no DATA line: not a PCD file, or the header is truncated");
  if (fields.empty()) fail("no FIELDS line in the PCD header");
  if (sizes.size() != fields.size()) fail("SIZE has " + std::to_string(sizes.size()) + " entries for " + std::to_string(fields.size()) + " FIELDS");
  if (counts.empty()) counts.assign(fields.size(), 1);
  if (counts.size() != fields.size()) fail("COUNT has " + std::to_string(counts.size()) + " entries for " + std::to_string(fields.size()) + " FIELDS");
  if (width < 0 || height < 1) fail("WIDTH/HEIGHT missing or invalid");
  if (points < 0) points = width * height;
  if (points != width * height) fail("POINTS " + std::to_string(points) + " != WIDTH x HEIGHT (" + std::to_string(width) + " x " + std::to_string(height) + ")");
  if (points > 2000000000LL) fail("POINTS " + std::to_string(points) + " is absurd (corrupt header?)");
  // PCL 1.13 dereferences a null pointer for a TYPE it does not know ('N', or F of size 2: a
  // fuzz finding), so TYPE is checked against SIZE here: I/U of 1, 2, 4 or 8 bytes, F of 4 or 8
  if (!types.empty() && types.size() != fields.size())
    fail("TYPE has " + std::to_string(types.size()) + " entries for " + std::to_string(fields.size()) + " FIELDS");
  std::uint64_t point_size = 0;
  for (std::size_t i = 0; i < sizes.size(); ++i) {
    if (sizes[i] != 1 && sizes[i] != 2 && sizes[i] != 4 && sizes[i] != 8) fail("SIZE " + std::to_string(sizes[i]) + " is not 1, 2, 4 or 8");
    if (!types.empty()) {
      const std::string& t = types[i];
      if (t != "I" && t != "U" && t != "F")
        fail("TYPE '" + t.substr(0, 10) + "' of field " + fields[i] + " is not I, U or F");
      if (t == "F" && sizes[i] != 4 && sizes[i] != 8)
        fail("field " + fields[i] + ": TYPE F needs SIZE 4 or 8 (got " + std::to_string(sizes[i]) + ")");
    }
    if (counts[i] < 1) fail("COUNT must be >= 1");
    point_size += std::uint64_t(sizes[i]) * std::uint64_t(counts[i]);
  }
  const std::uint64_t header_end = std::uint64_t(in.tellg());
  const std::uint64_t remaining = file_size >= header_end ? file_size - header_end : 0;
  if (data == "binary") {
    if (remaining < std::uint64_t(points) * point_size)
      fail("binary data holds " + std::to_string(remaining) + " bytes but " + std::to_string(points) + " points of " +
           std::to_string(point_size) + " bytes need " + std::to_string(std::uint64_t(points) * point_size) + " (the file is truncated)");
  } else if (data == "binary_compressed") {
    std::uint32_t sz[2] = {0, 0};
    if (remaining < 8 || !in.read(reinterpret_cast<char*>(sz), 8)) fail("binary_compressed data is missing its size header (truncated)");
    if (sz[0] > remaining - 8) fail("compressed block of " + std::to_string(sz[0]) + " bytes exceeds the file (truncated)");
    if (std::uint64_t(sz[1]) != std::uint64_t(points) * point_size)
      fail("decompressed size " + std::to_string(sz[1]) + " does not match POINTS x point size");
  } else if (data == "ascii") {
    // PCL's reader goes on parsing header keywords in the body (a line "COLUMNS..." after DATA
    // empties its field list, and the body then writes out of bounds: a fuzz finding), so the
    // body is checked here first: one line per point, as many numbers as FIELDS x COUNT
    std::uint64_t per_line = 0;
    for (long long c : counts) per_line += std::uint64_t(c);
    long long rows = 0;
    while (std::getline(in, line)) {
      ++lineno;
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (line.find_first_not_of(" \t") == std::string::npos) continue;
      if (rows == points)
        fail("more data lines than the " + std::to_string(points) + " POINTS the header declares");
      std::istringstream ls(line);
      std::uint64_t n = 0;
      for (std::string tok; ls >> tok; ++n) {
        char* end = nullptr;
        std::strtod(tok.c_str(), &end);
        if (end == tok.c_str() || *end != '\0') fail("'" + tok.substr(0, 30) + "' is not a number (point " + std::to_string(rows) + ")");
      }
      if (n != per_line)
        fail("point " + std::to_string(rows) + " has " + std::to_string(n) + " values; FIELDS x COUNT need " + std::to_string(per_line));
      ++rows;
    }
    if (rows < points)
      fail("the data holds " + std::to_string(rows) + " of the " + std::to_string(points) + " POINTS the header declares (truncated?)");
  } else {
    fail("unknown DATA encoding '" + data + "' (ascii, binary or binary_compressed)");
  }
}

}  // namespace

pcl::PCLPointCloud2 read_cloud(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw FileError("'" + path + "': no such file; check the path");
  pcl::PCLPointCloud2 blob;
  if (ext_of(path) == "pcd") {
    if (std::filesystem::file_size(path, ec) == 0) throw FileError("'" + path + "': the file is empty");
    prevalidate_pcd(path);
    pcl::PCDReader reader;
    int rc = -1;
    try {
      Eigen::Vector4f origin;
      Eigen::Quaternionf orientation;
      int version = 0;
      rc = reader.read(path, blob, origin, orientation, version);
    } catch (const std::exception& e) {
      throw FileError("'" + path + "': malformed PCD file (" + e.what() + ")");
    }
    if (rc < 0)
      throw FileError("'" + path + "': malformed or truncated PCD file (PCL's reader failed with code " +
                      std::to_string(rc) + "; see its message above)");
  } else {
    const TriMesh m = read_mesh(path);
    // PCL clouds hold single precision: a finite coordinate beyond ±3.4e38 would become ±inf
    // and the cloud's points "non-finite" to everything downstream
    for (Eigen::Index i = 0; i < m.V.rows(); ++i)
      for (int k = 0; k < 3; ++k)
        if (std::isfinite(m.V(i, k)) && std::abs(m.V(i, k)) > double(std::numeric_limits<float>::max())) {
          char buf[96];
          std::snprintf(buf, sizeof buf, "%.6g", m.V(i, k));
          throw FileError("'" + path + "': vertex " + std::to_string(i) + " has " + "xyz"[k] + " = " + buf +
                          ", beyond the single precision (±3.4e38) of a PCL cloud; rescale the cloud to a sane unit");
        }
    if (m.N.rows() == m.V.rows() && m.V.rows() > 0) {
      pcl::PointCloud<pcl::PointNormal> c;
      c.resize(std::size_t(m.V.rows()));
      for (Eigen::Index i = 0; i < m.V.rows(); ++i) {
        auto& p = c[std::size_t(i)];
        p.x = float(m.V(i, 0)); p.y = float(m.V(i, 1)); p.z = float(m.V(i, 2));
        p.normal_x = float(m.N(i, 0)); p.normal_y = float(m.N(i, 1)); p.normal_z = float(m.N(i, 2));
      }
      pcl::toPCLPointCloud2(c, blob);
    } else {
      pcl::PointCloud<pcl::PointXYZ> c;
      c.resize(std::size_t(m.V.rows()));
      for (Eigen::Index i = 0; i < m.V.rows(); ++i)
        c[std::size_t(i)] = pcl::PointXYZ(float(m.V(i, 0)), float(m.V(i, 1)), float(m.V(i, 2)));
      pcl::toPCLPointCloud2(c, blob);
    }
  }
  if (!has_field(blob, "x") || !has_field(blob, "y") || !has_field(blob, "z"))
    throw FileError("'" + path + "': the cloud has no x/y/z fields");
  return blob;
}

pcl::PointCloud<pcl::PointNormal>::Ptr read_cloud_normals(const std::string& path, bool* has_normals) {
  const pcl::PCLPointCloud2 blob = read_cloud(path);
  auto out = pcl::PointCloud<pcl::PointNormal>::Ptr(new pcl::PointCloud<pcl::PointNormal>);
  const bool hn = has_field(blob, "normal_x") && has_field(blob, "normal_y") && has_field(blob, "normal_z");
  pcl::PointCloud<pcl::PointXYZ> xyz;
  pcl::fromPCLPointCloud2(blob, xyz);
  out->resize(xyz.size());
  out->width = xyz.width;
  out->height = xyz.height;
  out->is_dense = xyz.is_dense;
  pcl::PointCloud<pcl::Normal> n;
  if (hn) pcl::fromPCLPointCloud2(blob, n);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (std::size_t i = 0; i < xyz.size(); ++i) {
    auto& p = (*out)[i];
    p.x = xyz[i].x; p.y = xyz[i].y; p.z = xyz[i].z;
    p.normal_x = hn ? n[i].normal_x : nan;
    p.normal_y = hn ? n[i].normal_y : nan;
    p.normal_z = hn ? n[i].normal_z : nan;
    p.curvature = hn ? n[i].curvature : nan;
  }
  if (has_normals) *has_normals = hn;
  return out;
}

void write_cloud(const std::string& path, const pcl::PCLPointCloud2& cloud, bool binary) {
  const std::string e = ext_of(path);
  if (e == "pcd") {
    atomic_write_with(path, [&](const std::string& tmp) {
      pcl::PCDWriter w;
      return (binary ? w.writeBinary(tmp, cloud) : w.writeASCII(tmp, cloud)) == 0;
    });
    return;
  }
  if (e != "ply") throw FileError("cannot write cloud '" + path + "': use .pcd or .ply");
  // Fields beyond x y z and normals (colour, confidence, ...): PCL's PLY writer keeps them all.
  bool extra = false;
  for (const auto& f : cloud.fields)
    extra |= f.name != "x" && f.name != "y" && f.name != "z" && f.name != "normal_x" && f.name != "normal_y" && f.name != "normal_z" &&
             f.name != "curvature" && f.name.rfind("_", 0) != 0;
  if (extra) {
    atomic_write_with(path, [&](const std::string& tmp) {
      pcl::PLYWriter w;
      return w.write(tmp, cloud, Eigen::Vector4f::Zero(), Eigen::Quaternionf::Identity(), binary, false) == 0;
    });
    return;
  }
  TriMesh m;
  pcl::PointCloud<pcl::PointXYZ> xyz;
  pcl::fromPCLPointCloud2(cloud, xyz);
  m.V.resize(Eigen::Index(xyz.size()), 3);
  for (std::size_t i = 0; i < xyz.size(); ++i) m.V.row(Eigen::Index(i)) << xyz[i].x, xyz[i].y, xyz[i].z;
  if (has_field(cloud, "normal_x")) {
    pcl::PointCloud<pcl::Normal> n;
    pcl::fromPCLPointCloud2(cloud, n);
    m.N.resize(m.V.rows(), 3);
    for (std::size_t i = 0; i < n.size(); ++i) m.N.row(Eigen::Index(i)) << n[i].normal_x, n[i].normal_y, n[i].normal_z;
  }
  MeshWriteOptions o;
  o.binary = binary;
  write_mesh(path, m, o, MeshFormat::PLY);
}

}  // namespace tbsp
