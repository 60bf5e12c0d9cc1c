#include "tet_cmds.h"

#include "command.h"

#include <chrono>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>

#include "progress_bar.h"
#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/deform/tet_deformer.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/tet_mesh_io.h"
#include "tbsp/plugins/tet_job_json.h"
#include "tbsp/plugins/tet_job_run.h"

namespace fs = std::filesystem;

namespace tbsp::cli {

namespace {

bool is_tet_file(const std::string& p) { return lower_ext(p) == ".mesh"; }

}  // namespace

void add_tetdeform(CLI::App& app, TetDeformArgs& a, CLI::App*& sub) {
  sub = app.add_subcommand("tetdeform", "volumetric as-rigid-as-possible deformation on a tet mesh (thesis ch. 7) + transfer (§7.3)");
  sub->add_option("--mesh", a.mesh, "input: a closed triangle mesh (.ply .obj .off .vtk) or a tet mesh (.mesh)")
      ->required()->check(CLI::ExistingFile);
  sub->add_option("--handles", a.handles, "handles JSON (docs/tetdeform_json.md)")->required()->check(CLI::ExistingFile);
  sub->add_option("--out", a.out, "output: deformed input surface (.ply .obj .off .vtk) or tet mesh (.mesh)")->required();
  sub->add_option("--tets", a.tets, "target tetrahedron count: the surface is decimated (QEM) and tetrahedralized "
                                    "(TetGen); 0 = tetrahedralize at full resolution")->check(CLI::NonNegativeNumber);
  sub->add_option("--iterations", a.iterations, "iterations (default: the handles file's, else 50)")->check(CLI::PositiveNumber);
  sub->add_option("--rigid", a.rigid, "rigid regions JSON {\"rigid\": [region, ...]}")->check(CLI::ExistingFile);
  sub->add_option("--stiffness", a.stiffness, "stiffness JSON {\"default\": s, \"regions\": [...]}")->check(CLI::ExistingFile);
  sub->add_option("--report", a.report, "JSON report: sizes, per-step timings, E_nonrigid per iteration");
  sub->add_option("--save-tets", a.save_tets, "also write the deformed tet mesh (.mesh)");
  sub->add_flag("--no-rotation-interpolation", a.no_interpolation, "disable step (III)");
  sub->add_flag("-q,--quiet", a.quiet, "no progress bar or summary");
}

int cmd_tetdeform(const TetDeformArgs& a) {
  nlohmann::json rep;
  const auto t_start = Clock::now();
  // 1. input and tet mesh
  const bool input_tets = is_tet_file(a.mesh);
  const TetJobSetup setup = input_tets ? tet_job_setup(read_tet_mesh(a.mesh)) : tet_job_setup(read_mesh(a.mesh), a.tets, a.mesh);
  const TetMesh& tets = setup.tets;
  const Eigen::Index n_in = setup.numInputVertices();

  // 2. job files
  const TetJobFiles files = TetJobFiles::load(a.handles, a.rigid, a.stiffness);
  const TetJob job = files.parse(n_in);

  // 3. deformer
  TetDeformer d;
  d.setMesh(tets);
  const TetDeformerOptions o = tet_job_options(job, !a.no_interpolation);
  d.setOptions(o);
  apply_tet_job(setup, job, files, d);
  ProgressBar bar(!a.quiet);
  d.setProgressCallback(bar.callback());
  const int iterations = a.iterations > 0 ? a.iterations : job.iterations.value_or(50);
  auto t0 = Clock::now();
  try {
    d.deform(iterations);
  } catch (const InvalidInput& e) {
    // handle-set problems surface at the first solve; name the file
    throw InvalidInput(a.handles + ": " + e.what());
  }
  const double t_deform = seconds_since(t0);
  bar.finish();
  const TetDeformReport& r = d.report();

  // 4. output
  double t_pre = 0, t_apply = 0;
  if (is_tet_file(a.out)) {
    TetMesh outm = d.mesh();
    outm.V = d.positions();
    write_tet_mesh(a.out, outm);
  } else {
    write_mesh(a.out, deformed_surface(setup, d, &t_pre, &t_apply));
  }
  if (!a.save_tets.empty()) {
    TetMesh outm = d.mesh();
    outm.V = d.positions();
    write_tet_mesh(a.save_tets, outm);
  }

  // 5. report
  const int it = std::max(1, r.iterations);
  rep["input"] = {{"mesh", a.mesh}, {"handles", a.handles}, {"vertices", n_in}};
  rep["output"] = a.out;
  rep["tet_mesh"] = {{"vertices", r.vertices}, {"tets", r.tets}, {"decimated", setup.decimated}, {"added_vertices", r.added_vertices},
                     {"split_tets", r.split_tets}, {"virtual_tets", r.virtual_tets}};
  rep["handles"] = {{"vertex", r.vertex_handles}, {"region", r.region_handles}, {"point", r.point_handles},
                    {"constrained_vertices", r.constrained_vertices}, {"rigid_regions", r.rigid_regions},
                    {"rotation_handle_tets", r.rotation_handle_tets}};
  rep["options"] = {{"iterations", iterations}, {"rotation_interpolation", o.rotation_interpolation},
                    {"max_step_degrees", o.max_handle_step_deg}, {"tolerance", o.tolerance}};
  rep["iterations"] = r.iterations;
  rep["converged"] = r.converged;
  rep["e_nonrigid"] = r.e_nonrigid;
  rep["e_arap"] = r.e_arap;
  rep["volume_ratio"] = r.volume_ratio;
  rep["max_handle_residual"] = r.max_handle_residual;
  rep["solver"] = r.backend;
  const double per_it = (r.t_def + r.t_rotext + r.t_rotint + r.t_rigid + r.t_difupd) / it;
  rep["timings_s"] = {{"tetrahedralize", setup.tetrahedralize_seconds}, {"setup", r.t_setup}, {"factorize", r.t_factorize},
                      {"factorize_rotint", r.t_factorize_rotint}, {"deform_total", t_deform},
                      {"per_iteration", {{"def", r.t_def / it}, {"rotext", r.t_rotext / it}, {"rotint", r.t_rotint / it},
                                         {"rigid", r.t_rigid / it}, {"difupd", r.t_difupd / it}, {"total", per_it}}},
                      {"iterations_per_s", per_it > 0 ? 1.0 / per_it : 0.0},
                      {"transfer_precompute", t_pre}, {"transfer_apply", t_apply}, {"total", seconds_since(t_start)}};
  if (!a.report.empty()) write_text_file_atomic(a.report, rep.dump(2) + "\n");
  if (!a.quiet)
    std::cout << "tetdeform: " << r.vertices << " vertices / " << r.tets << " tets, " << r.iterations << " iterations ("
              << (r.converged ? "converged" : "not converged") << "), E_nonrigid " << r.e_nonrigid.front() << " -> "
              << r.e_nonrigid.back() << ", volume " << (r.volume_ratio - 1) * 100 << " %, " << (per_it > 0 ? 1.0 / per_it : 0)
              << " iterations/s -> " << a.out << "\n";
  return 0;
}

void add_tet_commands(CLI::App& app, CommandTable& table) {
  register_command<TetDeformArgs>(app, table, add_tetdeform, cmd_tetdeform);
}

}  // namespace tbsp::cli
