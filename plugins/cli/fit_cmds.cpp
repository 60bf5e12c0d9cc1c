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
#include "tbsp/fitting/template_fitting.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/cloud_io.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/point_search.h"
#include "tbsp/plugins/fit_json.h"
#include "tbsp/plugins/preview_render.h"
#include "tbsp/plugins/synthetic_scan.h"

namespace tbsp::cli {

namespace {

struct FitArgs {
  std::string templ, cloud, markers, out, status, report, roi, png;
  tbsp::FitParameters p;
  bool no_prop = false, no_scale = false, no_field = false, quiet = false, kernel_detail = false, no_pleats = false, no_detail_pull = false;
};

int cmd_fit(FitArgs a) {
  const tbsp::TriMesh templ = tbsp::read_mesh(a.templ);
  bool has_normals = false;
  const auto cloud = tbsp::read_cloud_normals(a.cloud, &has_normals);
  if (cloud->empty()) throw tbsp::InvalidInput(a.cloud + ": the cloud is empty");
  // no markers: the template must be roughly in place; it is aligned first (trimmed ICP)
  const std::vector<tbsp::FitMarker> markers =
      a.markers.empty() ? std::vector<tbsp::FitMarker>{} : tbsp::load_markers_json(a.markers);
  tbsp::RegionOfInterest roi;
  if (!a.roi.empty()) roi = tbsp::load_roi_json(a.roi);
  a.p.propagate_displacements = !a.no_prop;
  a.p.estimate_scale = !a.no_scale;
  a.p.rotation_field = !a.no_field;
  a.p.detail_residual_matching = !a.kernel_detail;
  a.p.detail_pull_unexplained = !a.no_detail_pull;
  a.p.pleat_collapse = !a.no_pleats;
  if (a.p.coarse_prepass_nodes == std::vector<int>{0}) a.p.coarse_prepass_nodes.clear();  // --coarse-prepass-nodes 0
  tbsp::cli::ProgressBar bar(!a.quiet);
  tbsp::TriMesh out;
  tbsp::FitReport rep;
  std::vector<tbsp::VertexStatus> status;
  auto run = [&](auto& fit) {
    fit.setInputTemplate(templ);
    fit.setMarkers(markers);
    fit.setParameters(a.p);
    fit.setRegionOfInterest(roi);
    fit.setProgressCallback(bar.callback());
    try {
      rep = fit.reconstruct(out);
    } catch (const tbsp::InvalidInput& e) {
      // the library names the item (markers[3], the cloud's normals, ...); the files are the CLI's
      throw tbsp::InvalidInput("fitting " + a.templ + " to " + a.cloud + (a.markers.empty() ? "" : " with " + a.markers) + ": " +
                               e.what());
    }
    status = fit.getVertexStatus();
  };
  if (has_normals) {
    tbsp::TemplateFitting<pcl::PointNormal> fit;
    fit.setInputCloud(cloud);
    run(fit);
  } else {
    pcl::PointCloud<pcl::PointXYZ>::Ptr xyz(new pcl::PointCloud<pcl::PointXYZ>);
    for (const auto& q : *cloud) xyz->push_back(pcl::PointXYZ(q.x, q.y, q.z));
    tbsp::TemplateFitting<pcl::PointXYZ> fit;
    fit.setInputCloud(xyz);
    run(fit);
  }
  bar.finish();
  tbsp::write_mesh(a.out, out);
  if (!a.status.empty()) {
    std::string text = "# per output vertex: matched | propagated | masked | unmatched\n";
    for (auto st : status) text += std::string(tbsp::to_string(st)) + "\n";
    tbsp::write_text_file_atomic(a.status, text);
  }
  nlohmann::json j = tbsp::fit_report_json(rep);
  j["input"] = {{"template", a.templ}, {"cloud", a.cloud}, {"markers", a.markers}, {"roi", a.roi}};
  j["output"] = a.out;
  if (!a.report.empty()) tbsp::write_text_file_atomic(a.report, j.dump(2) + "\n");
  if (!a.png.empty()) {
    Eigen::MatrixX3d P(Eigen::Index(cloud->size()), 3);
    Eigen::Index n = 0;
    for (const auto& q : *cloud)
      if (std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.z)) P.row(n++) << q.x, q.y, q.z;
    P.conservativeResize(n, 3);
    const tbsp::PointSearch tree(P);
    Eigen::VectorXd d(out.V.rows());
    for (Eigen::Index v = 0; v < out.V.rows(); ++v) {
      double d2 = 0;
      tree.nearest(out.V.row(v).transpose(), &d2);
      d(v) = std::sqrt(d2);
    }
    tbsp::TriMesh colored = out, st = out;
    colored.C = tbsp::colormap(d, 0, 0.01 * rep.bbox_diagonal);
    Eigen::VectorXd sv(out.V.rows());
    for (Eigen::Index v = 0; v < sv.rows(); ++v) sv(v) = status[std::size_t(v)] == tbsp::VertexStatus::Matched ? 0.0 : status[std::size_t(v)] == tbsp::VertexStatus::Propagated ? 0.5 : 1.0;
    st.C = tbsp::colormap(sv, 0, 1);
    tbsp::render_panels_png(a.png, {{templ, "template"}, {colored, "fit: distance to scan 0..1% diag"},
                                    {st, "blue matched, green propagated, red masked"}});
  }
  if (!a.quiet)
    std::cout << "fitted " << out.V.rows() << " vertices to " << cloud->size() << " points: " << rep.iterations
              << " iterations, scale " << rep.scale << ", Hausdorff " << 100 * rep.hausdorff_rel << "% of the bbox diagonal (rms "
              << 100 * rep.rms / rep.bbox_diagonal << "%), " << rep.t_total << " s -> " << a.out << "\n"
              << (rep.message.empty() ? "" : "  note: " + rep.message + "\n");
  return 0;
}

struct SynthArgs {
  std::string mesh, cloud, markers, truth;
  tbsp::synth::ScenarioOptions o;
};

int cmd_synth_scan(const SynthArgs& a) {
  const tbsp::TriMesh m = tbsp::read_mesh(a.mesh);
  tbsp::synth::Scenario s;
  try {
    s = tbsp::synth::make_scenario(m, a.o);
  } catch (const tbsp::InvalidInput& e) {
    throw tbsp::InvalidInput(a.mesh + ": " + e.what());  // the options' and the mesh's problems, with the file
  }
  tbsp::TriMesh cloud;
  cloud.V = s.P;
  cloud.N = s.N;
  cloud.F.resize(0, 3);
  tbsp::write_mesh(a.cloud, cloud);  // PLY/OBJ/OFF/VTK vertices (+ normals where the format has them)
  nlohmann::json mk;
  mk["comment"] = "generated by tbsp synth-scan from " + a.mesh;
  for (const auto& x : s.markers) mk["markers"].push_back({{"template_vertex", x.template_vertex}, {"cloud_index", x.cloud_index}});
  tbsp::write_text_file_atomic(a.markers, mk.dump(1) + "\n");
  if (!a.truth.empty()) {
    tbsp::TriMesh t = m;
    t.V = s.target;
    t.N.resize(0, 3);
    tbsp::write_mesh(a.truth, t);
  }
  std::cout << "synthetic scan: " << s.P.rows() << " points (" << 100 * a.o.outliers << "% outliers), hole "
            << 100 * s.hole_area_fraction << "% of the surface, " << s.markers.size() << " markers\n";
  return 0;
}

}  // namespace

void add_fit_commands(CLI::App& app, CommandTable& table) {
  auto a = std::make_shared<FitArgs>();
  auto* fitc = app.add_subcommand("fit", "fit a template mesh to a point cloud (thesis ch. 5)");
  fitc->add_option("--template", a->templ, "template mesh (.ply .obj .off .vtk)")->required()->check(CLI::ExistingFile);
  fitc->add_option("--cloud", a->cloud, "scan (.pcd, or .ply/.obj/.off/.vtk vertices); normals used if present")->required()->check(CLI::ExistingFile);
  fitc->add_option("--markers", a->markers,
                   "markers JSON (docs/fit_json.md); without: the template must be roughly in place (within ~10 deg, "
                   "~5 %) and is aligned to the scan first (rotation, scale, translation by trimmed ICP)")
      ->check(CLI::ExistingFile);
  fitc->add_option("--out", a->out, "fitted mesh, written atomically")->required();
  fitc->add_option("--status", a->status, "per-vertex status text file");
  fitc->add_option("--report", a->report, "JSON report (iterations, timings, Hausdorff, RMS, coverage)");
  fitc->add_option("--roi", a->roi, "region-of-interest JSON (exclusions)");
  fitc->add_option("--png", a->png, "PNG: template, fit coloured by distance to the scan, status");
  fitc->add_option("--r-max", a->p.max_match_distance, "final match radius r_max (0 = from the data)");
  fitc->add_option("--theta-max", a->p.max_normal_angle_deg, "max normal deviation θ_max in degrees");
  fitc->add_option("--iterations", a->p.max_iterations, "max iterations");
  fitc->add_option("--match-weight", a->p.match_weight, "weight of data constraints");
  fitc->add_option("--coarse-nodes", a->p.coarse_nodes,
                   "coarse stage: nodes of a deformation graph fitted to the scan before the iterations, for parts "
                   "turned about joints (400 is the measured setting; default -1: 400 without markers; with markers the fit runs "
                   "without and with 400 nodes side by side and keeps the one fewer scan points lie far from; 0 = off)");
  fitc->add_option("--coarse-prepass-nodes", a->p.coarse_prepass_nodes,
                   "without markers, with --coarse-nodes: comma-separated nodes of coarser graphs, each fitted first in one "
                   "more hypothesis; the fit closest to the scan is kept (default 100,200; 0 = one hypothesis)")
      ->delimiter(',');
  fitc->add_option("--detail-rounds", a->p.detail_rounds,
                   "rounds of Laplacian updating after the fit, unsupported vertices held (sharper protrusions; default -1: 4 on "
                   "templates of at most 20,000 vertices, else 0; 0 = off)");
  fitc->add_option("--pull-rounds", a->p.pull_rounds,
                   "without detail rounds: rounds that move only the vertices near regions of the cloud the fit left "
                   "unexplained, towards those points (default 3; 0 = off)");
  fitc->add_option("--detail-radius-factor", a->p.detail_radius_factor,
                   "kernel radius of the detail rounds' residual matching, x r_max (default 2)");
  fitc->add_option("--detail-normal-angle", a->p.detail_normal_angle_deg,
                   "detail rounds: max angle (degrees) between a point's normal and the face it projects onto (default 40)");
  fitc->add_option("--detail-surface-weight", a->p.detail_surface_weight,
                   "weight of the detail rounds' per-face data constraints (default 0 = off)");
  fitc->add_flag("--detail-no-pull", a->no_detail_pull,
                 "detail rounds: points of unexplained regions pull only within r_max, as other points do (default: at any distance)");
  fitc->add_flag("--detail-kernel-targets", a->kernel_detail,
                 "detail rounds: the §5.3 kernel targets along the normals instead of residual matching");
  fitc->add_flag("--laplacian-updating", a->p.laplacian_updating, "§5.5.1: rebuild the Laplacian each iteration");
  fitc->add_flag("--remesh", a->p.remeshing, "§5.5.2: adaptive subdivision (changes connectivity)");
  fitc->add_flag("--fairing", a->p.fairing, "§5.5.3: tangential fairing against fold-overs");
  fitc->add_flag("--no-pleat-collapse", a->no_pleats,
                 "with --remesh --fairing: keep pleats (faces against the data normals) instead of collapsing them");
  fitc->add_flag("--check-self-intersections", a->p.check_self_intersections,
                 "count the result's intersecting face pairs also without --fairing (with it they are counted and repaired)");
  fitc->add_flag("--refine-rotations", a->p.refine_rotations, "re-estimate the rotation field from the fit");
  fitc->add_flag("--consistent-normals", a->p.consistent_normals,
                 "make estimated normals consistent between neighbours after orienting them by the template");
  fitc->add_flag("--no-propagation", a->no_prop, "skip the displacement propagation of §5.3");
  fitc->add_flag("--no-scale", a->no_scale, "skip the global scale of §5.2");
  fitc->add_flag("--no-rotation-field", a->no_field, "initial deformation without the markers' rotation field (§3.2.3); with --coarse-nodes 400 "
                 "--detail-rounds 4 it fits real scans of a part turned by 45 deg better, synthetic articulations worse (docs/fitting.md)");
  fitc->add_flag("-q,--quiet", a->quiet, "no progress bar or summary");

  table.push_back({fitc, [a] { return cmd_fit(*a); }});
  auto s = std::make_shared<SynthArgs>();
  auto* synth = app.add_subcommand("synth-scan", "synthetic scan with ground truth from a mesh (deform, sample, noise, outliers, hole, markers)");
  synth->add_option("--mesh", s->mesh, "source mesh")->required()->check(CLI::ExistingFile);
  synth->add_option("--out-cloud", s->cloud, "cloud with normals (.ply)")->required();
  synth->add_option("--out-markers", s->markers, "markers JSON for tbsp fit")->required();
  synth->add_option("--out-truth", s->truth, "the deformed mesh (ground truth)");
  synth->add_option("--bend", s->o.bend_deg, "bend angle (degrees)");
  synth->add_option("--twist", s->o.twist_deg, "twist angle (degrees)");
  synth->add_option("--scale", s->o.scale, "uniform scale");
  synth->add_option("--points", s->o.points, "number of points");
  synth->add_option("--noise", s->o.noise, "Gaussian noise sigma / bbox diagonal");
  synth->add_option("--outliers", s->o.outliers, "fraction of uniform outliers");
  synth->add_option("--hole", s->o.hole, "fraction of the surface removed");
  synth->add_option("--markers", s->o.markers, "number of markers");
  synth->add_option("--seed", s->o.seed, "random seed");

  table.push_back({synth, [s] { return cmd_synth_scan(*s); }});
}

}  // namespace tbsp::cli
