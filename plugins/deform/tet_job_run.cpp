// Shared steps of a tetdeform job (tet_job_run.h): used by `tbsp tetdeform` and the `tetdeform`
// pipeline stage.
#include "tbsp/plugins/tet_job_run.h"

#include <chrono>
#include <cmath>

#include "tbsp/core/error.h"
#include "tbsp/deform/deformation_transfer.h"
#include "tbsp/mesh/point_search.h"
#include "tbsp/mesh/tetrahedralize.h"
#include "tbsp/plugins/json_file.h"

namespace tbsp {
namespace {

double seconds_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

double mean_tet_edge(const TetMesh& t) {
  double s = 0;
  for (Eigen::Index j = 0; j < t.T.rows(); ++j) s += (t.V.row(t.T(j, 0)) - t.V.row(t.T(j, 1))).norm();
  return s / double(std::max<Eigen::Index>(1, t.T.rows()));
}

}  // namespace

TetJobSetup tet_job_setup(const TriMesh& surface, int target_tets, const std::string& name) {
  TetJobSetup s;
  const auto t0 = std::chrono::steady_clock::now();
  s.surface = surface;
  TriMesh dec;
  try {
    s.tets = tetrahedralize_to_size(surface, target_tets, {}, &dec);
  } catch (const InvalidInput& e) {
    throw InvalidInput(name + ": cannot be tetrahedralized: " + e.what());
  } catch (const Error& e) {
    throw Error(name + ": cannot be tetrahedralized: " + e.what());
  }
  s.decimated = dec.F.rows() != surface.F.rows() || s.tets.V.rows() < surface.V.rows() ||
                !(s.tets.V.topRows(surface.V.rows()) - surface.V).isZero(0);
  s.tetrahedralize_seconds = seconds_since(t0);
  const PointSearch ps(surface.V);
  s.to_input.resize(std::size_t(s.tets.V.rows()));
  s.dist.resize(std::size_t(s.tets.V.rows()));
  for (Eigen::Index i = 0; i < s.tets.V.rows(); ++i) {
    double d2;
    s.to_input[std::size_t(i)] = ps.nearest(s.tets.V.row(i).transpose(), &d2);
    s.dist[std::size_t(i)] = std::sqrt(d2);
  }
  s.snap = 1.5 * mean_tet_edge(s.tets);
  return s;
}

TetJobSetup tet_job_setup(const TetMesh& tets) {
  TetJobSetup s;
  s.from_tets = true;
  s.tets = tets;
  s.surface = tet_boundary_surface(tets.V, tets.T);
  s.to_input.resize(std::size_t(tets.V.rows()));
  s.dist.assign(std::size_t(tets.V.rows()), 0.0);
  for (std::size_t i = 0; i < s.to_input.size(); ++i) s.to_input[i] = Eigen::Index(i);
  s.snap = 1.5 * mean_tet_edge(tets);
  return s;
}

TetJobFiles TetJobFiles::load(const std::string& handles, const std::string& rigid, const std::string& stiffness) {
  TetJobFiles f;
  f.handles = handles;
  f.rigid = rigid;
  f.stiffness = stiffness;
  f.handles_doc = load_json_file(handles);
  if (!rigid.empty()) f.rigid_doc = load_json_file(rigid);
  if (!stiffness.empty()) f.stiffness_doc = load_json_file(stiffness);
  return f;
}

TetJob TetJobFiles::parse(Eigen::Index num_input_vertices) const {
  TetJob job;
  parse_tet_handles(handles_doc, num_input_vertices, handles, job);
  if (!rigid.empty()) parse_tet_rigid(rigid_doc, num_input_vertices, rigid, job);
  if (!stiffness.empty()) parse_tet_stiffness(stiffness_doc, num_input_vertices, stiffness, job);
  return job;
}

TetDeformerOptions tet_job_options(const TetJob& job, bool rotation_interpolation) {
  TetDeformerOptions o;
  if (job.rotation_interpolation) o.rotation_interpolation = *job.rotation_interpolation;
  if (!rotation_interpolation) o.rotation_interpolation = false;
  if (job.max_step_degrees) o.max_handle_step_deg = *job.max_step_degrees;
  return o;
}

void apply_tet_job(const TetJobSetup& s, const TetJob& job, const TetJobFiles& names, TetDeformer& d) {
  if (!job.stiffness.empty() || job.default_stiffness != 1.0) {
    Eigen::VectorXd st = Eigen::VectorXd::Constant(s.tets.T.rows(), job.default_stiffness);
    for (const auto& [r, v] : job.stiffness)
      for (int t : resolve_region_tets(r, s.tets, s.to_input, s.dist, s.snap)) st(t) = v;
    d.setStiffness(st);
  }
  for (std::size_t i = 0; i < job.rigid.size(); ++i) {
    const auto ts = resolve_region_tets(job.rigid[i], s.tets, s.to_input, s.dist, s.snap);
    if (ts.empty()) throw InvalidInput(names.rigid + ": rigid[" + std::to_string(i) + "] contains no tetrahedron; enlarge it");
    d.addRigidRegion(ts);
  }
  for (const auto& h : job.handles) {
    try {
      if (h.kind == TetHandleSpec::Region) {
        const auto vs = resolve_region_vertices(h.region, s.tets.V, s.to_input, s.dist, s.snap);
        if (vs.empty())
          throw InvalidInput("the region selects no vertex of the tet mesh (" + std::to_string(s.tets.V.rows()) +
                             " vertices); enlarge it or use more tets");
        d.addRegionHandle(vs, h.motion);
      } else if (h.kind == TetHandleSpec::Vertex) {
        if (s.from_tets || !s.decimated) d.addVertexHandle(h.vertex, h.target);
        else d.addPointHandle(s.surface.V.row(h.vertex).transpose(), h.target);
      } else {
        d.addPointHandle(h.point, h.target);
      }
    } catch (const InvalidInput& e) {
      throw InvalidInput(names.handles + ": " + h.where + ": " + e.what());
    }
  }
}

TriMesh deformed_surface(const TetJobSetup& s, const TetDeformer& d, double* transfer_precompute_s, double* transfer_apply_s) {
  double t_pre = 0, t_apply = 0;
  TriMesh out = s.surface;
  if (s.from_tets) {
    out = tet_boundary_surface(d.positions().topRows(s.tets.V.rows()), s.tets.T);
  } else if (!s.decimated) {
    out.V = d.positions().topRows(s.surface.V.rows());
  } else {
    DeformationTransfer dt;
    dt.precompute(s.tets, s.surface.V);
    t_pre = dt.precomputeSeconds();
    const auto t0 = std::chrono::steady_clock::now();
    out.V = dt.apply(d.inputPositions());
    t_apply = seconds_since(t0);
  }
  out.N.resize(0, 3);
  if (transfer_precompute_s) *transfer_precompute_s = t_pre;
  if (transfer_apply_s) *transfer_apply_s = t_apply;
  return out;
}

}  // namespace tbsp
