#include "tbsp/plugins/deform_report.h"

#include <algorithm>

namespace tbsp {

nlohmann::json deform_report_json(const DeformReport& r) {
  nlohmann::json j;
  j["timings_s"] = {{"laplacian", r.t_laplacian}, {"constraint_graph", r.t_graph}, {"factorize", r.t_factorize},
                    {"rotations", r.t_rotations},  {"solve", r.t_solve},
                    {"total", r.t_laplacian + r.t_graph + r.t_factorize + r.t_rotations + r.t_solve}};
  j["counts"] = {{"vertices", r.vertices},
                 {"free_vertices", r.free_vertices},
                 {"isolated_vertices_kept", r.fixed_isolated},
                 {"position_constraints", r.position_constraints},
                 {"line_constraints", r.line_constraints},
                 {"plane_constraints", r.plane_constraints},
                 {"hard_constraints", r.hard_constraints},
                 {"rotation_field_nodes", r.rotation_nodes}};
  j["solver"] = {{"backend", r.backend}, {"coupled_xyz", r.coupled_xyz}, {"refactorized", r.refactorized},
                 {"rotation_field", r.rotation_field}, {"scale", r.scale}};
  nlohmann::json by_type = nlohmann::json::object();
  for (const char* t : {"position", "line", "plane", "hard"}) by_type[t] = {{"count", 0}, {"max", 0.0}};
  nlohmann::json each = nlohmann::json::array();
  for (const auto& c : r.residuals) {
    const char* t = c.hard ? "hard" : c.type == ConstraintType::Position ? "position" : c.type == ConstraintType::Line ? "line" : "plane";
    by_type[t]["count"] = by_type[t]["count"].get<int>() + 1;
    by_type[t]["max"] = std::max(by_type[t]["max"].get<double>(), c.distance);
    each.push_back({{"id", c.id}, {"type", t}, {"distance", c.distance}});
  }
  j["residuals"] = {{"max", r.max_residual}, {"rms", r.rms_residual}, {"by_type", by_type}, {"constraints", each}};
  return j;
}

}  // namespace tbsp
