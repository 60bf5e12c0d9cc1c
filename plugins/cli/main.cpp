// tbsp — command-line front end of the tbsp plugin suite.
#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>

#include "capture_cmds.h"
#include "mocap_cmds.h"
#include "tet_cmds.h"
#include "texture_cmds.h"
#include "progress_bar.h"
#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/deform/laplacian_deformer.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/cloud_io.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/plugins/constraints_json.h"
#include "tbsp/plugins/deform_report.h"
#include "tbsp/plugins/fit_json.h"
#include "tbsp/fitting/template_fitting.h"
#include "tbsp/mesh/point_search.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/plugins/preview_render.h"
#include "tbsp/plugins/synthetic_scan.h"

namespace fs = std::filesystem;

namespace {

struct DeformArgs {
  std::string mesh, constraints, out, report;
  bool rotation_field = false, uniform = false, quiet = false, self_intersections = false;
  double scale = 0;  // 0 = from the constraints file
};

// Runs one deformation job; returns the deformed mesh and fills the report.
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

int cmd_deform(const DeformArgs& a) {
  const tbsp::TriMesh mesh = tbsp::read_mesh(a.mesh);
  const tbsp::DeformJob job = tbsp::load_constraints_json(a.constraints, mesh);
  if (job.constraints.empty())
    throw tbsp::InvalidInput(a.constraints + ": no constraints; at least one position constraint is needed");
  tbsp::DeformReport rep;
  const tbsp::TriMesh out = run_deform(mesh, job, a.rotation_field, a.uniform, a.scale, a.quiet, rep);
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

struct FitArgs {
  std::string templ, cloud, markers, out, status, report, roi, png;
  tbsp::FitParameters p;
  bool no_prop = false, no_scale = false, no_field = false, quiet = false, kernel_detail = false, no_pleats = false;
};

int cmd_fit(FitArgs a) {
  const tbsp::TriMesh templ = tbsp::read_mesh(a.templ);
  bool has_normals = false;
  const auto cloud = tbsp::read_cloud_normals(a.cloud, &has_normals);
  if (cloud->empty()) throw tbsp::InvalidInput(a.cloud + ": the cloud is empty");
  const std::vector<tbsp::FitMarker> markers = tbsp::load_markers_json(a.markers);
  tbsp::RegionOfInterest roi;
  if (!a.roi.empty()) roi = tbsp::load_roi_json(a.roi);
  a.p.propagate_displacements = !a.no_prop;
  a.p.estimate_scale = !a.no_scale;
  a.p.rotation_field = !a.no_field;
  a.p.detail_residual_matching = !a.kernel_detail;
  a.p.pleat_collapse = !a.no_pleats;
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
    rep = fit.reconstruct(out);
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

struct ValidateArgs {
  std::string mesh, json, against;
  bool strict = false, self_intersections = false;
  double probe = 0;  // 0: 0.1 % of the reference's bounding-box diagonal
};

int cmd_validate(const ValidateArgs& a) {
  const std::string& path = a.mesh;
  const bool self_intersections = a.self_intersections;
  const tbsp::TriMesh mesh = tbsp::read_mesh(path);
  const tbsp::MeshReport r = tbsp::validate_mesh(mesh);
  std::cout << path << ": " << r.summary();
  // self-intersections (exact predicates): only on request, and only where the faces form a
  // consistently oriented manifold mesh (the other problems above come first)
  int crossing = -1;
  std::vector<std::pair<int, int>> pairs;
  if (self_intersections) {
    if (r.nonfinite_vertices.empty() && r.bad_index_faces.empty() && r.nonmanifold_edges.empty() &&
        r.inconsistent_edges.empty() && r.duplicate_faces.empty()) {
      try {
        crossing = tbsp::count_self_intersections(mesh.V, mesh.F, &pairs);
      } catch (const tbsp::InvalidInput& e) {
        std::cout << "  self-intersections: not checked (" << e.what() << ")\n";
      }
    } else {
      std::cout << "  self-intersections: not checked (fix the problems above first: the test needs a consistently "
                   "oriented manifold mesh)\n";
    }
    if (crossing >= 0) {
      std::cout << "  self-intersections: " << crossing << " pairs of faces";
      for (std::size_t k = 0; k < pairs.size() && k < 5; ++k)
        std::cout << (k == 0 ? " (" : ", ") << pairs[k].first << "-" << pairs[k].second;
      std::cout << (pairs.size() > 5 ? ", ...)" : pairs.empty() ? "" : ")") << "\n";
    }
  }
  // orientation against a reference surface (the scan a fit was made from): faces that point into it
  tbsp::ReferenceOrientation ori;
  if (!a.against.empty()) {
    const tbsp::TriMesh ref = tbsp::read_mesh(a.against);
    if (ref.F.rows() == 0)
      throw tbsp::InvalidInput("[tbsp validate] " + a.against +
                               " has no faces: --against needs the reference as a surface mesh (a point cloud cannot be "
                               "probed; reconstruct it or pass the scan's mesh)");
    const double diag = (ref.V.colwise().maxCoeff() - ref.V.colwise().minCoeff()).norm();
    const double d = a.probe > 0 ? a.probe : 0.001 * diag;
    if (!(d > 0)) throw tbsp::InvalidInput("[tbsp validate] " + a.against + " is a single point; give --probe-distance");
    ori = tbsp::check_orientation_against(mesh.V, mesh.F, ref.V, ref.F, d);
    std::cout << "  orientation against " << a.against << " (probe +-" << d << "): " << ori.consistent << " faces agree, "
              << ori.flipped << " point into it";
    for (std::size_t k = 0; k < ori.flipped_faces.size() && k < 5; ++k)
      std::cout << (k == 0 ? " (" : ", ") << ori.flipped_faces[k];
    std::cout << (ori.flipped_faces.size() > 5 ? ", ...)" : ori.flipped_faces.empty() ? "" : ")") << ", " << ori.unmatched
              << " not judged (no reference surface within the probe)"
              << (ori.degenerate ? ", " + std::to_string(ori.degenerate) + " of zero area" : "") << "\n";
  }
  if (!a.json.empty()) {
    nlohmann::json j = {{"file", path},
                        {"vertices", r.num_vertices},
                        {"faces", r.num_faces},
                        {"components", r.components},
                        {"boundary_edges", r.boundary_edges},
                        {"boundary_loops", r.boundary_loops},
                        {"euler_characteristic", r.euler_characteristic},
                        {"genus", r.genus},
                        {"nonfinite_vertices", r.nonfinite_vertices},
                        {"bad_index_faces", r.bad_index_faces},
                        {"degenerate_faces", r.degenerate_faces},
                        {"duplicate_faces", r.duplicate_faces},
                        {"isolated_vertices", r.isolated_vertices},
                        {"nonmanifold_edges", r.nonmanifold_edges},
                        {"inconsistent_edges", r.inconsistent_edges},
                        {"clean", r.isClean()}};
    if (self_intersections) {
      j["self_intersections"] = crossing;  // -1: not checked
      j["self_intersecting_pairs"] = pairs;
    }
    if (!a.against.empty())
      j["against"] = {{"reference", a.against},      {"probe_distance", ori.distance}, {"consistent", ori.consistent},
                      {"flipped", ori.flipped},      {"flipped_faces", ori.flipped_faces},
                      {"unmatched", ori.unmatched}, {"degenerate", ori.degenerate}};
    tbsp::write_text_file_atomic(a.json, j.dump(2) + "\n");
  }
  return a.strict && (!r.isClean() || (self_intersections && crossing != 0) || ori.flipped > 0) ? 4 : 0;
}

struct SynthArgs {
  std::string mesh, cloud, markers, truth;
  tbsp::synth::ScenarioOptions o;
};

int cmd_synth_scan(const SynthArgs& a) {
  const tbsp::TriMesh m = tbsp::read_mesh(a.mesh);
  const tbsp::synth::Scenario s = tbsp::synth::make_scenario(m, a.o);
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

// One panel of `tbsp render`: meshes shaded, files without faces (and .pcd clouds) as points;
// per-vertex / per-point colours from the file, or a scalar (--color-by / --scalar) with a bar.
tbsp::RenderPanel render_panel(const std::string& path, const std::string& color_by, const std::string& scalar_file,
                               const std::vector<double>& range) {
  tbsp::TriMesh m;
  if (fs::path(path).extension() == ".pcd") {
    const auto c = tbsp::read_cloud_normals(path);
    m.V.resize(Eigen::Index(c->size()), 3);
    Eigen::Index n = 0;
    for (const auto& q : *c)
      if (std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.z)) m.V.row(n++) << q.x, q.y, q.z;
    m.V.conservativeResize(n, 3);
    m.F.resize(0, 3);
  } else {
    m = tbsp::read_mesh(path);
  }
  const bool cloud = m.F.rows() == 0;
  tbsp::RenderPanel p(tbsp::TriMesh(), fs::path(path).filename().string() +
                                           (cloud ? " (" + std::to_string(m.V.rows()) + " points)" : std::string()));
  Eigen::VectorXd values;
  std::string label;
  if (!color_by.empty()) {
    values = m.V.col(color_by == "x" ? 0 : color_by == "y" ? 1 : 2);
    label = color_by;
  } else if (!scalar_file.empty()) {
    std::ifstream in(scalar_file);
    if (!in) throw tbsp::FileError("'" + scalar_file + "': cannot open; check the path");
    std::vector<double> v;
    std::string tok;
    while (in >> tok) {
      char* end = nullptr;
      const double x = std::strtod(tok.c_str(), &end);
      if (end == tok.c_str() || *end != '\0' || !std::isfinite(x))
        throw tbsp::FileError(scalar_file + ": value " + std::to_string(v.size()) + " ('" + tok.substr(0, 20) + "') is not a finite number");
      v.push_back(x);
    }
    if (Eigen::Index(v.size()) != m.V.rows())
      throw tbsp::InvalidInput("--scalar " + scalar_file + ": " + std::to_string(v.size()) + " values for the " +
                               std::to_string(m.V.rows()) + (cloud ? " points" : " vertices") + " of " + path +
                               "; give one value per line, in vertex order");
    values = Eigen::Map<const Eigen::VectorXd>(v.data(), Eigen::Index(v.size()));
    label = fs::path(scalar_file).filename().string();
  }
  Eigen::MatrixX3d colors = m.C;
  if (values.size() > 0) {
    p.colorbar = true;
    p.colorbar_lo = range.size() == 2 ? range[0] : values.minCoeff();
    p.colorbar_hi = range.size() == 2 ? range[1] : values.maxCoeff();
    p.colorbar_label = label;
    colors = tbsp::colormap(values, p.colorbar_lo, p.colorbar_hi);
  }
  if (cloud) {
    p.points = m.V;
    if (colors.rows() == m.V.rows()) p.point_colors = colors;
  } else {
    m.C = colors.rows() == m.V.rows() ? colors : Eigen::MatrixX3d();
    p.mesh = std::move(m);
  }
  return p;
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

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"tbsp - template-based shape processing for PCL pipelines"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "tbsp 0.1.0");
  int verbose = 0;
  app.add_flag("-v,--verbose", verbose, "debug logging; -vv: trace (per-iteration timings of factorizations and solves; the extra diagnostics slow a fit down)");

  DeformArgs da;
  auto* deform = app.add_subcommand("deform", "Laplacian deformation of a mesh under constraints (thesis ch. 3)");
  deform->add_option("--mesh", da.mesh, "input mesh (.ply .obj .off .vtk)")->required()->check(CLI::ExistingFile);
  deform->add_option("--constraints", da.constraints, "constraints JSON (docs/constraints_json.md)")->required()->check(CLI::ExistingFile);
  deform->add_option("--out", da.out, "output mesh (.ply .obj .off .vtk), written atomically")->required();
  deform->add_flag("--rotation-field", da.rotation_field, "estimate and apply the rotation field of §3.2.3 (eq. 3.12)");
  deform->add_flag("--uniform", da.uniform, "uniform instead of cotangent Laplacian weights");
  deform->add_flag("--check-self-intersections", da.self_intersections,
                   "count pairs of faces that cross each other in the input and the output (report: self_intersections)");
  deform->add_option("--scale", da.scale, "global scale λ of the differential coordinates (§5.2)")->check(CLI::PositiveNumber);
  deform->add_option("--report", da.report, "JSON report: timings, counts, residuals");
  deform->add_flag("-q,--quiet", da.quiet, "no progress bar or summary");

  FitArgs fa;
  auto* fitc = app.add_subcommand("fit", "fit a template mesh to a point cloud (thesis ch. 5)");
  fitc->add_option("--template", fa.templ, "template mesh (.ply .obj .off .vtk)")->required()->check(CLI::ExistingFile);
  fitc->add_option("--cloud", fa.cloud, "scan (.pcd, or .ply/.obj/.off/.vtk vertices); normals used if present")->required()->check(CLI::ExistingFile);
  fitc->add_option("--markers", fa.markers, "markers JSON (docs/fit_json.md)")->required()->check(CLI::ExistingFile);
  fitc->add_option("--out", fa.out, "fitted mesh, written atomically")->required();
  fitc->add_option("--status", fa.status, "per-vertex status text file");
  fitc->add_option("--report", fa.report, "JSON report (iterations, timings, Hausdorff, RMS, coverage)");
  fitc->add_option("--roi", fa.roi, "region-of-interest JSON (exclusions)");
  fitc->add_option("--png", fa.png, "PNG: template, fit coloured by distance to the scan, status");
  fitc->add_option("--r-max", fa.p.max_match_distance, "final match radius r_max (0 = from the data)");
  fitc->add_option("--theta-max", fa.p.max_normal_angle_deg, "max normal deviation θ_max in degrees");
  fitc->add_option("--iterations", fa.p.max_iterations, "max iterations");
  fitc->add_option("--match-weight", fa.p.match_weight, "weight of data constraints");
  fitc->add_option("--detail-rounds", fa.p.detail_rounds,
                   "rounds of Laplacian updating after the fit, unsupported vertices held (sharper protrusions; 0 = off)");
  fitc->add_option("--detail-radius-factor", fa.p.detail_radius_factor,
                   "kernel radius of the detail rounds' residual matching, x r_max (default 2)");
  fitc->add_option("--detail-normal-angle", fa.p.detail_normal_angle_deg,
                   "detail rounds: max angle (degrees) between a point's normal and the face it projects onto (default 40)");
  fitc->add_option("--detail-surface-weight", fa.p.detail_surface_weight,
                   "weight of the detail rounds' per-face data constraints (default 0 = off)");
  fitc->add_flag("--detail-kernel-targets", fa.kernel_detail,
                 "detail rounds: the §5.3 kernel targets along the normals instead of residual matching");
  fitc->add_flag("--laplacian-updating", fa.p.laplacian_updating, "§5.5.1: rebuild the Laplacian each iteration");
  fitc->add_flag("--remesh", fa.p.remeshing, "§5.5.2: adaptive subdivision (changes connectivity)");
  fitc->add_flag("--fairing", fa.p.fairing, "§5.5.3: tangential fairing against fold-overs");
  fitc->add_flag("--no-pleat-collapse", fa.no_pleats,
                 "with --remesh --fairing: keep pleats (faces against the data normals) instead of collapsing them");
  fitc->add_flag("--check-self-intersections", fa.p.check_self_intersections,
                 "count the result's intersecting face pairs also without --fairing (with it they are counted and repaired)");
  fitc->add_flag("--refine-rotations", fa.p.refine_rotations, "re-estimate the rotation field from the fit");
  fitc->add_flag("--consistent-normals", fa.p.consistent_normals,
                 "make estimated normals consistent between neighbours after orienting them by the template");
  fitc->add_flag("--no-propagation", fa.no_prop, "skip the displacement propagation of §5.3");
  fitc->add_flag("--no-scale", fa.no_scale, "skip the global scale of §5.2");
  fitc->add_flag("--no-rotation-field", fa.no_field, "skip the rotation field of §3.2.3");
  fitc->add_flag("-q,--quiet", fa.quiet, "no progress bar or summary");

  ValidateArgs va;
  auto* validate = app.add_subcommand("validate", "report mesh problems (non-manifold, degenerate, NaN, ...)");
  validate->add_option("mesh", va.mesh, "mesh file")->required();
  validate->add_option("--json", va.json, "also write the report as JSON");
  validate->add_flag("--strict", va.strict,
                     "exit 4 unless the mesh is clean (and, with the checks below, nothing crosses or points into the "
                     "reference)");
  validate->add_flag("--self-intersections", va.self_intersections,
                     "also count pairs of faces that cross each other (exact predicates; needs a manifold, consistently "
                     "oriented mesh; with --strict any crossing exits 4)");
  validate->add_option("--against", va.against,
                       "reference surface mesh (e.g. the scan a fit was made from): count faces that point into it, probed "
                       "along each face normal (docs/fitting.md, fold-overs)");
  validate->add_option("--probe-distance", va.probe,
                       "half-length of each face's probe along its normal, model units (default 0.1 % of the reference's "
                       "bounding-box diagonal)")
      ->check(CLI::PositiveNumber);

  std::string c_in, c_out;
  bool c_ascii = false;
  auto* convert = app.add_subcommand("convert", "convert between mesh formats");
  convert->add_option("input", c_in, "input mesh")->required();
  convert->add_option("output", c_out, "output mesh")->required();
  convert->add_flag("--ascii", c_ascii, "ASCII PLY instead of binary");

  std::vector<std::string> r_meshes;
  std::string r_out, r_color_by, r_scalar;
  std::vector<double> r_range;
  double r_az = 30, r_el = 20;
  auto* render = app.add_subcommand("render", "preview PNG of meshes and point clouds side by side (a file without faces is drawn as points)");
  render->add_option("meshes", r_meshes, "mesh or point-cloud files (.ply .obj .off .vtk .pcd)")->required();
  render->add_option("--color-by", r_color_by, "colour every panel by a scalar per vertex / point: x, y or z (with a colour bar)")
      ->check(CLI::IsMember({"x", "y", "z"}));
  render->add_option("--scalar", r_scalar, "colour by the values of a text file, one number per vertex / point (with a colour bar)");
  render->add_option("--range", r_range, "colour bar range LO HI (default: the values' min and max)")->expected(2);
  bool r_own = false;
  render->add_flag("--own-frames", r_own, "frame each panel on its own content (default: one frame for all, to compare sizes)");
  render->add_option("--out", r_out, "PNG file")->required();
  render->add_option("--azimuth", r_az, "view azimuth (degrees)");
  render->add_option("--elevation", r_el, "view elevation (degrees)");

  std::string g_shape = "icosphere", g_out;
  int g_level = 3, g_rings = 60, g_segments = 24;
  auto* generate = app.add_subcommand("generate", "write a procedural mesh (icosphere, grid, tube, bumpy-bar)");
  generate->add_option("shape", g_shape, "icosphere | grid | tube | bumpy-bar | box (closed 1 x 0.2 x 0.2 bar)")->required();
  generate->add_option("--out", g_out, "output mesh")->required();
  generate->add_option("--level", g_level, "icosphere subdivision level / grid cells = 2^level");
  generate->add_option("--rings", g_rings, "tube rings");
  generate->add_option("--segments", g_segments, "tube segments");

  SynthArgs sa;
  auto* synth = app.add_subcommand("synth-scan", "synthetic scan with ground truth from a mesh (deform, sample, noise, outliers, hole, markers)");
  synth->add_option("--mesh", sa.mesh, "source mesh")->required()->check(CLI::ExistingFile);
  synth->add_option("--out-cloud", sa.cloud, "cloud with normals (.ply)")->required();
  synth->add_option("--out-markers", sa.markers, "markers JSON for tbsp fit")->required();
  synth->add_option("--out-truth", sa.truth, "the deformed mesh (ground truth)");
  synth->add_option("--bend", sa.o.bend_deg, "bend angle (degrees)");
  synth->add_option("--twist", sa.o.twist_deg, "twist angle (degrees)");
  synth->add_option("--scale", sa.o.scale, "uniform scale");
  synth->add_option("--points", sa.o.points, "number of points");
  synth->add_option("--noise", sa.o.noise, "Gaussian noise sigma / bbox diagonal");
  synth->add_option("--outliers", sa.o.outliers, "fraction of uniform outliers");
  synth->add_option("--hole", sa.o.hole, "fraction of the surface removed");
  synth->add_option("--markers", sa.o.markers, "number of markers");
  synth->add_option("--seed", sa.o.seed, "random seed");

  tbsp::cli::SynthStudioArgs ssa;
  CLI::App* synth_studio = nullptr;
  tbsp::cli::add_synth_studio(app, ssa, synth_studio);
  tbsp::cli::ReplayArgs ra;
  CLI::App* replay = nullptr;
  tbsp::cli::add_replay(app, ra, replay);
  tbsp::cli::TetDeformArgs tda;
  CLI::App* tetdeform = nullptr;
  tbsp::cli::add_tetdeform(app, tda, tetdeform);
  tbsp::cli::TextureArgs txa;
  CLI::App* texture = nullptr;
  tbsp::cli::add_texture(app, txa, texture);
  tbsp::cli::MocapArgs ma;
  CLI::App* mocap = nullptr;
  tbsp::cli::add_mocap(app, ma, mocap);

  std::string demo_in = TBSP_SAMPLE_DATA_DIR, demo_out = "tbsp_demo_out";
  bool demo_quiet = false;
  auto* demo = app.add_subcommand("demo", "run the demos on sample_data/: template fitting (ch. 5) and bending (ch. 3)");
  demo->add_option("--data", demo_in, "sample data folder");
  demo->add_option("--out", demo_out, "output folder");
  demo->add_flag("-q,--quiet", demo_quiet, "no progress bar");

  CLI11_PARSE(app, argc, argv);
  tbsp::logger()->set_level(verbose >= 2 ? spdlog::level::trace : verbose == 1 ? spdlog::level::debug : spdlog::level::warn);
  const std::string sub = app.get_subcommands().front()->get_name();
  try {
    if (*deform) return cmd_deform(da);
    if (*fitc) return cmd_fit(fa);
    if (*validate) return cmd_validate(va);
    if (*convert) {
      tbsp::MeshWriteOptions o;
      o.binary = !c_ascii;
      tbsp::write_mesh(c_out, tbsp::read_mesh(c_in), o);
      return 0;
    }
    if (*render) {
      std::vector<tbsp::RenderPanel> panels;
      for (const auto& m : r_meshes) panels.push_back(render_panel(m, r_color_by, r_scalar, r_range));
      tbsp::RenderOptions o;
      o.shared_frame = !r_own;
      o.azimuth_deg = r_az;
      o.elevation_deg = r_el;
      tbsp::render_panels_png(r_out, panels, o);
      return 0;
    }
    if (*generate) {
      tbsp::TriMesh m;
      if (g_shape == "icosphere") m = tbsp::make_icosphere(g_level);
      else if (g_shape == "grid") m = tbsp::make_grid(1 << g_level, 1 << g_level);
      else if (g_shape == "tube") m = tbsp::make_tube(g_rings, g_segments);
      else if (g_shape == "box") m = tbsp::make_box(5 << g_level, 1 << g_level, 1 << g_level, 1.0, 0.2, 0.2);
      else if (g_shape == "bumpy-bar") {
        // tube with a helical ridge pattern, so that shearing and twisting are visible
        m = tbsp::make_tube(g_rings, g_segments, 1.0, 0.1);
        for (Eigen::Index i = 0; i < g_rings * g_segments; ++i) {
          const double x = m.V(i, 0), a = std::atan2(m.V(i, 2), m.V(i, 1));
          const double r = 1.0 + 0.12 * std::sin(4 * a + 12 * M_PI * x);
          m.V(i, 1) *= r;
          m.V(i, 2) *= r;
        }
      } else {
        throw tbsp::InvalidInput("unknown shape '" + g_shape + "' (icosphere, grid, tube, bumpy-bar, box)");
      }
      tbsp::write_mesh(g_out, m);
      return 0;
    }
    if (*demo) return cmd_demo(demo_in, demo_out, demo_quiet);
    if (*synth) return cmd_synth_scan(sa);
    if (*synth_studio) return tbsp::cli::cmd_synth_studio(ssa);
    if (*replay) return tbsp::cli::cmd_replay(ra);
    if (*tetdeform) return tbsp::cli::cmd_tetdeform(tda);
    if (*texture) return tbsp::cli::cmd_texture(txa);
    if (*mocap) return tbsp::cli::cmd_mocap(ma);
  } catch (const tbsp::Cancelled& e) {
    std::cerr << "tbsp " << sub << ": cancelled: " << e.what() << "\n";
    return 130;
  } catch (const tbsp::InvalidInput& e) {
    std::cerr << "tbsp " << sub << ": error: " << e.what() << "\n";
    return 2;
  } catch (const tbsp::NumericalFailure& e) {
    std::cerr << "tbsp " << sub << ": numerical failure: " << e.what() << "\n";
    return 3;
  } catch (const std::exception& e) {
    std::cerr << "tbsp " << sub << ": error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
