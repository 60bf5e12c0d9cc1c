#include "deform_cmds.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "command.h"
#include "progress_bar.h"
#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/plugins/deform_report.h"

namespace tbsp::cli {

tbsp::TriMesh run_deform(const tbsp::TriMesh& mesh, const tbsp::DeformJob& job, bool rotation_field, bool uniform,
                         double scale, bool quiet, tbsp::DeformReport& report) {
  tbsp::cli::ProgressBar bar(!quiet);
  tbsp::LaplacianDeformer d;
  d.setProgressCallback(bar.callback());
  if (uniform) d.setLaplacianWeights(tbsp::LaplacianWeights::Uniform);
  else if (job.weights) d.setLaplacianWeights(*job.weights);
  d.setMesh(mesh);
  for (const auto& c : job.constraints) d.addConstraint(c);
  d.setUseRotationField(rotation_field || job.rotation_field.value_or(false));
  d.setScale(scale > 0 ? scale : job.scale);
  tbsp::TriMesh out = mesh;
  out.V = d.deform();
  out.N.resize(0, 3);
  bar.finish();
  report = d.report();
  return out;
}

namespace {

struct DeformArgs {
  std::string mesh, constraints, out, report;
  bool rotation_field = false, uniform = false, quiet = false, self_intersections = false;
  double scale = 0;  // 0 = from the constraints file
};

int cmd_deform(const DeformArgs& a) {
  const tbsp::TriMesh mesh = tbsp::read_mesh(a.mesh);
  const tbsp::DeformJob job = tbsp::load_constraints_json(a.constraints, mesh);
  if (job.constraints.empty())
    throw tbsp::InvalidInput(a.constraints + ": no constraints; at least one position constraint is needed");
  tbsp::DeformReport rep;
  tbsp::TriMesh out;
  try {
    out = run_deform(mesh, job, a.rotation_field, a.uniform, a.scale, a.quiet, rep);
  } catch (const tbsp::InvalidInput& e) {
    throw tbsp::InvalidInput("deforming " + a.mesh + " with " + a.constraints + ": " + e.what());  // the files, with the library's item
  }
  // crossings the deformation made: counted on the input and the output (exact predicates; -1
  // where the mesh is not a consistently oriented manifold)
  int cross_in = -1, cross_out = -1;
  if (a.self_intersections) {
    try {
      cross_in = tbsp::count_self_intersections(mesh.V, mesh.F);
      cross_out = tbsp::count_self_intersections(out.V, out.F);
    } catch (const tbsp::InvalidInput& e) {
      if (!a.quiet) std::cout << "self-intersections not checked: " << e.what() << "\n";
    }
  }
  tbsp::write_mesh(a.out, out);
  nlohmann::json j = tbsp::deform_report_json(rep);
  if (a.self_intersections) j["self_intersections"] = {{"input", cross_in}, {"output", cross_out}};
  j["input"] = {{"mesh", a.mesh}, {"constraints", a.constraints}};
  j["output"] = a.out;
  if (!a.report.empty()) tbsp::write_text_file_atomic(a.report, j.dump(2) + "\n");
  if (!a.quiet)
    std::cout << "deformed " << rep.vertices << " vertices with " << job.constraints.size() << " constraints"
              << (rep.rotation_field ? " (rotation field, " + std::to_string(rep.rotation_nodes) + " nodes)" : "")
              << ": factorize " << rep.t_factorize * 1e3 << " ms, solve " << rep.t_solve * 1e3
              << " ms, max residual " << rep.max_residual << " -> " << a.out << "\n"
              << (cross_out >= 0 ? "  self-intersecting face pairs: " + std::to_string(cross_in) + " in the input, " +
                                       std::to_string(cross_out) + " in the output\n"
                                 : "");
  return 0;
}

}  // namespace

void add_deform_commands(CLI::App& app, CommandTable& table) {
  auto a = std::make_shared<DeformArgs>();
  auto* deform = app.add_subcommand("deform", "Laplacian deformation of a mesh under constraints (thesis ch. 3)");
  deform->add_option("--mesh", a->mesh, "input mesh (.ply .obj .off .vtk)")->required()->check(CLI::ExistingFile);
  deform->add_option("--constraints", a->constraints, "constraints JSON (docs/constraints_json.md)")->required()->check(CLI::ExistingFile);
  deform->add_option("--out", a->out, "output mesh (.ply .obj .off .vtk), written atomically")->required();
  deform->add_flag("--rotation-field", a->rotation_field, "estimate and apply the rotation field of §3.2.3 (eq. 3.12)");
  deform->add_flag("--uniform", a->uniform, "uniform instead of cotangent Laplacian weights");
  deform->add_flag("--check-self-intersections", a->self_intersections,
                   "count pairs of faces that cross each other in the input and the output (report: self_intersections)");
  deform->add_option("--scale", a->scale, "global scale λ of the differential coordinates (§5.2)")->check(CLI::PositiveNumber);
  deform->add_option("--report", a->report, "JSON report: timings, counts, residuals");
  deform->add_flag("-q,--quiet", a->quiet, "no progress bar or summary");

  table.push_back({deform, [a] { return cmd_deform(*a); }});
}

}  // namespace tbsp::cli
