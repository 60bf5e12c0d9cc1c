#pragma once
/// \file tet_job_run.h
/// \brief The steps of a `tbsp tetdeform` job shared by the CLI and the `tetdeform` pipeline
/// stage: tet mesh from a surface (or a given tet mesh), the job's handles / rigid regions /
/// stiffness applied to a TetDeformer, and the deformed input surface (DeformationTransfer when
/// the tet mesh was decimated). The deformation itself is tbsp::TetDeformer (pcl_ext/deform).

#include <string>
#include <vector>

#include "tbsp/deform/tet_deformer.h"
#include "tbsp/mesh/tet_mesh.h"
#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/plugins/tet_job_json.h"

namespace tbsp {

/// The input of a job and its tet mesh, with the map from tet vertices to input vertices.
struct TetJobSetup {
  TriMesh surface;              ///< the input surface (a tet mesh input: its boundary)
  TetMesh tets;                 ///< the tet mesh the deformer runs on
  bool from_tets = false;       ///< the input was a tet mesh
  bool decimated = false;       ///< the tet mesh's vertices are not the surface's (QEM-decimated)
  std::vector<Eigen::Index> to_input;  ///< nearest input vertex of each tet vertex
  std::vector<double> dist;            ///< ... and its distance
  double snap = 0;              ///< vertex-list regions: tet vertices within this of a listed vertex
  double tetrahedralize_seconds = 0;
  /// Vertex count that handle / region vertex indices refer to.
  Eigen::Index numInputVertices() const { return from_tets ? tets.V.rows() : surface.V.rows(); }
};

/// \brief Tetrahedralizes `surface` (TetGen; QEM-decimated first to about `target_tets`
/// tetrahedra when > 0). `name` names the mesh in errors.
/// \throws InvalidInput "NAME: cannot be tetrahedralized: ..." (open or self-intersecting surface).
TetJobSetup tet_job_setup(const TriMesh& surface, int target_tets, const std::string& name);
/// \brief A given tet mesh (handle indices refer to its vertices).
TetJobSetup tet_job_setup(const TetMesh& tets);

/// The job's files (handles required, rigid regions and stiffness optional: empty path), read
/// once; parse() checks them against a mesh's vertex count (it may run for many meshes).
struct TetJobFiles {
  std::string handles, rigid, stiffness;           ///< paths (also named in errors)
  nlohmann::json handles_doc, rigid_doc, stiffness_doc;
  /// \throws FileError naming the file (missing, not JSON).
  static TetJobFiles load(const std::string& handles, const std::string& rigid, const std::string& stiffness);
  /// \throws FileError ("H.json: handles[2].rotate.axis: ..."), indices checked against `num_input_vertices`.
  TetJob parse(Eigen::Index num_input_vertices) const;
};

/// \brief The deformer options a job asks for; `rotation_interpolation = false` turns step (III)
/// off whatever the file says (--no-rotation-interpolation).
TetDeformerOptions tet_job_options(const TetJob& job, bool rotation_interpolation = true);

/// \brief Puts the job's stiffness, rigid regions and handles on `d` (whose mesh must be
/// `s.tets`). \throws InvalidInput naming the file and the entry (a region with no vertex, ...).
void apply_tet_job(const TetJobSetup& s, const TetJob& job, const TetJobFiles& files, TetDeformer& d);

/// \brief The deformed input surface after `d.deform()`: the surface's vertices moved, by
/// DeformationTransfer (§7.3) when the tet mesh was decimated. `transfer_precompute_s` /
/// `transfer_apply_s` (optional) receive the transfer's times (0 without transfer).
TriMesh deformed_surface(const TetJobSetup& s, const TetDeformer& d, double* transfer_precompute_s = nullptr,
                         double* transfer_apply_s = nullptr);

}  // namespace tbsp
