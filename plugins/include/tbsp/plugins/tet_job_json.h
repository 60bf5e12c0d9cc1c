#pragma once
/// \file tet_job_json.h
/// \brief The handle / rigid-region / stiffness files of `tbsp tetdeform`
/// (format: docs/tetdeform_json.md).
///
/// Regions are given as input-mesh vertex lists, spheres or boxes; they are resolved against
/// the tet mesh by resolve_*: sphere/box regions take every tet vertex (or tet barycenter)
/// inside, vertex lists take the tet vertices whose nearest input vertex is listed and lies
/// within `snap` of it (the surface vertices of a decimated tet mesh).

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "tbsp/deform/tet_deformer.h"
#include "tbsp/mesh/point_search.h"

namespace tbsp {

/// A region of space or of the input mesh.
struct TetRegion {
  enum Kind { Vertices, Sphere, Box } kind = Vertices;
  std::vector<int> vertices;             ///< input-mesh vertex indices (Vertices)
  Eigen::Vector3d a = Eigen::Vector3d::Zero(), b = Eigen::Vector3d::Zero();  ///< centre/radius(x) or min/max
  double radius = 0;
  bool contains(const Eigen::Vector3d& p) const;  ///< Sphere / Box only
};

struct TetHandleSpec {
  enum Kind { Region, Vertex, Point } kind = Region;
  TetRegion region;            ///< Region
  RigidMotion motion;          ///< Region
  int vertex = -1;             ///< Vertex: input-mesh vertex
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   ///< Point: rest position
  Eigen::Vector3d target = Eigen::Vector3d::Zero();  ///< Vertex / Point
  std::string where;           ///< "handles[3]" for messages
};

struct TetJob {
  std::vector<TetHandleSpec> handles;
  std::optional<int> iterations;
  std::optional<bool> rotation_interpolation;
  std::optional<double> max_step_degrees;
  std::vector<TetRegion> rigid;          ///< from a rigid-regions file
  double default_stiffness = 1.0;        ///< from a stiffness file
  std::vector<std::pair<TetRegion, double>> stiffness;
};

/// \brief Parses a handles document; vertex indices are checked against `num_input_vertices`.
/// `source` names the file in errors. \throws FileError ("H.json: handles[2].rotate.axis: ...").
void parse_tet_handles(const nlohmann::json& doc, Eigen::Index num_input_vertices, const std::string& source, TetJob& job);
/// \brief {"rigid": [region, ...]}. \throws FileError.
void parse_tet_rigid(const nlohmann::json& doc, Eigen::Index num_input_vertices, const std::string& source, TetJob& job);
/// \brief {"default": s, "regions": [{region..., "stiffness": s}]}. \throws FileError.
void parse_tet_stiffness(const nlohmann::json& doc, Eigen::Index num_input_vertices, const std::string& source, TetJob& job);

/// \brief Tet vertices in `r`. `input` is the input mesh's vertices (for vertex lists),
/// `tet_to_input`/`dist` the nearest input vertex of each tet vertex and its distance.
std::vector<int> resolve_region_vertices(const TetRegion& r, const Eigen::MatrixX3d& tet_vertices,
                                         const std::vector<Eigen::Index>& tet_to_input, const std::vector<double>& dist,
                                         double snap);
/// \brief Tets in `r` (barycenter inside for spheres/boxes, all four vertices in the list for
/// vertex lists).
std::vector<int> resolve_region_tets(const TetRegion& r, const TetMesh& tets, const std::vector<Eigen::Index>& tet_to_input,
                                     const std::vector<double>& dist, double snap);

}  // namespace tbsp
