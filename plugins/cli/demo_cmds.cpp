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
#include "deform_cmds.h"
#include "tbsp/fitting/template_fitting.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/mesh/point_search.h"
#include "tbsp/plugins/deform_report.h"
#include "tbsp/plugins/fit_json.h"
#include "tbsp/plugins/preview_render.h"

namespace fs = std::filesystem;

namespace tbsp::cli {

namespace {

// Template fitting demo (thesis ch. 5) on the sample data: template, synthetic scan, markers.
void demo_fit(const std::string& sample_dir, const std::string& out_dir, bool quiet) {
  const tbsp::TriMesh templ = tbsp::read_mesh(sample_dir + "/bumpy_bar.off");
  const tbsp::TriMesh scan = tbsp::read_mesh(sample_dir + "/bar_scan.ply");
  const std::vector<tbsp::FitMarker> markers = tbsp::load_markers_json(sample_dir + "/bar_markers.json");
  tbsp::cli::ProgressBar bar(!quiet);
  std::vector<tbsp::VertexStatus> status;
  tbsp::TriMesh fit;
  const tbsp::FitReport rep = tbsp::fit_template(templ, scan.V, scan.N, markers, {}, {}, fit, status, bar.callback());
  bar.finish();
  tbsp::write_mesh(out_dir + "/fitted.ply", fit);
  nlohmann::json j = tbsp::fit_report_json(rep);
  tbsp::write_text_file_atomic(out_dir + "/fit_report.json", j.dump(2) + "\n");
  // error colouring: distance of each fitted vertex to the nearest scan point
  const tbsp::PointSearch tree(scan.V);
  Eigen::VectorXd d(fit.V.rows());
  for (Eigen::Index v = 0; v < fit.V.rows(); ++v) {
    double d2 = 0;
    tree.nearest(fit.V.row(v).transpose(), &d2);
    d(v) = std::sqrt(d2);
  }
  tbsp::TriMesh colored = fit;
  const double dmax = 2.0;  // colour scale, % of the diagonal
  colored.C = tbsp::colormap(100.0 * d / rep.bbox_diagonal, 0, dmax);
  tbsp::RenderPanel scan_panel(tbsp::TriMesh(), "input: scan, " + std::to_string(scan.V.rows()) + " points (hole, 5% outliers)");
  scan_panel.points = scan.V;
  tbsp::RenderPanel fit_panel(colored, "fit: distance to the nearest scan point");
  fit_panel.colorbar = true;
  fit_panel.colorbar_lo = 0;
  fit_panel.colorbar_hi = dmax;
  fit_panel.colorbar_label = "% of the diagonal (red: the hole, filled)";
  tbsp::RenderOptions ro;
  ro.azimuth_deg = 20;
  ro.elevation_deg = 30;
  tbsp::render_panels_png(out_dir + "/fit.png",
                          {{templ, "template (" + std::to_string(templ.V.rows()) + " vertices)"}, scan_panel, fit_panel}, ro);
  // the figures a newcomer reads first: robust ones. The scan holds 5 % uniform outliers by
  // design (synth-scan --outliers 0.05, sample_data/README.md), so its largest distances to any
  // surface are the outliers', not the fit's.
  Eigen::VectorXd sd = tbsp::point_mesh_distances(fit.V, fit.F, scan.V) / rep.bbox_diagonal * 100.0;
  std::vector<double> q(sd.data(), sd.data() + sd.size());
  std::sort(q.begin(), q.end());
  auto quant = [&](double f) { return q.empty() ? 0.0 : q[std::size_t(f * double(q.size() - 1))]; };
  std::printf("tbsp demo (chapter 5): fitted %s/bumpy_bar.off (%ld vertices) to bar_scan.ply (%ld points, %zu markers) in "
              "%.2f s, %d iterations\n"
              "  distance of the scan points to the fit, %% of the diagonal: median %.3f, 90%% of the points within %.3f\n"
              "  (the scan's noise alone, sigma 0.2 %%, puts the median at 0.135)\n"
              "  global scale %.3f (the scan was made at x1.5); %ld vertices matched to the data, %ld filled in across the 25%% hole\n"
              "  (the scan also holds 5%% uniform outliers, by design: 95%% within %.3f, the farthest outlier %.1f)\n"
              "  wrote %s/fitted.ply, fit_report.json, fit.png\n",
              sample_dir.c_str(), (long)templ.V.rows(), (long)scan.V.rows(), markers.size(), rep.t_total, rep.iterations,
              quant(0.5), quant(0.9), rep.scale, (long)rep.matched, (long)rep.propagated, quant(0.95), q.empty() ? 0.0 : q.back(),
              out_dir.c_str());
}

int cmd_demo(const std::string& sample_dir, const std::string& out_dir, bool quiet) {
  const std::string mesh_path = sample_dir + "/bumpy_bar.off";
  const std::string cons_path = sample_dir + "/bend_90.json";
  fs::create_directories(out_dir);
  demo_fit(sample_dir, out_dir, quiet);
  const tbsp::TriMesh mesh = tbsp::read_mesh(mesh_path);
  const tbsp::DeformJob job = tbsp::load_constraints_json(cons_path, mesh);
  tbsp::DeformReport rep_lin, rep_rot;
  const tbsp::TriMesh lin = run_deform(mesh, job, false, false, 0, true, rep_lin);
  const tbsp::TriMesh rot = run_deform(mesh, job, true, false, 0, quiet, rep_rot);
  tbsp::write_mesh(out_dir + "/bent_rotation_field.ply", rot);
  tbsp::write_mesh(out_dir + "/bent_linear.ply", lin);
  // how much each result changed the local shape: edge-length distortion per vertex
  auto distortion = [&](const tbsp::TriMesh& m) {
    Eigen::VectorXd d = Eigen::VectorXd::Zero(m.V.rows()), cnt = Eigen::VectorXd::Zero(m.V.rows());
    for (Eigen::Index f = 0; f < m.F.rows(); ++f)
      for (int k = 0; k < 3; ++k) {
        const int a = m.F(f, k), b = m.F(f, (k + 1) % 3);
        const double l0 = (mesh.V.row(a) - mesh.V.row(b)).norm(), l1 = (m.V.row(a) - m.V.row(b)).norm();
        const double e = std::abs(l1 / l0 - 1);
        d(a) += e; d(b) += e; cnt(a) += 1; cnt(b) += 1;
      }
    return Eigen::VectorXd(d.cwiseQuotient(cnt.cwiseMax(1)));
  };
  const Eigen::VectorXd dl = distortion(lin), dr = distortion(rot);
  tbsp::TriMesh lin_c = lin, rot_c = rot;
  lin_c.C = tbsp::colormap(dl, 0, 0.5);
  rot_c.C = tbsp::colormap(dr, 0, 0.5);
  // the input with its constraints: fixed vertices blue, moved ones red, their targets as dots
  tbsp::TriMesh in_c = mesh;
  in_c.C = Eigen::MatrixX3d::Constant(mesh.V.rows(), 3, 0.8);
  tbsp::RenderPanel in_panel(in_c, "input + constraints (targets: dots)");
  in_panel.points.resize(Eigen::Index(job.constraints.size()), 3);
  in_panel.point_colors.resize(Eigen::Index(job.constraints.size()), 3);
  for (std::size_t k = 0; k < job.constraints.size(); ++k) {
    const auto& c = job.constraints[k];
    in_panel.points.row(Eigen::Index(k)) = c.target.transpose();
    in_panel.point_colors.row(Eigen::Index(k)) = Eigen::RowVector3d(0.85, 0.2, 0.15);
    if (c.at.vertex < 0) continue;  // (the demo's constraints are on vertices)
    const bool moved = (c.target - mesh.V.row(c.at.vertex).transpose()).norm() > 1e-9;
    in_c.C.row(c.at.vertex) = moved ? Eigen::RowVector3d(0.85, 0.2, 0.15) : Eigen::RowVector3d(0.2, 0.35, 0.85);
    in_panel.points.row(Eigen::Index(k)) = c.target.transpose();
    in_panel.point_colors.row(Eigen::Index(k)) = moved ? Eigen::RowVector3d(0.85, 0.2, 0.15) : Eigen::RowVector3d(0.2, 0.35, 0.85);
  }
  in_panel.mesh = in_c;
  auto strain_panel = [](const tbsp::TriMesh& m, const std::string& title) {
    tbsp::RenderPanel p(m, title);
    p.colorbar = true;
    p.colorbar_lo = 0;
    p.colorbar_hi = 0.5;
    p.colorbar_label = "edge strain |l'/l - 1|";
    return p;
  };
  tbsp::RenderOptions ro;
  ro.azimuth_deg = 0;
  ro.elevation_deg = 0;
  tbsp::render_panels_png(out_dir + "/demo.png",
                          {in_panel, strain_panel(lin_c, "linear (eq. 3.6)"), strain_panel(rot_c, "rotation field (eq. 3.12)")},
                          ro);
  nlohmann::json j;
  j["linear"] = tbsp::deform_report_json(rep_lin);
  j["rotation_field"] = tbsp::deform_report_json(rep_rot);
  j["mean_edge_strain"] = {{"linear", dl.mean()}, {"rotation_field", dr.mean()}};
  tbsp::write_text_file_atomic(out_dir + "/report.json", j.dump(2) + "\n");
  std::cout << "tbsp demo (chapter 3): bent " << mesh_path << " by 90 degrees (" << job.constraints.size() << " constraints)\n"
            << "  mean edge strain: linear " << dl.mean() << ", with rotation field " << dr.mean() << "\n"
            << "  wrote " << out_dir << "/bent_rotation_field.ply, bent_linear.ply, demo.png, report.json\n";
  return 0;
}

struct DemoArgs {
  std::string in = TBSP_SAMPLE_DATA_DIR, out = "tbsp_demo_out";
  bool quiet = false;
};

}  // namespace

void add_demo_commands(CLI::App& app, CommandTable& table) {
  auto d = std::make_shared<DemoArgs>();
  auto* demo = app.add_subcommand("demo", "run the demos on sample_data/: template fitting (ch. 5) and bending (ch. 3)");
  demo->add_option("--data", d->in, "sample data folder");
  demo->add_option("--out", d->out, "output folder");
  demo->add_flag("-q,--quiet", d->quiet, "no progress bar");

  table.push_back({demo, [d] { return cmd_demo(d->in, d->out, d->quiet); }});
}

}  // namespace tbsp::cli
