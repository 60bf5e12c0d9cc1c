#include "tbsp/mesh/point_mesh_distance.h"

#include <embree3/rtcore.h>

#include "embree_device.h"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "tbsp/core/error.h"

namespace tbsp {

RTCDevice detail::embree_device() {
  static RTCDevice device = [] {
    RTCDevice d = rtcNewDevice(nullptr);
    if (!d)
      throw NumericalFailure("[tbsp] Embree could not create a device (error " + std::to_string(int(rtcGetDeviceError(nullptr))) + ")");
    return d;
  }();
  return device;
}

namespace {
using K = CGAL::Simple_cartesian<double>;
using Triangle = K::Triangle_3;
using Iterator = std::vector<Triangle>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<K, Iterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;
}  // namespace

struct MeshDistance::Impl {
  std::vector<Triangle> tris;
  Tree tree;
};

MeshDistance::MeshDistance(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) : impl_(std::make_unique<Impl>()) {
  if (F.rows() == 0) throw InvalidInput("[tbsp::MeshDistance] the mesh has no faces");
  impl_->tris.reserve(std::size_t(F.rows()));
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    auto p = [&](int k) { return K::Point_3(V(F(f, k), 0), V(F(f, k), 1), V(F(f, k), 2)); };
    impl_->tris.emplace_back(p(0), p(1), p(2));
  }
  impl_->tree.insert(impl_->tris.cbegin(), impl_->tris.cend());
  impl_->tree.build();
  impl_->tree.accelerate_distance_queries();
  // force the lazy internal structures to be built now, so concurrent queries only read
  (void)impl_->tree.closest_point(K::Point_3(V(0, 0), V(0, 1), V(0, 2)));
}

MeshDistance::~MeshDistance() = default;

Eigen::Vector3d closest_point_barycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                          const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return Eigen::Vector3d(1, 0, 0);
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return Eigen::Vector3d(0, 1, 0);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0 && d1 - d3 > 0) {
    const double v = d1 / (d1 - d3);
    return Eigen::Vector3d(1 - v, v, 0);
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return Eigen::Vector3d(0, 0, 1);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0 && d2 - d6 > 0) {
    const double w = d2 / (d2 - d6);
    return Eigen::Vector3d(1 - w, 0, w);
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0 && (d4 - d3) + (d5 - d6) > 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return Eigen::Vector3d(0, 1 - w, w);
  }
  const double denom = va + vb + vc;
  if (denom > 0) {
    const double v = vb / denom, w = vc / denom;
    return Eigen::Vector3d(1 - v - w, v, w);
  }
  // degenerate triangle: the closest point of its longest edge
  const Eigen::Vector3d e[3][2] = {{a, b}, {b, c}, {a, c}};
  int longest = 0;
  for (int k = 1; k < 3; ++k)
    if ((e[k][1] - e[k][0]).squaredNorm() > (e[longest][1] - e[longest][0]).squaredNorm()) longest = k;
  const Eigen::Vector3d s0 = e[longest][0], s1 = e[longest][1];
  const double len2 = (s1 - s0).squaredNorm();
  const double t = len2 > 0 ? std::clamp((p - s0).dot(s1 - s0) / len2, 0.0, 1.0) : 0.0;
  if (longest == 0) return Eigen::Vector3d(1 - t, t, 0);
  if (longest == 1) return Eigen::Vector3d(0, 1 - t, t);
  return Eigen::Vector3d(1 - t, 0, t);
}

Eigen::Vector3d MeshDistance::closest(const Eigen::Vector3d& q, int* face) const {
  const auto r = impl_->tree.closest_point_and_primitive(K::Point_3(q.x(), q.y(), q.z()));
  if (face) *face = int(r.second - impl_->tris.cbegin());
  return Eigen::Vector3d(r.first.x(), r.first.y(), r.first.z());
}

Eigen::VectorXd MeshDistance::distances(const Eigen::MatrixX3d& P, Eigen::VectorXi* faces) const {
  Eigen::VectorXd d(P.rows());
  if (faces) faces->resize(P.rows());
#pragma omp parallel for schedule(dynamic, 256)
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    int f = -1;
    const Eigen::Vector3d c = closest(P.row(i).transpose(), &f);
    d(i) = (c - P.row(i).transpose()).norm();
    if (faces) (*faces)(i) = f;
  }
  return d;
}

// ---- point_mesh_distances: Embree's BVH (single-precision boxes) + closest_point_barycentric

namespace {

float round_down(double x) {
  const float f = float(x);
  return double(f) <= x ? f : std::nextafter(f, -std::numeric_limits<float>::infinity());
}
float round_up(double x) {
  const float f = float(x);
  return double(f) >= x ? f : std::nextafter(f, std::numeric_limits<float>::infinity());
}

struct Triangles {
  const Eigen::MatrixX3d& V;
  const Eigen::MatrixX3i& F;
  const std::vector<int>* rows = nullptr;  // the tree's faces as rows of F (nullptr: all, in order)
  int row(unsigned prim) const { return rows ? (*rows)[prim] : int(prim); }
};

struct Query {
  const Triangles* mesh;
  Eigen::Vector3d q;
  double margin;  // added to the float query radius: Embree culls in single precision
  double d = std::numeric_limits<double>::infinity();
  int face = -1;  // of the closest point; the lowest index among equally close faces
};

void face_bounds(const RTCBoundsFunctionArguments* args) {
  const auto* m = static_cast<const Triangles*>(args->geometryUserPtr);
  const Eigen::Index f = m->row(args->primID);
  Eigen::Vector3d lo = m->V.row(m->F(f, 0)).transpose(), hi = lo;
  for (int k = 1; k < 3; ++k) {
    lo = lo.cwiseMin(m->V.row(m->F(f, k)).transpose());
    hi = hi.cwiseMax(m->V.row(m->F(f, k)).transpose());
  }
  // rounded outwards: the float box contains the double triangle
  RTCBounds* b = args->bounds_o;
  b->lower_x = round_down(lo.x());
  b->lower_y = round_down(lo.y());
  b->lower_z = round_down(lo.z());
  b->upper_x = round_up(hi.x());
  b->upper_y = round_up(hi.y());
  b->upper_z = round_up(hi.z());
}

bool face_query(RTCPointQueryFunctionArguments* args) {
  auto* r = static_cast<Query*>(args->userPtr);
  const Triangles& m = *r->mesh;
  const Eigen::Index f = m.row(args->primID);
  const Eigen::Vector3d a = m.V.row(m.F(f, 0)).transpose(), b = m.V.row(m.F(f, 1)).transpose(),
                        c = m.V.row(m.F(f, 2)).transpose();
  const Eigen::Vector3d w = closest_point_barycentric(r->q, a, b, c);
  const double d = (w(0) * a + w(1) * b + w(2) * c - r->q).norm();
  if (!(d < r->d || (d == r->d && int(f) < r->face))) return false;
  r->d = d;
  r->face = int(f);
  args->query->radius = round_up(d + r->margin);  // shrink the search sphere
  return true;
}


// Embree's tree over the faces of `mesh`; released with rtcReleaseScene.
RTCScene embree_face_tree(const Triangles& mesh, Eigen::Index count, const std::string& who) {
  RTCDevice device = detail::embree_device();
  RTCScene scene = rtcNewScene(device);
  RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
  rtcSetGeometryUserPrimitiveCount(g, unsigned(count));
  rtcSetGeometryUserData(g, const_cast<Triangles*>(&mesh));
  rtcSetGeometryBoundsFunction(g, face_bounds, nullptr);
  rtcCommitGeometry(g);
  rtcAttachGeometry(scene, g);
  rtcReleaseGeometry(g);
  rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
  rtcCommitScene(scene);
  const RTCError e = rtcGetDeviceError(device);
  if (e != RTC_ERROR_NONE) {
    rtcReleaseScene(scene);
    throw NumericalFailure(who + "Embree could not build the tree of " + std::to_string(count) + " faces (error " +
                           std::to_string(int(e)) + (e == RTC_ERROR_OUT_OF_MEMORY ? ": out of memory)" : ")"));
  }
  return scene;
}

// The closest of the tree's faces to q that is closer than r's current (d, face) — or as close
// with a lower index; r keeps its (d, face) when there is none.
void closer_face(RTCScene scene, Query& r) {
  RTCPointQuery pq;
  pq.x = float(r.q.x());
  pq.y = float(r.q.y());
  pq.z = float(r.q.z());
  pq.time = 0.f;
  pq.radius = std::isfinite(r.d) ? round_up(r.d + r.margin) : std::numeric_limits<float>::infinity();
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  rtcPointQuery(scene, &pq, &context, face_query, &r);
}

void check_distance_mesh(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const std::string& who) {
  if (F.rows() == 0) throw InvalidInput(who + "the mesh has no faces");
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int v = F(f, k);
      if (v < 0 || v >= V.rows())
        throw InvalidInput(who + "face " + std::to_string(f) + " refers to vertex " + std::to_string(v) + " but the mesh has " +
                           std::to_string(V.rows()) + " vertices");
      if (!V.row(v).allFinite())
        throw InvalidInput(who + "vertex " + std::to_string(v) + " (of face " + std::to_string(f) + ") is not finite");
    }
}

// a float step of the coordinates is ~6e-8 of their size: 1e-6 of it keeps the culling
// conservative (no face that could be closest is skipped)
double culling_margin(double scale, const Eigen::Vector3d& q) { return 1e-6 * std::max(scale, q.cwiseAbs().maxCoeff()); }

}  // namespace

Eigen::VectorXd point_mesh_distances(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Eigen::MatrixX3d& P,
                                     Eigen::VectorXi* faces) {
  const std::string who = "[tbsp::point_mesh_distances] ";
  check_distance_mesh(V, F, who);
  const Triangles mesh{V, F};
  const double scale = V.cwiseAbs().maxCoeff();
  RTCScene scene = embree_face_tree(mesh, F.rows(), who);
  Eigen::VectorXd d(P.rows());
  if (faces) faces->setConstant(P.rows(), -1);
#pragma omp parallel for schedule(dynamic, 256)
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    const Eigen::Vector3d q = P.row(i).transpose();
    if (!q.allFinite()) {
      d(i) = std::numeric_limits<double>::quiet_NaN();
      continue;
    }
    Query r{&mesh, q, culling_margin(scale, q)};
    closer_face(scene, r);
    d(i) = r.d;
    if (faces) (*faces)(i) = r.face;
  }
  rtcReleaseScene(scene);
  return d;
}

void update_point_mesh_distances(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Eigen::MatrixX3d& P,
                                 const std::vector<char>& moved, Eigen::VectorXd& dist, Eigen::VectorXi& faces) {
  const std::string who = "[tbsp::update_point_mesh_distances] ";
  check_distance_mesh(V, F, who);
  if (moved.size() != std::size_t(V.rows()))
    throw InvalidInput(who + "`moved` has " + std::to_string(moved.size()) + " entries for " + std::to_string(V.rows()) +
                       " vertices");
  if (dist.rows() != P.rows() || faces.rows() != P.rows())
    throw InvalidInput(who + "the distances (" + std::to_string(dist.rows()) + ") and faces (" + std::to_string(faces.rows()) +
                       ") to update must have one entry per point (" + std::to_string(P.rows()) + ")");
  // the faces with a moved corner, in increasing order (ties keep going to the lowest index)
  std::vector<int> rows;
  std::vector<char> face_moved(std::size_t(F.rows()), 0);
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    if (moved[std::size_t(F(f, 0))] || moved[std::size_t(F(f, 1))] || moved[std::size_t(F(f, 2))]) {
      rows.push_back(int(f));
      face_moved[std::size_t(f)] = 1;
    }
  if (rows.empty()) return;
  for (Eigen::Index i = 0; i < P.rows(); ++i)
    if (P.row(i).allFinite() && !(faces(i) >= 0 && faces(i) < F.rows()))
      throw InvalidInput(who + "point " + std::to_string(i) + " has no closest face (" + std::to_string(faces(i)) +
                         ") to update from: start from point_mesh_distances of the same points");
  const Triangles part{V, F, &rows};
  const double scale = V.cwiseAbs().maxCoeff();
  RTCScene scene = embree_face_tree(part, Eigen::Index(rows.size()), who);
  // a point whose closest face kept its corners is at most as far from every other face that did
  // (d_old): only a moved face can now be closer. Where its closest face moved, the faces that did
  // not are at least d_old away: a moved face closer than that is the answer; otherwise the
  // closest moved face (at dm) stands unless a face that did not move is closer, and such a face
  // lies within dm of the point.
  std::vector<char> again(std::size_t(P.rows()), 0);
  Eigen::VectorXd dm(P.rows());
  Eigen::VectorXi fm(P.rows());
#pragma omp parallel for schedule(dynamic, 1024)
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    const Eigen::Vector3d q = P.row(i).transpose();
    if (!q.allFinite()) continue;
    Query r{&part, q, culling_margin(scale, q)};
    const bool kept = !face_moved[std::size_t(faces(i))];
    if (kept) {
      r.d = dist(i);
      r.face = faces(i);
    }
    closer_face(scene, r);
    if (!kept && !(r.d < dist(i))) again[std::size_t(i)] = 1;
    dist(i) = dm(i) = r.d;
    faces(i) = fm(i) = r.face;
  }
  rtcReleaseScene(scene);
  // those points against the faces that did not move and come within the box around their
  // balls of radius dm (padded by 1e-9 of the coordinates against rounding): a tree over them
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  std::vector<Eigen::Index> idx;
  for (Eigen::Index i = 0; i < P.rows(); ++i)
    if (again[std::size_t(i)]) {
      idx.push_back(i);
      const double pad = dm(i) + 1e-9 * std::max(scale, P.row(i).cwiseAbs().maxCoeff());
      lo = lo.cwiseMin(P.row(i).transpose() - Eigen::Vector3d::Constant(pad));
      hi = hi.cwiseMax(P.row(i).transpose() + Eigen::Vector3d::Constant(pad));
    }
  if (idx.empty()) return;
  std::vector<int> near;
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    if (face_moved[std::size_t(f)]) continue;
    Eigen::Vector3d flo = V.row(F(f, 0)).transpose(), fhi = flo;
    for (int k = 1; k < 3; ++k) {
      flo = flo.cwiseMin(V.row(F(f, k)).transpose());
      fhi = fhi.cwiseMax(V.row(F(f, k)).transpose());
    }
    if ((flo.array() <= hi.array()).all() && (fhi.array() >= lo.array()).all()) near.push_back(int(f));
  }
  if (near.empty()) return;
  const Triangles rest{V, F, &near};
  RTCScene rest_scene = embree_face_tree(rest, Eigen::Index(near.size()), who);
#pragma omp parallel for schedule(dynamic, 64)
  for (std::size_t k = 0; k < idx.size(); ++k) {
    const Eigen::Index i = idx[k];
    const Eigen::Vector3d q = P.row(i).transpose();
    Query r{&rest, q, culling_margin(scale, q)};
    r.d = dm(i);
    r.face = fm(i);
    closer_face(rest_scene, r);
    dist(i) = r.d;
    faces(i) = r.face;
  }
  rtcReleaseScene(rest_scene);
}

}  // namespace tbsp
