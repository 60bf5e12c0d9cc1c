#include "tbsp/mesh/tetrahedralize.h"
#include "tbsp/mesh/topology.h"

// CGAL's Garland-Heckbert quadrics (Eigen 4x4 temporaries) trip -Wmaybe-uninitialized inside
// Eigen when instantiated here; the warning is in the library code, not ours.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif

#include <CGAL/Simple_cartesian.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Bounded_normal_change_placement.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Count_ratio_stop_predicate.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Count_stop_predicate.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/GarlandHeckbert_plane_policies.h>
#include <CGAL/Surface_mesh_simplification/edge_collapse.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <sys/wait.h>
#include <unistd.h>

#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/mesh/mesh_validation.h"

namespace fs = std::filesystem;

namespace tbsp {

namespace {
using K = CGAL::Simple_cartesian<double>;
using SM = CGAL::Surface_mesh<K::Point_3>;
namespace SMS = CGAL::Surface_mesh_simplification;

SM to_surface_mesh(const TriMesh& m) {
  SM sm;
  std::vector<SM::Vertex_index> vi(std::size_t(m.V.rows()));
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) vi[std::size_t(i)] = sm.add_vertex(K::Point_3(m.V(i, 0), m.V(i, 1), m.V(i, 2)));
  for (Eigen::Index f = 0; f < m.F.rows(); ++f) {
    const auto fi = sm.add_face(vi[std::size_t(m.F(f, 0))], vi[std::size_t(m.F(f, 1))], vi[std::size_t(m.F(f, 2))]);
    if (fi == SM::null_face())
      throw InvalidInput("[tbsp::decimate_mesh] face " + std::to_string(f) +
                         " cannot be added to a halfedge structure (non-manifold or inconsistently oriented there); "
                         "repair the mesh first");
  }
  return sm;
}

TriMesh from_surface_mesh(SM& sm) {
  sm.collect_garbage();
  TriMesh m;
  m.V.resize(Eigen::Index(sm.number_of_vertices()), 3);
  for (auto v : sm.vertices()) {
    const auto& p = sm.point(v);
    m.V.row(Eigen::Index(v.idx())) << p.x(), p.y(), p.z();
  }
  m.F.resize(Eigen::Index(sm.number_of_faces()), 3);
  Eigen::Index r = 0;
  for (auto f : sm.faces()) {
    int k = 0;
    for (auto v : CGAL::vertices_around_face(sm.halfedge(f), sm)) m.F(r, k++) = int(v.idx());
    ++r;
  }
  return m;
}

std::string last_lines(const std::string& text, int n) {
  std::vector<std::string> lines;
  std::istringstream is(text);
  std::string l;
  while (std::getline(is, l))
    if (!l.empty()) lines.push_back(l);
  std::string out;
  for (std::size_t i = lines.size() > std::size_t(n) ? lines.size() - std::size_t(n) : 0; i < lines.size(); ++i)
    out += (out.empty() ? "" : " | ") + lines[i];
  return out;
}

std::string read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}

struct TempDir {
  fs::path path;
  TempDir() {
    static std::atomic<int> counter{0};
    const auto stamp = std::chrono::steady_clock::now().time_since_epoch().count();
    path = fs::temp_directory_path() /
           ("tbsp_tetgen_" + std::to_string(::getpid()) + "_" + std::to_string(counter++) + "_" + std::to_string(stamp));
    fs::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

// Reads TetGen's .node/.ele (zero-based with -z).
TetMesh read_tetgen_output(const fs::path& node, const fs::path& ele) {
  TetMesh out;
  std::ifstream n(node), e(ele);
  if (!n || !e) throw Error("[tbsp::tetrahedralize] TetGen produced no " + node.filename().string() + " / " + ele.filename().string());
  long long nv = 0, dim = 0, na = 0, nb = 0;
  n >> nv >> dim >> na >> nb;
  if (!n || nv <= 0 || dim != 3) throw Error("[tbsp::tetrahedralize] cannot parse TetGen's node file " + node.string());
  out.V.resize(nv, 3);
  for (long long i = 0; i < nv; ++i) {
    long long id;
    n >> id >> out.V(i, 0) >> out.V(i, 1) >> out.V(i, 2);
    double skip;
    for (long long k = 0; k < na + nb; ++k) n >> skip;
    if (!n || id != i) throw Error("[tbsp::tetrahedralize] TetGen's node file is truncated at node " + std::to_string(i));
  }
  long long nt = 0, npt = 0, nr = 0;
  e >> nt >> npt >> nr;
  if (!e || nt <= 0 || npt < 4) throw Error("[tbsp::tetrahedralize] cannot parse TetGen's element file " + ele.string());
  out.T.resize(nt, 4);
  for (long long i = 0; i < nt; ++i) {
    long long id;
    e >> id;
    for (long long k = 0; k < npt; ++k) {
      long long v;
      e >> v;
      if (k < 4) out.T(i, int(k)) = int(v);
    }
    double skip;
    for (long long k = 0; k < nr; ++k) e >> skip;
    if (!e || id != i) throw Error("[tbsp::tetrahedralize] TetGen's element file is truncated at element " + std::to_string(i));
  }
  return out;
}

}  // namespace

namespace {
// Stops the edge collapses at a target edge count, reporting progress on the way; a progress
// callback returning false stops them at once (the caller then throws Cancelled).
struct ProgressStop {
  std::size_t target_edges;
  const ProgressCallback* progress;
  mutable bool cancelled = false;
  mutable double next_report = 0.0;
  template <class FT, class Profile>
  bool operator()(const FT&, const Profile&, std::size_t initial, std::size_t current) const {
    if (current <= target_edges) return true;
    if (progress && *progress && initial > target_edges) {
      const double f = double(initial - current) / double(initial - target_edges);
      if (f >= next_report) {
        next_report = f + 0.01;
        if (!(*progress)(f, "decimate")) cancelled = true;
      }
    }
    return cancelled;
  }
};
}  // namespace

TriMesh decimate_mesh(const TriMesh& mesh, Eigen::Index target_faces, const ProgressCallback& progress) {
  if (target_faces < 4)
    throw InvalidInput("[tbsp::decimate_mesh] the target face count must be at least 4, got " + std::to_string(target_faces));
  MeshRequirements req;
  req.allow_nonmanifold = false;
  req.allow_degenerate = true;
  req.allow_inconsistent_orientation = false;
  require_valid_mesh(mesh, req, "tbsp::decimate_mesh");
  if (mesh.F.rows() <= target_faces) return mesh;
  SM sm = to_surface_mesh(mesh);
  // An edge collapse removes two faces on a closed surface; stop on the edge count
  // (#E = 3/2 #F on a closed mesh).
  const ProgressStop stop{std::size_t(target_faces) * 3 / 2, &progress};
  using GH = SMS::GarlandHeckbert_plane_policies<SM, K>;
  GH gh(sm);
  SMS::Bounded_normal_change_placement<GH::Get_placement> placement(gh.get_placement());
  SMS::edge_collapse(sm, stop, CGAL::parameters::get_cost(gh.get_cost()).get_placement(placement));
  if (stop.cancelled) throw Cancelled("[tbsp::decimate_mesh] cancelled by the progress callback");
  report_progress(progress, 1.0, "decimate");
  TriMesh out = from_surface_mesh(sm);
  logger()->debug("decimate_mesh: {} -> {} faces", mesh.F.rows(), out.F.rows());
  return out;
}

TetMesh tetrahedralize(const TriMesh& surface, const TetgenOptions& options) {
  MeshRequirements req;
  req.allow_boundary = false;
  req.allow_nonmanifold = false;
  req.allow_degenerate = false;
  req.allow_isolated_vertices = true;
  req.allow_inconsistent_orientation = false;
  const MeshReport rep = require_valid_mesh(surface, req, "tetrahedralize");
  if (!rep.isolated_vertices.empty())
    throw InvalidInput("[tbsp::tetrahedralize] " + std::to_string(rep.isolated_vertices.size()) +
                       " isolated vertices (e.g. vertex " + std::to_string(rep.isolated_vertices[0]) +
                       ") would become interior points; remove unreferenced vertices first");

  TempDir dir;
  const fs::path in = dir.path / "surface.smesh";
  {
    std::ofstream os(in);
    os << std::setprecision(17);
    os << surface.V.rows() << " 3 0 0\n";
    for (Eigen::Index i = 0; i < surface.V.rows(); ++i)
      os << i << ' ' << surface.V(i, 0) << ' ' << surface.V(i, 1) << ' ' << surface.V(i, 2) << '\n';
    os << surface.F.rows() << " 0\n";
    for (Eigen::Index f = 0; f < surface.F.rows(); ++f)
      os << "3 " << surface.F(f, 0) << ' ' << surface.F(f, 1) << ' ' << surface.F(f, 2) << '\n';
    os << "0\n0\n";
    if (!os) throw Error("[tbsp::tetrahedralize] cannot write the temporary file " + in.string());
  }
  // Self-intersection check first (TetGen -d): the meshing run itself may abort or silently
  // produce a tetrahedralization of the overlapping volume on such input.
  {
    const std::string dcmd = "cd '" + dir.path.string() + "' && '" + options.tetgen_program +
                             "' -dz surface.smesh > check.log 2>&1";
    report_progress(options.progress, 0.0, "tetgen");
    const int drc = std::system(dcmd.c_str());
    const std::string dtext = read_all(dir.path / "check.log");
    if (drc != 0 && (dtext.find("not found") != std::string::npos || (WIFEXITED(drc) && WEXITSTATUS(drc) == 127)))
      throw Error("[tbsp::tetrahedralize] cannot run '" + options.tetgen_program +
                  "': install the Debian package `tetgen` (scripts/deps does) or set TetgenOptions::tetgen_program");
    const auto found = dtext.find("!! Found");
    if (found != std::string::npos) {
      const std::string summary = dtext.substr(found + 3, dtext.find('\n', found) - found - 3);
      const auto first = dtext.find("Facet #");
      std::string example;
      if (first != std::string::npos) {
        const auto e1 = dtext.find('\n', first);
        const auto e2 = dtext.find('\n', e1 + 1);
        example = dtext.substr(first, e2 - first);
        for (auto& c : example)
          if (c == '\n') c = ' ';
        example = "; e.g. " + example;
      }
      throw InvalidInput("[tbsp::tetrahedralize] the surface self-intersects (TetGen -d: " + summary + example +
                         ", zero-based vertex indices). Repair the surface, or use surface_to_tets() for deformation transfer");
    }
  }
  std::ostringstream sw;
  sw << "-pz";
  if (options.preserve_surface) sw << 'Y';
  if (options.max_radius_edge_ratio > 0) {
    sw << 'q' << options.max_radius_edge_ratio;
    if (options.min_dihedral_deg > 0) sw << '/' << options.min_dihedral_deg;
  }
  if (options.max_volume > 0) sw << 'a' << std::setprecision(10) << options.max_volume;
  const fs::path log = dir.path / "tetgen.log";
  const std::string cmd = "cd '" + dir.path.string() + "' && '" + options.tetgen_program + "' " + sw.str() +
                          " surface.smesh > tetgen.log 2>&1";
  report_progress(options.progress, 0.3, "tetgen");
  const int rc = std::system(cmd.c_str());
  const std::string text = read_all(log);
  if (rc != 0) {
    if (text.find("not found") != std::string::npos || (WIFEXITED(rc) && WEXITSTATUS(rc) == 127))
      throw Error("[tbsp::tetrahedralize] cannot run '" + options.tetgen_program +
                  "': install the Debian package `tetgen` (scripts/deps does) or set TetgenOptions::tetgen_program");
    std::string reason = last_lines(text, 4);
    if (text.find("intersect") != std::string::npos) reason = "the surface self-intersects; TetGen says: " + reason;
    throw Error("[tbsp::tetrahedralize] TetGen " + sw.str() + " failed on a surface of " + std::to_string(surface.V.rows()) +
                " vertices / " + std::to_string(surface.F.rows()) + " faces: " + reason +
                ". Repair the surface (remove self-intersections) or use surface_to_tets()");
  }
  TetMesh out = read_tetgen_output(dir.path / "surface.1.node", dir.path / "surface.1.ele");
  orient_tets(out);
  if (options.preserve_surface && out.V.rows() >= surface.V.rows() &&
      !(out.V.topRows(surface.V.rows()) - surface.V).isZero(1e-9 * std::max(1.0, bbox_diagonal(surface.V))))
    logger()->warn("tetrahedralize: TetGen reordered the input vertices");
  logger()->debug("tetrahedralize: {} surface vertices -> {} vertices, {} tets ({})", surface.V.rows(), out.V.rows(),
                  out.T.rows(), sw.str());
  report_progress(options.progress, 1.0, "tetgen");
  return out;
}

TetMesh tetrahedralize_to_size(const TriMesh& surface, Eigen::Index target_tets, const TetgenOptions& options,
                               TriMesh* decimated_surface) {
  if (target_tets <= 0 || surface.F.rows() * 2 <= target_tets) {
    if (decimated_surface) *decimated_surface = surface;
    return tetrahedralize(surface, options);
  }
  double ratio = 2.2;
  Eigen::Index faces = std::max<Eigen::Index>(8, Eigen::Index(double(target_tets) / ratio));
  TriMesh dec = decimate_mesh(surface, faces, options.progress);
  TetMesh tets = tetrahedralize(dec, options);
  const double miss = double(tets.T.rows()) / double(target_tets);
  if (miss < 0.7 || miss > 1.3) {
    ratio = double(tets.T.rows()) / double(dec.F.rows());
    faces = std::max<Eigen::Index>(8, Eigen::Index(double(target_tets) / ratio));
    dec = decimate_mesh(surface, faces, options.progress);
    tets = tetrahedralize(dec, options);
  }
  if (decimated_surface) *decimated_surface = dec;
  return tets;
}

TetMesh tetrahedralize_components(const TriMesh& surface, Eigen::Index target_tets, const TetgenOptions& options,
                                  TriMesh* decimated_surface) {
  Eigen::VectorXi label;
  const int nc = connected_components(surface.F, surface.V.rows(), label);
  std::vector<int> order;  // components by first face
  std::vector<char> seen(std::size_t(std::max(nc, 0)), 0);
  for (Eigen::Index f = 0; f < surface.F.rows(); ++f) {
    const int c = label(surface.F(f, 0));
    if (!seen[std::size_t(c)]) {
      seen[std::size_t(c)] = 1;
      order.push_back(c);
    }
  }
  TetMesh out;
  TriMesh dec_all;
  std::vector<Eigen::RowVector3d> V;
  std::vector<Eigen::Matrix<int, 1, 4>> T;
  std::vector<Eigen::RowVector3d> DV;
  std::vector<Eigen::RowVector3i> DF;
  for (int c : order) {
    std::vector<int> map(std::size_t(surface.V.rows()), -1);
    TriMesh part;
    std::vector<Eigen::RowVector3d> pv;
    std::vector<Eigen::RowVector3i> pf;
    for (Eigen::Index f = 0; f < surface.F.rows(); ++f) {
      if (label(surface.F(f, 0)) != c) continue;
      Eigen::RowVector3i tri;
      for (int k = 0; k < 3; ++k) {
        const int v = surface.F(f, k);
        if (map[std::size_t(v)] < 0) {
          map[std::size_t(v)] = int(pv.size());
          pv.push_back(surface.V.row(v));
        }
        tri(k) = map[std::size_t(v)];
      }
      pf.push_back(tri);
    }
    part.V.resize(Eigen::Index(pv.size()), 3);
    for (std::size_t i = 0; i < pv.size(); ++i) part.V.row(Eigen::Index(i)) = pv[i];
    part.F.resize(Eigen::Index(pf.size()), 3);
    for (std::size_t i = 0; i < pf.size(); ++i) part.F.row(Eigen::Index(i)) = pf[i];
    const Eigen::Index share = target_tets > 0 ? std::max<Eigen::Index>(20, target_tets * part.F.rows() / surface.F.rows()) : 0;
    TriMesh dec;
    const TetMesh t = tetrahedralize_to_size(part, share, options, &dec);
    const int off = int(V.size()), doff = int(DV.size());
    for (Eigen::Index i = 0; i < t.V.rows(); ++i) V.push_back(t.V.row(i));
    for (Eigen::Index i = 0; i < t.T.rows(); ++i) T.push_back(t.T.row(i).array() + off);
    for (Eigen::Index i = 0; i < dec.V.rows(); ++i) DV.push_back(dec.V.row(i));
    for (Eigen::Index i = 0; i < dec.F.rows(); ++i) DF.push_back(dec.F.row(i).array() + doff);
  }
  out.V.resize(Eigen::Index(V.size()), 3);
  for (std::size_t i = 0; i < V.size(); ++i) out.V.row(Eigen::Index(i)) = V[i];
  out.T.resize(Eigen::Index(T.size()), 4);
  for (std::size_t i = 0; i < T.size(); ++i) out.T.row(Eigen::Index(i)) = T[i];
  // zero-volume slivers TetGen can leave on a small decimated part (its boundary kept with -Y)
  const Eigen::VectorXd vol = tet_signed_volumes(out.V, out.T).cwiseAbs();
  const double tol = 1e-9 * vol.mean();
  Eigen::Index kept = 0;
  for (Eigen::Index t = 0; t < out.T.rows(); ++t)
    if (vol(t) > tol) out.T.row(kept++) = out.T.row(t);
  out.T.conservativeResize(kept, 4);
  if (decimated_surface) {
    decimated_surface->V.resize(Eigen::Index(DV.size()), 3);
    for (std::size_t i = 0; i < DV.size(); ++i) decimated_surface->V.row(Eigen::Index(i)) = DV[i];
    decimated_surface->F.resize(Eigen::Index(DF.size()), 3);
    for (std::size_t i = 0; i < DF.size(); ++i) decimated_surface->F.row(Eigen::Index(i)) = DF[i];
  }
  return out;
}

}  // namespace tbsp
