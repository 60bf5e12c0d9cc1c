#include "tbsp/plugins/fit_json.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <fstream>

#include "tbsp/core/error.h"
#include "tbsp/plugins/json_file.h"

namespace tbsp {

namespace {
nlohmann::json load(const std::string& path) {
  nlohmann::json doc = load_json_file(path);
  if (!doc.is_object()) throw FileError(path + ": expected a JSON object");
  return doc;
}
}  // namespace

std::vector<FitMarker> load_markers_json(const std::string& path) try {
  const JsonReader in(path);
  const nlohmann::json doc = load(path);
  if (!doc.contains("markers") || !doc["markers"].is_array()) in.fail("markers", "missing: expected an array");
  std::vector<FitMarker> out;
  const auto& a = doc["markers"];
  for (std::size_t i = 0; i < a.size(); ++i) {
    const std::string w = "markers[" + std::to_string(i) + "]";
    const auto& j = a[i];
    if (!j.is_object()) in.fail(w, "expected an object");
    in.check_keys(j, {"template_vertex", "cloud_index", "position", "weight", "rotation", "comment"}, w);
    FitMarker m;
    if (!j.contains("template_vertex")) in.fail(w, "needs \"template_vertex\"");
    const long long tv = in.integer(j["template_vertex"], w + ".template_vertex");
    if (tv < 0 || tv > 2000000000LL) in.fail(w + ".template_vertex", "template vertex " + std::to_string(tv) + " does not exist");
    m.template_vertex = int(tv);
    if (j.contains("cloud_index") == j.contains("position"))
      in.fail(w, "give exactly one of \"cloud_index\" (a point of the cloud) or \"position\" (a free marker)");
    if (j.contains("cloud_index")) m.cloud_index = in.integer(j["cloud_index"], w + ".cloud_index");
    else m.position = in.vec3(j["position"], w + ".position");
    if (j.contains("weight")) m.weight = in.positive(j["weight"], w + ".weight");
    if (j.contains("rotation")) {
      const auto& r = j["rotation"];
      if (!r.is_object() || !r.contains("axis") || !r.contains("angle_deg"))
        in.fail(w + ".rotation", "expected {\"axis\": [x,y,z], \"angle_deg\": a}");
      const Eigen::Vector3d ax = in.vec3(r["axis"], w + ".rotation.axis");
      if (ax.norm() < 1e-12) in.fail(w + ".rotation.axis", "must be non-zero");
      m.rotation = Eigen::AngleAxisd(in.number(r["angle_deg"], w + ".rotation.angle_deg") * M_PI / 180, ax.normalized())
                       .toRotationMatrix();
    }
    out.push_back(m);
  }
  return out;
} catch (const nlohmann::json::exception& e) {
  throw_json_structure_error(path, e);
}

RegionOfInterest load_roi_json(const std::string& path) try {
  const JsonReader in(path);
  const nlohmann::json doc = load(path);
  RegionOfInterest roi;
  auto spheres = [&](const char* key, std::vector<Sphere>& out) {
    if (!doc.contains(key)) return;
    if (!doc[key].is_array()) in.fail(key, "expected an array");
    for (std::size_t i = 0; i < doc[key].size(); ++i) {
      const std::string w = std::string(key) + "[" + std::to_string(i) + "]";
      const auto& j = doc[key][i];
      if (!j.is_object() || !j.contains("center") || !j.contains("radius"))
        in.fail(w, "expected {\"center\": [x,y,z], \"radius\": r}");
      out.push_back({in.vec3(j["center"], w + ".center"), in.positive(j["radius"], w + ".radius")});
    }
  };
  auto boxes = [&](const char* key, std::vector<Box>& out) {
    if (!doc.contains(key)) return;
    if (!doc[key].is_array()) in.fail(key, "expected an array");
    for (std::size_t i = 0; i < doc[key].size(); ++i) {
      const std::string w = std::string(key) + "[" + std::to_string(i) + "]";
      const auto& j = doc[key][i];
      if (!j.is_object() || !j.contains("min") || !j.contains("max")) in.fail(w, "expected {\"min\": [..], \"max\": [..]}");
      out.push_back({in.vec3(j["min"], w + ".min"), in.vec3(j["max"], w + ".max")});
    }
  };
  in.check_keys(doc, {"exclude_template_vertices", "exclude_template_spheres", "exclude_template_boxes", "exclude_cloud_points",
                      "exclude_cloud_spheres", "exclude_cloud_boxes", "comment"},
                "top level");
  if (doc.contains("exclude_template_vertices")) {
    if (!doc["exclude_template_vertices"].is_array()) in.fail("exclude_template_vertices", "expected an array");
    for (const auto& v : doc["exclude_template_vertices"]) roi.exclude_template_vertices.push_back(int(in.integer(v, "exclude_template_vertices")));
  }
  if (doc.contains("exclude_cloud_points")) {
    if (!doc["exclude_cloud_points"].is_array()) in.fail("exclude_cloud_points", "expected an array");
    for (const auto& v : doc["exclude_cloud_points"]) roi.exclude_cloud_points.push_back(in.integer(v, "exclude_cloud_points"));
  }
  spheres("exclude_template_spheres", roi.exclude_template_spheres);
  spheres("exclude_cloud_spheres", roi.exclude_cloud_spheres);
  boxes("exclude_template_boxes", roi.exclude_template_boxes);
  boxes("exclude_cloud_boxes", roi.exclude_cloud_boxes);
  return roi;
} catch (const nlohmann::json::exception& e) {
  throw_json_structure_error(path, e);
}

const char* to_string(VertexStatus s) {
  switch (s) {
    case VertexStatus::Matched: return "matched";
    case VertexStatus::Propagated: return "propagated";
    case VertexStatus::Masked: return "masked";
    default: return "unmatched";
  }
}

nlohmann::json fit_report_json(const FitReport& r) {
  nlohmann::json j;
  j["status"] = r.status == FitReport::Status::Success ? "success" : "not_converged";
  j["message"] = r.message;
  j["iterations"] = r.iterations;
  nlohmann::json h = nlohmann::json::array();
  for (const auto& it : r.history)
    h.push_back({{"iteration", it.iteration}, {"match_radius", it.match_radius}, {"matched", it.matched},
                 {"max_move_p99", it.max_move}, {"seconds", it.seconds}, {"matching_seconds", it.matching_seconds}, {"solve_seconds", it.solve_seconds}, {"binned", it.binned}});
  j["history"] = h;
  j["scale"] = r.scale;
  if (r.aligned_without_markers) {
    nlohmann::json T = nlohmann::json::array();
    for (int i = 0; i < 4; ++i) T.push_back({r.alignment(i, 0), r.alignment(i, 1), r.alignment(i, 2), r.alignment(i, 3)});
    j["alignment"] = {{"matrix", T},
                      {"rotation_deg", r.alignment_rotation_deg},
                      {"scale", r.alignment_scale},
                      {"iterations", r.alignment_iterations},
                      {"rms", r.alignment_rms},
                      {"auto_markers", r.auto_markers},
                      {"seconds", r.t_alignment}};
  }
  if (r.coarse_nodes > 0) {
    j["coarse_stage"] = {{"nodes", r.coarse_nodes}, {"steps", r.coarse_steps}, {"seconds", r.t_coarse}};
    if (r.coarse_hypotheses > 1)
      j["coarse_stage"]["hypotheses"] = {{"count", r.coarse_hypotheses}, {"kept", r.coarse_kept}, {"kept_prepass_nodes", r.coarse_prepass_nodes}, {"tail_means", r.coarse_scores}};
  }
  if (!r.coarse_far_points.empty())  // with markers and the default coarse_nodes: fitted without and with the coarse stage
    j["coarse_compare"] = {{"compared", r.coarse_compared},
                           {"kept", r.coarse_nodes > 0 ? "coarse stage" : "without"},
                           {"points_beyond_r_max", r.coarse_far_points}};
  const auto& u = r.used;
  j["parameters"] = {{"max_match_distance", u.max_match_distance}, {"initial_match_distance", u.initial_match_distance},
                     {"max_normal_angle_deg", u.max_normal_angle_deg}, {"max_iterations", u.max_iterations},
                     {"tolerance", u.tolerance}, {"marker_weight", u.marker_weight}, {"match_weight", u.match_weight},
                     {"support_points", u.support_points}, {"propagation_weight", u.propagation_weight}, {"rim_rejection", u.rim_rejection},
                     {"plane_fit", u.plane_fit}, {"binned_matching", u.binned_matching}, {"rotation_field", u.rotation_field}, {"estimate_scale", u.estimate_scale},
                     {"propagate_displacements", u.propagate_displacements}, {"refine_rotations", u.refine_rotations},
                     {"laplacian_updating", u.laplacian_updating}, {"remeshing", u.remeshing},
                     {"subdivision_error", u.subdivision_error}, {"fairing", u.fairing}, {"pleat_collapse", u.pleat_collapse},
                     {"check_self_intersections", u.check_self_intersections},
                     {"radius_steps", u.radius_steps}, {"freeze_constraints", u.freeze_constraints},
                     {"freeze_iteration", u.freeze_iteration}, {"relaxation", u.relaxation},
                     {"detail_rounds", u.detail_rounds}, {"pull_rounds", u.pull_rounds}, {"detail_iterations", u.detail_iterations},
                     {"detail_weight", u.detail_weight}, {"detail_surface_weight", u.detail_surface_weight},
                     {"detail_residual_matching", u.detail_residual_matching}, {"detail_radius_factor", u.detail_radius_factor},
                     {"detail_pull_unexplained", u.detail_pull_unexplained},
                     {"detail_normal_angle_deg", u.detail_normal_angle_deg}, {"detail_tolerance", u.detail_tolerance},
                     {"detail_marker_weight", u.detail_marker_weight}, {"consistent_normals", u.consistent_normals},
                     {"coarse_nodes", u.coarse_nodes}, {"coarse_rounds", u.coarse_rounds}, {"coarse_steps", u.coarse_steps},
                     {"coarse_radius", u.coarse_radius}, {"coarse_stiffness", u.coarse_stiffness},
                     {"coarse_final_stiffness", u.coarse_final_stiffness}, {"coarse_normal_angle_deg", u.coarse_normal_angle_deg},
                     {"coarse_point_weight", u.coarse_point_weight}, {"coarse_prepass_nodes", u.coarse_prepass_nodes}};
  j["counts"] = {{"points", r.points_total}, {"points_skipped_nonfinite", r.points_skipped_nonfinite},
                 {"points_excluded", r.points_excluded}, {"normals_estimated", r.normals_estimated},
                 {"normals_flipped_for_consistency", r.normals_flipped_for_consistency},
                 {"vertices", r.vertices}, {"faces", r.faces}, {"matched", r.matched}, {"propagated", r.propagated},
                 {"masked", r.masked}, {"detail_iterations_run", r.detail_iterations_run},
                 {"detail_surface_constraints", r.detail_surface_constraints},
                 {"detail_points_tracked", r.detail_points_tracked}, {"detail_rounds_pulling", r.detail_rounds_pulling}, {"pull_rounds_run", r.pull_rounds_run}};
  j["metrics"] = {{"bbox_diagonal", r.bbox_diagonal}, {"point_spacing", r.point_spacing},
                  {"hausdorff", r.hausdorff}, {"hausdorff_relative", r.hausdorff_rel}, {"rms", r.rms},
                  {"mean", r.mean}, {"p99", r.p99}, {"tail_mean", r.tail_mean}, {"coverage_vertices", r.coverage_vertices},
                  {"coverage_points", r.coverage_points}, {"flipped_faces", r.flipped_faces}, {"folded_edges", r.folded_edges},
                  {"local_folds", r.local_folds}, {"untangled_vertices", r.untangled_vertices},
                  {"self_intersections", r.self_intersections},
                  {"self_intersections_before_repair", r.self_intersections_before},
                  {"pleat_faces_before", r.pleat_faces_before}, {"pleat_faces_after", r.pleat_faces_after},
                  {"pleat_collapses", r.pleat_collapses}};
  j["unexplained_regions"] = nlohmann::json::array();
  for (const auto& u : r.unexplained)
    j["unexplained_regions"].push_back(
        {{"points", u.points}, {"centre", {u.centre.x(), u.centre.y(), u.centre.z()}}, {"max_distance", u.max_distance}});
  j["timings_s"] = {{"normals", r.t_normals},     {"search_structure", r.t_search}, {"initial_deformation", r.t_initial},
                    {"coarse_stage", r.t_coarse},
                    {"global_scale", r.t_scale},  {"iterations", r.t_iterations},   {"matching", r.t_matching},
                    {"solve", r.t_solve},         {"propagation", r.t_propagation}, {"detail", r.t_detail}, {"pull", r.t_pull},
                    {"remeshing", r.t_remeshing},
                    {"fairing", r.t_fairing},     {"metrics", r.t_metrics},         {"total", r.t_total}};
  return j;
}

}  // namespace tbsp
