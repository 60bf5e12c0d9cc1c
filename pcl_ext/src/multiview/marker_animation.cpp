#include "tbsp/multiview/marker_animation.h"

#include <algorithm>
#include <cmath>
#include <memory>

#include <Eigen/Geometry>
#include <Eigen/SVD>

#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/deform/deformation_transfer.h"
#include "tbsp/deform/tet_deformer.h"
#include "tbsp/mesh/point_search.h"
#include "tbsp/mesh/tet_mesh.h"
#include "tbsp/mesh/tetrahedralize.h"

namespace tbsp {

namespace {
// True when the points (columns) span a plane: a similarity fitted to them has a defined
// rotation and a non-zero scale (collinear or coincident points do not).
bool spans_a_plane(const Eigen::Matrix3Xd& X) {
  if (X.cols() < 3) return false;
  const Eigen::Matrix3Xd C = X.colwise() - X.rowwise().mean();
  const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3Xd>(C).singularValues();
  return sv(0) > 0 && sv(1) > 1e-6 * sv(0);
}
}  // namespace

bool MarkerAnimationOptions::isValid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (tets != 0 && tets < 100) return fail("tets must be 0 (full resolution) or >= 100");
  if (iterations < 1 || iterations > 100) return fail("iterations must be in 1..100");
  if (start_iterations < 1 || start_iterations > 1000) return fail("start_iterations must be in 1..1000");
  if (!(transfer_radius >= 0) || !std::isfinite(transfer_radius)) return fail("transfer_radius must be >= 0 and finite");
  return true;
}

// The deformer of one set of present markers (the cache key: map entries, in handle order).
struct MarkerAnimation::Deformer {
  TetDeformer d;
  int last_used = -1;  ///< frame it last ran
};

struct MarkerAnimation::Impl {
  DeformationTransfer transfer, tracked, points;
  Eigen::MatrixX3d rest;  ///< per map entry: rest position (aligned frame)
  std::map<std::vector<int>, std::unique_ptr<Deformer>> deformers;
  int last_frame = -1;
  const Deformer* last = nullptr;
};

MarkerAnimation::MarkerAnimation() : impl_(new Impl) {}
MarkerAnimation::~MarkerAnimation() = default;

void MarkerAnimation::setOptions(const MarkerAnimationOptions& o) {
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput("[tbsp::MarkerAnimation::setOptions] " + why);
  options_ = o;
  started_ = false;
}

void MarkerAnimation::setTemplate(const TriMesh& surface) {
  template_ = surface;
  template_tets_ = TetMesh{};
  tets_given_ = false;
  started_ = false;
}

void MarkerAnimation::setTemplate(const TriMesh& surface, const TetMesh& tets) {
  template_ = surface;
  template_tets_ = tets;
  tets_given_ = true;
  started_ = false;
}

void MarkerAnimation::setMarkers(std::vector<std::string> names, Eigen::MatrixXd data) {
  names_ = std::move(names);
  data_ = std::move(data);
  started_ = false;
}

void MarkerAnimation::start() {
  const std::string who = "[tbsp::MarkerAnimation] ";
  const auto t0 = Clock::now();
  started_ = false;
  surface_ = template_;
  tets_ = template_tets_;
  if (surface_.V.rows() < 4 || surface_.F.rows() < 4) throw InvalidInput(who + "the template is empty: set a closed surface mesh");
  if (!surface_.V.allFinite()) throw InvalidInput(who + "the template has non-finite vertices");
  if (names_.empty() || data_.rows() == 0) throw InvalidInput(who + "no marker trajectories: set markers with at least one frame");
  if (data_.cols() != 3 * static_cast<Eigen::Index>(names_.size()))
    throw InvalidInput(who + "the trajectories have " + std::to_string(data_.cols()) + " columns for " + std::to_string(names_.size()) +
                       " markers (3 per marker expected)");
  if (map_.empty()) throw InvalidInput(who + "the marker map is empty: name at least 3 markers and their template vertices");
  // Map entries -> trajectory columns; unknown names and vertices are errors naming them.
  column_.assign(map_.size(), -1);
  for (std::size_t k = 0; k < map_.size(); ++k) {
    const auto it = std::find(names_.begin(), names_.end(), map_[k].marker);
    if (it == names_.end())
      throw InvalidInput(who + "the marker map names '" + map_[k].marker + "', which the trajectories do not have (they have " +
                         std::to_string(names_.size()) + " markers, e.g. '" + names_.front() + "'): fix the name or remove the entry");
    column_[k] = static_cast<int>(it - names_.begin());
    if (map_[k].vertex == -1) {
      if (!map_[k].point.allFinite())
        throw InvalidInput(who + "marker '" + map_[k].marker + "' has neither a template vertex nor a finite point: give one of them");
    } else if (map_[k].vertex < 0 || map_[k].vertex >= surface_.V.rows()) {
      throw InvalidInput(who + "marker '" + map_[k].marker + "' maps to vertex " + std::to_string(map_[k].vertex) + ", but the template has " +
                         std::to_string(surface_.V.rows()) + " vertices");
    }
    for (std::size_t j = 0; j < k; ++j) {
      if (map_[j].marker == map_[k].marker) throw InvalidInput(who + "marker '" + map_[k].marker + "' is mapped twice");
      if (map_[k].vertex >= 0 && map_[j].vertex == map_[k].vertex)
        throw InvalidInput(who + "markers '" + map_[j].marker + "' and '" + map_[k].marker + "' both map to template vertex " +
                           std::to_string(map_[k].vertex) + "; one vertex cannot follow two markers: pick a neighbouring vertex");
    }
  }
  auto present = [&](int f, std::size_t k) { return data_.block<1, 3>(f, 3 * column_[k]).allFinite(); };
  // Rest positions of the map entries (template frame; aligned below with the surface).
  Eigen::MatrixX3d& rest = impl_->rest;
  rest.resize(Eigen::Index(map_.size()), 3);
  for (std::size_t k = 0; k < map_.size(); ++k)
    rest.row(Eigen::Index(k)) = map_[k].vertex >= 0 ? Eigen::RowVector3d(surface_.V.row(map_[k].vertex)) : Eigen::RowVector3d(map_[k].point.transpose());

  report_ = MarkerAnimationReport{};
  report_progress(progress_, 0.0, "tetrahedralize");
  // In the template's own frame (the similarity is applied to the tets afterwards: TetGen and
  // the decimation are not exactly invariant to it).
  if (!tets_given_) {
    try {
      tets_ = options_.tets > 0 ? tetrahedralize_to_size(surface_, options_.tets) : tetrahedralize(surface_);
    } catch (const Error& e) {
      // Open, non-manifold or self-intersecting (parts modelled as overlapping shells): one
      // tetrahedron per triangle (§10.8) instead of a volume.
      tets_ = surface_to_tets(surface_);
      report_.shell_tets = true;
      report_.tetrahedralize_error = e.what();
    }
  }
  // Rigid regions: the tets whose barycentre's nearest template vertex is in the set.
  rigid_tets_.clear();
  if (!rigid_sets_.empty()) {
    std::vector<int> owner(std::size_t(surface_.V.rows()), -1);
    for (std::size_t r = 0; r < rigid_sets_.size(); ++r)
      for (int v : rigid_sets_[r]) {
        if (v < 0 || v >= surface_.V.rows())
          throw InvalidInput(who + "rigid region " + std::to_string(r) + " names vertex " + std::to_string(v) + ", but the template has " +
                             std::to_string(surface_.V.rows()) + " vertices");
        owner[std::size_t(v)] = int(r);
      }
    const PointSearch ps(surface_.V);
    rigid_tets_.assign(rigid_sets_.size(), {});
    for (Eigen::Index t = 0; t < tets_.T.rows(); ++t) {
      Eigen::Vector3d c = Eigen::Vector3d::Zero();
      for (int k = 0; k < 4; ++k) c += tets_.V.row(tets_.T(t, k)).transpose() / 4.0;
      const int o = owner[std::size_t(ps.nearest(c))];
      if (o >= 0) rigid_tets_[std::size_t(o)].push_back(int(t));
    }
    for (std::size_t r = 0; r < rigid_tets_.size(); ++r) {
      if (rigid_tets_[r].empty())
        throw InvalidInput(who + "rigid region " + std::to_string(r) + " covers no tetrahedron of the control mesh: give it more vertices");
      report_.rigid_region_tets.push_back(int(rigid_tets_[r].size()));
    }
  }
  // Similarity alignment on the first frame with >= 3 alignment markers present.
  if (options_.align) {
    int f0 = -1;
    for (int f = 0; f < data_.rows() && f0 < 0; ++f) {
      int n = 0;
      for (std::size_t k = 0; k < map_.size(); ++k) n += map_[k].align && present(f, k);
      if (n >= 3) f0 = f;
    }
    if (f0 < 0) throw InvalidInput(who + "no frame has 3 or more of the map's alignment markers: mark more entries \"align\": true");
    std::vector<std::size_t> use;
    for (std::size_t k = 0; k < map_.size(); ++k)
      if (map_[k].align && present(f0, k)) use.push_back(k);
    Eigen::Matrix3Xd src(3, use.size()), dst(3, use.size());
    for (std::size_t i = 0; i < use.size(); ++i) {
      src.col(Eigen::Index(i)) = rest.row(Eigen::Index(use[i])).transpose();
      dst.col(Eigen::Index(i)) = data_.block<1, 3>(f0, 3 * column_[use[i]]).transpose();
    }
    const bool dst_spans = spans_a_plane(dst);
    if (!dst_spans || !spans_a_plane(src)) {
      std::string names;
      for (std::size_t i = 0; i < use.size() && i < 8; ++i) names += (i ? ", " : "") + map_[use[i]].marker;
      if (use.size() > 8) names += ", ...";
      throw InvalidInput(who + "the alignment markers (" + names + ") " +
                         (dst_spans ? "map to template vertices" : "are, in frame " + std::to_string(f0) + " of the trajectories,") +
                         " on one line or at one point: a similarity needs three that span a plane; mark more, spread-out entries "
                         "\"align\": true (or pose the template yourself and turn the alignment off: --no-align, MarkerAnimationOptions::align)");
    }
    const Eigen::Matrix4d S = Eigen::umeyama(src, dst, true);
    if (!S.allFinite()) throw InvalidInput(who + "the alignment markers are degenerate (collinear or coincident): mark more, spread-out entries");
    report_.alignment = S;
    report_.scale = S.block<3, 1>(0, 0).norm();
    report_.alignment_frame = f0;
    double ss = 0;
    for (std::size_t i = 0; i < use.size(); ++i)
      ss += (S.block<3, 3>(0, 0) * src.col(Eigen::Index(i)) + S.block<3, 1>(0, 3) - dst.col(Eigen::Index(i))).squaredNorm();
    report_.alignment_rms = std::sqrt(ss / double(use.size()));
    const Eigen::Matrix3d A = S.block<3, 3>(0, 0);
    const Eigen::RowVector3d t = S.block<3, 1>(0, 3).transpose();
    surface_.V = (surface_.V * A.transpose()).rowwise() + t;
    tets_.V = (tets_.V * A.transpose()).rowwise() + t;
    rest = (rest * A.transpose()).rowwise() + t;
  }
  report_progress(progress_, 0.0, "transfer");
  DeformationTransferOptions to;
  to.radius = options_.transfer_radius;
  impl_->transfer.setOptions(to);
  impl_->transfer.precompute(tets_, surface_.V);
  tracked_.resize(0, 3);
  if (tracked_rest_.rows() > 0) {
    if (!tracked_rest_.allFinite()) throw InvalidInput(who + "a tracked point is not finite");
    const Eigen::Matrix3d A = report_.alignment.block<3, 3>(0, 0);
    const Eigen::RowVector3d t = report_.alignment.block<3, 1>(0, 3).transpose();
    impl_->tracked.setOptions(to);
    impl_->tracked.precompute(tets_, (tracked_rest_ * A.transpose()).rowwise() + t);
  }
  impl_->points.setOptions(to);
  impl_->points.precompute(tets_, rest);  // the map entries' positions for the residuals (interior points)
  impl_->deformers.clear();
  impl_->last = nullptr;
  report_.tet_vertices = tets_.V.rows();
  report_.tets = tets_.T.rows();
  report_.surface_vertices = surface_.V.rows();
  report_.seconds_setup = seconds_since(t0);
  next_frame_ = 0;
  started_ = true;
}

MarkerAnimation::Deformer& MarkerAnimation::deformerFor(const std::vector<int>& entries, bool& built) {
  auto& cache = impl_->deformers;
  const auto found = cache.find(entries);
  built = found == cache.end();
  if (!built) return *found->second;
  if (cache.size() >= 8) {  // keep the 8 most recently used sets
    auto oldest = cache.begin();
    for (auto it = cache.begin(); it != cache.end(); ++it)
      if (it->second->last_used < oldest->second->last_used) oldest = it;
    if (impl_->last == oldest->second.get()) impl_->last = nullptr;
    cache.erase(oldest);
  }
  auto D = std::make_unique<Deformer>();
  D->d.setMesh(tets_);
  for (const auto& r : rigid_tets_) D->d.addRigidRegion(r);
  for (int k : entries) {
    const Eigen::Vector3d p = impl_->rest.row(k).transpose();
    D->d.addPointHandle(p, p);
  }
  ++report_.deformers_built;
  return *(cache[entries] = std::move(D));
}

bool MarkerAnimation::next(TriMesh& out) {
  if (!started_) start();
  if (next_frame_ >= data_.rows()) return false;
  const int f = next_frame_;
  MarkerFrameReport fr;
  fr.frame = f;
  std::vector<int> entries;
  for (std::size_t k = 0; k < map_.size(); ++k) {
    if (data_.block<1, 3>(f, 3 * column_[k]).allFinite()) entries.push_back(static_cast<int>(k));
    else fr.missing.push_back(map_[k].marker);
  }
  if (entries.empty())
    throw InvalidInput("[tbsp::MarkerAnimation] frame " + std::to_string(f) + ": every mapped marker is missing (a gap in all of them)");
  const auto t0 = Clock::now();
  bool built = false;
  Deformer* Dp = nullptr;
  bool cold = false;
  try {
    Dp = &deformerFor(entries, built);
    cold = built || impl_->last != Dp;
    for (std::size_t h = 0; h < entries.size(); ++h)
      Dp->d.setHandleTarget(static_cast<int>(h), data_.block<1, 3>(f, 3 * column_[std::size_t(entries[h])]).transpose());
    const int its = cold ? options_.start_iterations : options_.iterations;
    for (int i = 0; i < its; ++i) Dp->d.iterate();  // the first iteration factorizes
  } catch (const InvalidInput& e) {
    if (impl_->last == Dp) impl_->last = nullptr;
    impl_->deformers.erase(entries);
    std::string miss;
    for (const auto& n : fr.missing) miss += (miss.empty() ? "" : ", ") + n;
    throw InvalidInput("[tbsp::MarkerAnimation] frame " + std::to_string(f) + " (missing: " + (miss.empty() ? "none" : miss) +
                       "): the markers present cannot drive the template (" + e.what() +
                       "); a part of the template whose markers are all missing has nothing to follow: map more markers on it");
  }
  Deformer& D = *Dp;
  D.last_used = f;
  impl_->last = &D;
  fr.rebuilt = built;
  fr.markers_used = static_cast<int>(entries.size());
  fr.seconds_deform = seconds_since(t0);
  const auto t1 = Clock::now();
  TriMesh m;
  m.F = surface_.F;
  const Eigen::MatrixX3d X = D.d.inputPositions();
  m.V = impl_->transfer.apply(X);
  if (tracked_rest_.rows() > 0) tracked_ = impl_->tracked.apply(X);
  fr.seconds_transfer = seconds_since(t1);
  bool interior = false;
  for (int k : entries) interior = interior || map_[std::size_t(k)].vertex < 0;
  const Eigen::MatrixX3d P = interior ? impl_->points.apply(X) : Eigen::MatrixX3d();
  std::vector<double> res;
  res.reserve(entries.size());
  for (int k : entries) {
    const Eigen::RowVector3d at = map_[std::size_t(k)].vertex >= 0 ? Eigen::RowVector3d(m.V.row(map_[std::size_t(k)].vertex)) : Eigen::RowVector3d(P.row(k));
    res.push_back((at - data_.block<1, 3>(f, 3 * column_[std::size_t(k)])).norm());
  }
  std::sort(res.begin(), res.end());
  fr.median_residual = res[res.size() / 2];
  fr.max_residual = res.back();
  report_.frames.push_back(fr);
  ++next_frame_;
  out = std::move(m);
  report_progress(progress_, double(next_frame_) / double(data_.rows()), "frames");  // may throw Cancelled: the frame is out already
  return true;
}

std::vector<TriangulatedMarker> triangulate_image_markers(const std::vector<Camera>& cameras, const std::vector<ImageMarker>& markers) {
  const std::string who = "[tbsp::triangulate_image_markers] ";
  std::string known;
  for (const auto& c : cameras) known += (known.empty() ? "" : ", ") + c.name();
  std::vector<TriangulatedMarker> out;
  for (const auto& m : markers) {
    std::vector<Camera> cams;
    std::vector<Eigen::Vector2d> px;
    for (const auto& [name, p] : m.pixels) {
      const auto it = std::find_if(cameras.begin(), cameras.end(), [&](const Camera& c) { return c.name() == name; });
      if (it == cameras.end())
        throw InvalidInput(who + "marker '" + m.marker + "' has a pixel in camera '" + name + "', which is not one of the cameras (" + known + ")");
      if (!p.allFinite()) throw InvalidInput(who + "marker '" + m.marker + "': its pixel in camera '" + name + "' is not finite");
      cams.push_back(*it);
      px.push_back(p);
    }
    if (cams.size() < 2)
      throw InvalidInput(who + "marker '" + m.marker + "' is seen in " + std::to_string(cams.size()) +
                         " camera(s): place it in at least 2 views (3 or more, far apart, triangulate better)");
    TriangulatedMarker t;
    t.marker = m.marker;
    t.position = triangulate(cams, px);
    for (const auto& c : cams)
      if (!(c.depth(t.position) > 0))
        throw InvalidInput(who + "marker '" + m.marker + "' triangulates behind camera '" + c.name() + "': its pixels do not show one point; check them");
    t.views = int(cams.size());
    t.rms_px = reprojection_rms(cams, px, t.position);
    out.push_back(t);
  }
  return out;
}

TriMesh pose_template_to_image_markers(const TriMesh& tmpl, const std::vector<MarkerMapEntry>& map, const std::vector<ImageMarker>& image_markers,
                                       const std::vector<Camera>& cameras, const MarkerAnimationOptions& o,
                                       const std::vector<std::vector<int>>& rigid, ImagePoseReport* report) {
  const std::string who = "[tbsp::pose_template_to_image_markers] ";
  if (image_markers.size() < 3)
    throw InvalidInput(who + std::to_string(image_markers.size()) + " markers are placed in the images: place at least 3 (spread over the body)");
  std::vector<TriangulatedMarker> tri = triangulate_image_markers(cameras, image_markers);
  std::vector<MarkerMapEntry> entries;
  std::vector<std::string> names;
  Eigen::MatrixXd data(1, 3 * Eigen::Index(tri.size()));
  for (std::size_t k = 0; k < tri.size(); ++k) {
    const auto it = std::find_if(map.begin(), map.end(), [&](const MarkerMapEntry& e) { return e.marker == tri[k].marker; });
    if (it == map.end())
      throw InvalidInput(who + "image marker '" + tri[k].marker + "' has no template vertex or point in the map: add an entry for it");
    entries.push_back(*it);
    names.push_back(tri[k].marker);
    data.block<1, 3>(0, 3 * Eigen::Index(k)) = tri[k].position.transpose();
  }
  MarkerAnimation anim;
  anim.setOptions(o);
  anim.setTemplate(tmpl);
  anim.setMarkerMap(entries);
  anim.setRigidRegions(rigid);
  anim.setMarkers(names, data);
  TriMesh out;
  anim.next(out);
  if (report) {
    report->markers = std::move(tri);
    report->animation = anim.report();
  }
  return out;
}

}  // namespace tbsp
