#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <spdlog/fmt/fmt.h>
#include <nlohmann/json.hpp>

#include "command.h"
#include "progress_bar.h"
#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/cloud_io.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/plugins/preview_render.h"

namespace fs = std::filesystem;

namespace tbsp::cli {

namespace {

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
                        {"extent", r.extent},
                        {"scale_out_of_range", r.scale_out_of_range},
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

struct ConvertArgs {
  std::string in, out;
  bool ascii = false;
};
struct RenderArgs {
  std::vector<std::string> meshes;
  std::string out, color_by, scalar;
  std::vector<double> range;
  double az = 30, el = 20;
  bool own = false;
};
struct GenerateArgs {
  std::string shape = "icosphere", out;
  int level = 3, rings = 60, segments = 24;
};

int cmd_convert(const ConvertArgs& a) {
  tbsp::MeshWriteOptions o;
  o.binary = !a.ascii;
  tbsp::write_mesh(a.out, tbsp::read_mesh(a.in), o);
  return 0;
}

int cmd_render(const RenderArgs& a) {
  // (found by hand 2026-12-06: LO > HI painted every vertex the LO colour under an inverted bar)
  if (a.range.size() == 2 && !(a.range[0] < a.range[1]))
    throw tbsp::InvalidInput(fmt::format("--range {} {}: give LO < HI (the colour bar runs from LO to HI)", a.range[0], a.range[1]));
  std::vector<tbsp::RenderPanel> panels;
  for (const auto& m : a.meshes) panels.push_back(render_panel(m, a.color_by, a.scalar, a.range));
  tbsp::RenderOptions o;
  o.shared_frame = !a.own;
  o.azimuth_deg = a.az;
  o.elevation_deg = a.el;
  tbsp::render_panels_png(a.out, panels, o);
  return 0;
}

int cmd_generate(const GenerateArgs& a) {
  // sizes checked here: 1 << level and rings × segments would overflow or ask for more memory
  // than a mesh file is worth before the generators could refuse them
  if ((a.shape == "grid" && (a.level < 0 || a.level > 11)) || (a.shape == "box" && (a.level < 0 || a.level > 8)))
    throw tbsp::InvalidInput("--level " + std::to_string(a.level) + " is out of range for a " + a.shape + "; use 0.." +
                             (a.shape == "grid" ? "11 (2^level cells per side)" : "8 (5·2^level × 2^level × 2^level cells)"));
  if ((a.shape == "tube" || a.shape == "bumpy-bar") && (a.rings > 100000 || a.segments > 100000 ||
                                                        double(a.rings) * double(a.segments) > 2e7))
    throw tbsp::InvalidInput("--rings " + std::to_string(a.rings) + " × --segments " + std::to_string(a.segments) +
                             " is too large; use at most 100000 each and 20 million vertices in all");
  tbsp::TriMesh m;
  if (a.shape == "icosphere") m = tbsp::make_icosphere(a.level);
  else if (a.shape == "grid") m = tbsp::make_grid(1 << a.level, 1 << a.level);
  else if (a.shape == "tube") m = tbsp::make_tube(a.rings, a.segments);
  else if (a.shape == "box") m = tbsp::make_box(5 << a.level, 1 << a.level, 1 << a.level, 1.0, 0.2, 0.2);
  else if (a.shape == "bumpy-bar") {
    // tube with a helical ridge pattern, so that shearing and twisting are visible
    m = tbsp::make_tube(a.rings, a.segments, 1.0, 0.1);
    for (Eigen::Index i = 0; i < Eigen::Index(a.rings) * a.segments; ++i) {
      const double x = m.V(i, 0), t = std::atan2(m.V(i, 2), m.V(i, 1));
      const double r = 1.0 + 0.12 * std::sin(4 * t + 12 * M_PI * x);
      m.V(i, 1) *= r;
      m.V(i, 2) *= r;
    }
  } else {
    throw tbsp::InvalidInput("unknown shape '" + a.shape + "' (icosphere, grid, tube, bumpy-bar, box)");
  }
  tbsp::write_mesh(a.out, m);
  return 0;
}

}  // namespace

void add_mesh_commands(CLI::App& app, CommandTable& table) {
  auto v = std::make_shared<ValidateArgs>();
  auto* validate = app.add_subcommand("validate", "report mesh problems (non-manifold, degenerate, NaN, ...)");
  validate->add_option("mesh", v->mesh, "mesh file")->required();
  validate->add_option("--json", v->json, "also write the report as JSON");
  validate->add_flag("--strict", v->strict,
                     "exit 4 unless the mesh is clean (and, with the checks below, nothing crosses or points into the "
                     "reference)");
  validate->add_flag("--self-intersections", v->self_intersections,
                     "also count pairs of faces that cross each other (exact predicates; needs a manifold, consistently "
                     "oriented mesh; with --strict any crossing exits 4)");
  validate->add_option("--against", v->against,
                       "reference surface mesh (e.g. the scan a fit was made from): count faces that point into it, probed "
                       "along each face normal (docs/dev/fitting_experiments.md, fold-overs)");
  validate->add_option("--probe-distance", v->probe,
                       "half-length of each face's probe along its normal, model units (default 0.1 % of the reference's "
                       "bounding-box diagonal)")
      ->check(CLI::PositiveNumber);

  table.push_back({validate, [v] { return cmd_validate(*v); }});

  auto c = std::make_shared<ConvertArgs>();
  auto* convert = app.add_subcommand("convert", "convert between mesh formats");
  convert->add_option("input", c->in, "input mesh")->required();
  convert->add_option("output", c->out, "output mesh")->required();
  convert->add_flag("--ascii", c->ascii, "ASCII PLY instead of binary");

  table.push_back({convert, [c] { return cmd_convert(*c); }});

  auto r = std::make_shared<RenderArgs>();
  auto* render = app.add_subcommand("render", "preview PNG of meshes and point clouds side by side (a file without faces is drawn as points)");
  render->add_option("meshes", r->meshes, "mesh or point-cloud files (.ply .obj .off .vtk .pcd)")->required();
  render->add_option("--color-by", r->color_by, "colour every panel by a scalar per vertex / point: x, y or z (with a colour bar)")
      ->check(CLI::IsMember({"x", "y", "z"}));
  render->add_option("--scalar", r->scalar, "colour by the values of a text file, one number per vertex / point (with a colour bar)");
  render->add_option("--range", r->range, "colour bar range LO HI (default: the values' min and max)")->expected(2);
  render->add_flag("--own-frames", r->own, "frame each panel on its own content (default: one frame for all, to compare sizes)");
  render->add_option("--out", r->out, "PNG file")->required();
  render->add_option("--azimuth", r->az, "view azimuth (degrees)");
  render->add_option("--elevation", r->el, "view elevation (degrees)");

  table.push_back({render, [r] { return cmd_render(*r); }});

  auto g = std::make_shared<GenerateArgs>();
  auto* generate = app.add_subcommand("generate", "write a procedural mesh (icosphere, grid, tube, bumpy-bar)");
  generate->add_option("shape", g->shape, "icosphere | grid | tube | bumpy-bar | box (closed 1 x 0.2 x 0.2 bar)")->required();
  generate->add_option("--out", g->out, "output mesh")->required();
  generate->add_option("--level", g->level, "icosphere subdivision level / grid cells = 2^level");
  generate->add_option("--rings", g->rings, "tube rings");
  generate->add_option("--segments", g->segments, "tube segments");

  table.push_back({generate, [g] { return cmd_generate(*g); }});
}

}  // namespace tbsp::cli
