// fit_template: the stages of a template fit in order (template_fitter.h has the pipeline; each
// stage is in a file of its own, see fit_state.h).
#include "tbsp/fitting/template_fitter.h"

#include "fit_state.h"
#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/solve/blas_threads.h"

namespace tbsp {

FitReport fit_template(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in,
                       const std::vector<FitMarker>& markers, const RegionOfInterest& roi, const FitParameters& params,
                       TriMesh& result, std::vector<VertexStatus>& status, const ProgressCallback& progress,
                       bool orient_normals) {
  const auto t_all = Clock::now();
  // one BLAS thread: no contention with our OpenMP loops (blas_threads.h)
  const ScopedBlasThreads blas_threads(1);
  FitReport rep;
  fit_impl::FitState s(templ, markers, progress, rep, status);
  std::string why;
  if (!params.isValid(&why)) throw InvalidInput(s.who + "invalid parameters: " + why);
  MeshRequirements req;
  req.allow_nonmanifold = !params.remeshing;
  require_valid_mesh(templ, req, "tbsp::TemplateFitting::setInputTemplate");
  if (P_in.rows() == 0) throw InvalidInput(s.who + "the input cloud is empty; give a cloud with points");
  if (N_in.rows() != 0 && N_in.rows() != P_in.rows())
    throw InvalidInput(s.who + "the normals have " + std::to_string(N_in.rows()) + " rows for " +
                       std::to_string(P_in.rows()) + " points");
  report_progress(progress, 0.0, "prepare");
  fit_impl::prepare_cloud(s, P_in, N_in, roi, params, orient_normals);
  fit_impl::prepare_markers(s, P_in, roi);
  fit_impl::initial_pose(s);             // stage 1 (+ global scale)
  fit_impl::orient_cloud_normals(s);
  fit_impl::iterate_fit(s);              // stage 2
  fit_impl::propagate_displacements(s);  // stage 3
  fit_impl::detail_rounds(s);
  const int known_crossings = fit_impl::repair_surface(s);
  fit_impl::compute_metrics(s, known_crossings);
  result.V = s.V;
  result.F = s.F;
  result.N.resize(0, 3);
  result.C.resize(0, 3);
  rep.t_total = seconds_since(t_all);
  report_progress(progress, 1.0, "done");
  return rep;
}

}  // namespace tbsp
