#pragma once
/// \file cloud_io.h
/// \brief Point-cloud files: PCD (through PCL's reader, every encoding incl. binary_compressed)
/// and PLY / OBJ / OFF / VTK vertices (through tbsp's mesh readers).

#include <pcl/PCLPointCloud2.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <string>

namespace tbsp {

/// \brief Reads a cloud into a PCLPointCloud2 with the fields the file has (x,y,z and, where
/// present, normal_x.., rgb). \throws FileError naming the file and problem (missing file,
/// malformed header, truncated data, no x/y/z).
pcl::PCLPointCloud2 read_cloud(const std::string& path);

/// \brief Reads a cloud as PointNormal (normals NaN when the file has none; `has_normals`
/// says which). \throws FileError.
pcl::PointCloud<pcl::PointNormal>::Ptr read_cloud_normals(const std::string& path, bool* has_normals = nullptr);

/// \brief Writes a cloud atomically: `.pcd` (binary, or ascii when binary=false) or `.ply`
/// (binary little endian or ascii; x,y,z and normals if present; a cloud with more fields —
/// colour, confidence — goes through PCL's PLYWriter, which keeps them). \throws FileError.
void write_cloud(const std::string& path, const pcl::PCLPointCloud2& cloud, bool binary = true);

}  // namespace tbsp
