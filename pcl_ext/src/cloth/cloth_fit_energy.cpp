// E_fit of thesis §10.7 (eq. 10.6–10.8): one forward simulation of a material, rendered into
// every view and compared with the observations. The search is in cloth_parameter_search.cpp.
#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "../multiview/capture_features.h"
#include "tbsp/cloth/cloth_parameter_estimation.h"
#include "tbsp/core/error.h"
#include "tbsp/core/error_kind.h"
#include "tbsp/multiview/rasterizer.h"

namespace tbsp {

bool ClothEstimationOptions::isValid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(alpha >= 0) || !(beta >= 0) || !(alpha + beta > 0) || !std::isfinite(alpha + beta)) return fail("alpha and beta must be ≥ 0, not both 0");
  if (!(max_pixel_error > 0) || !std::isfinite(max_pixel_error)) return fail("max_pixel_error must be positive");
  if (!(clothness_min > 0 && clothness_min <= 1)) return fail("clothness_min must be in (0, 1]");
  if (frame_stride < 1 || frame_stride > 1000) return fail("frame_stride must be in 1..1000");
  if (settle_frames < 0) return fail("settle_frames must be ≥ 0");
  if (!(lower.d_n >= 0 && lower.d_t >= 0 && lower.k_bend >= 0 && upper.k_bend <= 1) || !std::isfinite(upper.d_n + upper.d_t))
    return fail("the search box must lie in d_n, d_t ≥ 0 (finite), k_bend ∈ [0, 1]");
  if (!(upper.d_n >= lower.d_n && upper.d_t >= lower.d_t && upper.k_bend >= lower.k_bend)) return fail("the search box has upper < lower");
  if (grid_k < 1 || grid_k > 10) return fail("grid_k must be in 1..10");
  if (greedy_samples < 0) return fail("greedy_samples must be ≥ 0");
  if (greedy_batch < 1 || greedy_batch > 1000) return fail("greedy_batch must be in 1..1000");
  if (start_samples < 1 || start_samples > 1000) return fail("start_samples must be in 1..1000");
  if (max_evaluations < start_samples) return fail("max_evaluations must be ≥ start_samples");
  if (!(tolerance > 0) || !std::isfinite(tolerance)) return fail("tolerance must be positive");
  if (window < 0 || window > 10000) return fail("window must be in 0..10000 (0 = the whole sequence)");
  if (window_phases < 1 || window_phases > std::max(window, 1)) return fail("window_phases must be in 1..max(window, 1)");
  return true;
}

ClothParameterEstimation::ClothParameterEstimation(const AnimatableModel& model, const std::vector<SkeletonPose>& poses,
                                                   const ClothObservations& observations)
    : model_(model), poses_(poses), obs_(observations) {
  const std::string w = "[tbsp::ClothParameterEstimation] ";
  model_.validate("tbsp::ClothParameterEstimation");
  if (obs_.numFrames() < 2) throw InvalidInput(w + "at least two observed frames are needed (got " + std::to_string(obs_.numFrames()) + ")");
  if (int(poses_.size()) != obs_.numFrames())
    throw InvalidInput(w + std::to_string(poses_.size()) + " skeleton poses for " + std::to_string(obs_.numFrames()) +
                       " observed frames: give one pose per recorded frame (the same frame range and step)");
  for (std::size_t f = 0; f < poses_.size(); ++f)
    if (int(poses_[f].size()) != model_.skeleton.numJoints())
      throw InvalidInput(w + "pose " + std::to_string(f) + " has " + std::to_string(poses_[f].size()) + " joints, the model's skeleton " +
                         std::to_string(model_.skeleton.numJoints()));
  for (int r = 0; r < numRegions(); ++r) checkRegion(r);
}

void ClothParameterEstimation::setReferenceSequence(const std::vector<Eigen::MatrixX3d>& frames) {
  const std::string w = "[tbsp::ClothParameterEstimation] reference sequence: ";
  if (int(frames.size()) != obs_.numFrames())
    throw InvalidInput(w + std::to_string(frames.size()) + " meshes for " + std::to_string(obs_.numFrames()) + " observed frames (one per frame)");
  for (std::size_t f = 0; f < frames.size(); ++f) {
    if (frames[f].rows() != model_.mesh.V.rows())
      throw InvalidInput(w + "frame " + std::to_string(f) + " has " + std::to_string(frames[f].rows()) + " vertices, the model " +
                         std::to_string(model_.mesh.V.rows()) + " (the sequence the model was built from is needed)");
    if (!frames[f].allFinite()) throw InvalidInput(w + "frame " + std::to_string(f) + " has non-finite coordinates");
  }
  reference_ = &frames;
}

void ClothParameterEstimation::setOptions(const ClothEstimationOptions& o) {
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput("[tbsp::ClothParameterEstimation] " + why);
  options_ = o;
  for (int r = 0; r < numRegions(); ++r) checkRegion(r);
}

bool ClothParameterEstimation::inRegion(Eigen::Index i, int region) const {
  return model_.clothness(i) >= options_.clothness_min && (model_.region.size() ? model_.region(i) : 0) == region;
}

int ClothParameterEstimation::clothVertices(int region) const {
  int n = 0;
  for (Eigen::Index i = 0; i < model_.clothness.size(); ++i) n += inRegion(i, region);
  return n;
}

void ClothParameterEstimation::checkRegion(int region) const {
  if (region < 0 || region >= numRegions())
    throw InvalidInput("[tbsp::ClothParameterEstimation] region " + std::to_string(region) + " does not exist (the model has " +
                       std::to_string(numRegions()) + ")");
  if (clothVertices(region) == 0)
    throw InvalidInput("[tbsp::ClothParameterEstimation] cloth region " + std::to_string(region) + " has no vertex with clothness ≥ " +
                       std::to_string(options_.clothness_min) +
                       ": there is no cloth to estimate a material for (segment a sequence in which the cloth moves, or drop the region)");
}

namespace {

// What one simulation window adds: sums over its scored frames.
struct Partial {
  double sum = 0, sil = 0, sift = 0;
  long rim_samples = 0, feature_samples = 0;
  int frames = 0;
};

// A work share's exchange after each process ran its simulations: every process ends with every
// simulation's terms (each computed by one process, 0 on the others: the sums are exact) and, if
// any failed, with the lowest failed simulation's error — its type and its message (sent by the
// process that ran it) — in its place.
void share_results(const ClothWorkShare& share, std::vector<Partial>& part, std::vector<std::exception_ptr>& err) {
  constexpr std::size_t kValues = 7;
  std::vector<double> v(part.size() * kValues, 0.0);
  for (std::size_t k = 0; k < part.size(); ++k) {
    if (long(k) % share.size != share.rank) continue;
    const Partial& p = part[k];
    double* x = &v[k * kValues];
    x[0] = p.sum, x[1] = p.sil, x[2] = p.sift, x[3] = double(p.rim_samples), x[4] = double(p.feature_samples), x[5] = p.frames;
    x[6] = error_kind(err[k]);
  }
  share.sum(v);
  long failed = -1;
  for (std::size_t k = 0; k < part.size(); ++k) {
    const double* x = &v[k * kValues];
    part[k] = Partial{x[0], x[1], x[2], long(x[3]), long(x[4]), int(x[5])};
    if (failed < 0 && x[6] != 0) failed = long(k);
  }
  if (failed < 0) return;
  // the failed simulation's error, with the message of the process that ran it
  const std::exception_ptr e = share_error(int(v[std::size_t(failed) * kValues + 6]), failed % share.size == share.rank,
                                           err[std::size_t(failed)], share.sum);
  for (auto& x : err) x = nullptr;
  err[std::size_t(failed)] = e;
}

struct FrameTerms {
  double sil = 0, sift = 0;
  long nsil = 0, nsift = 0;
};

// The surface point at camera depth `z` projecting to `q` is the visible surface there.
bool visible(const RenderBuffers& b, const Eigen::Vector2d& q, double z) {
  const int x = int(std::lround(q.x())), y = int(std::lround(q.y()));
  if (x < 0 || y < 0 || x >= b.width || y >= b.height) return false;
  const float d = b.depth[std::size_t(y) * std::size_t(b.width) + std::size_t(x)];
  return std::isfinite(d) && z <= d * 1.01;
}

// The camera cropped to the pixels the mesh can cover (the box of its projected vertices, 2 px
// of margin): the same projection shifted by the crop's corner `offset`. The renders of a body in
// a studio view cover a fraction of the image; clearing and scanning only the crop is what a
// sample's eight renders per frame cost.
Camera crop_to_mesh(const Camera& cam, const Eigen::MatrixX3d& V, Eigen::Vector2i& offset) {
  double x0 = std::numeric_limits<double>::infinity(), y0 = x0, x1 = -x0, y1 = -x0;
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    const Eigen::Vector3d X = V.row(i).transpose();
    if (!(cam.depth(X) > 0)) return offset = Eigen::Vector2i::Zero(), cam;  // behind the camera: no crop
    const Eigen::Vector2d q = cam.project(X);
    x0 = std::min(x0, q.x()), x1 = std::max(x1, q.x()), y0 = std::min(y0, q.y()), y1 = std::max(y1, q.y());
  }
  if (!(x1 >= x0) || !std::isfinite(x0 + x1 + y0 + y1)) return offset = Eigen::Vector2i::Zero(), cam;
  const int W = cam.width(), H = cam.height();
  const int a = std::clamp(int(std::floor(x0)) - 2, 0, W - 1), b = std::clamp(int(std::ceil(x1)) + 2, 0, W - 1);
  const int c = std::clamp(int(std::floor(y0)) - 2, 0, H - 1), d = std::clamp(int(std::ceil(y1)) + 2, 0, H - 1);
  offset = Eigen::Vector2i(a, c);
  return cam.cropped(a, c, b - a + 1, d - c + 1);
}

}  // namespace

void ClothParameterEstimation::setWorkShare(ClothWorkShare share) {
  const std::string w = "[tbsp::ClothParameterEstimation] work share: ";
  if (share.size < 1) throw InvalidInput(w + "size must be ≥ 1 (got " + std::to_string(share.size) + ")");
  if (share.rank < 0 || share.rank >= share.size)
    throw InvalidInput(w + "rank " + std::to_string(share.rank) + " is not in 0.." + std::to_string(share.size - 1));
  if (share.size > 1 && !share.sum) throw InvalidInput(w + "several processes need a collective sum (MPI_Allreduce)");
  share_ = std::move(share);
}

ClothFitEnergy ClothParameterEstimation::evaluate(int region, const ClothMaterial& rho) const { return evaluate(region, std::vector<ClothMaterial>{rho}).front(); }

std::vector<ClothFitEnergy> ClothParameterEstimation::evaluate(int region, const std::vector<ClothMaterial>& rhos) const {
  checkRegion(region);
  const Eigen::Index nv = model_.mesh.V.rows();
  std::vector<char> in_region(std::size_t(nv), 0);
  for (Eigen::Index i = 0; i < nv; ++i)
    in_region[std::size_t(i)] = inRegion(i, region);
  std::vector<char> face_in(std::size_t(model_.mesh.F.rows()), 0);
  for (Eigen::Index f = 0; f < model_.mesh.F.rows(); ++f)
    face_in[std::size_t(f)] = in_region[std::size_t(model_.mesh.F(f, 0))] && in_region[std::size_t(model_.mesh.F(f, 1))] && in_region[std::size_t(model_.mesh.F(f, 2))];
  // one model per sample: the region's material replaced (validated by ModelAnimator below)
  std::vector<AnimatableModel> models(rhos.size(), model_);
  for (std::size_t i = 0; i < rhos.size(); ++i) models[i].materials[std::size_t(region)] = rhos[i];

  const auto& cams = obs_.cameras();
  const int views = obs_.numViews(), frames = obs_.numFrames(), stride = options_.frame_stride;
  const double cap2 = options_.max_pixel_error * options_.max_pixel_error;
  const int W = options_.window;
  if (W > 0 && !reference_)
    throw InvalidInput("[tbsp::ClothParameterEstimation] window = " + std::to_string(W) +
                       " restarts the simulation from the reference mesh sequence: call setReferenceSequence, or set window = 0 (the whole sequence)");
  const double dt = model_.settings.time_step;
  // Frames [n0, n1): one simulation restarted at n0 (from the reference with a window, else from
  // the settled first pose), rendered into every view and compared with the observations.
  auto run = [&](const AnimatableModel& m, int n0, int n1, Partial& e) {
    Rasterizer raster;
    std::vector<RenderBuffers> prev(static_cast<std::size_t>(views)), cur(static_cast<std::size_t>(views));
    std::vector<Eigen::Vector2i> prev_off(static_cast<std::size_t>(views)), cur_off(static_cast<std::size_t>(views));  // crop corners
    std::vector<Camera> crop(static_cast<std::size_t>(views));
    bool prev_valid = false;
    ModelAnimator anim(m);
    TriMesh mesh;
    mesh.F = m.mesh.F;
    for (int n = n0; n < n1; ++n) {
      const bool restart = n == n0;
      if (restart && W > 0) {
        const auto& ref = *reference_;
        const std::size_t a = std::size_t(n > 0 ? n - 1 : 0), b = std::size_t(n > 0 ? n : std::min(1, frames - 1));
        mesh.V = anim.startFrom(poses_[std::size_t(n)], ref[std::size_t(n)], (ref[b] - ref[a]) / dt);
      } else {
        mesh.V = restart ? anim.start(poses_[0], options_.settle_frames) : anim.step(poses_[std::size_t(n)]);
      }
      const bool evaluated = !restart && n % stride == 0;
      const bool lift = (n + 1) % stride == 0 && n + 1 < n1;  // the next frame is evaluated
      if (!evaluated && !lift) {
        prev_valid = false;
        continue;
      }
      for (int k = 0; k < views; ++k) {
        crop[std::size_t(k)] = crop_to_mesh(cams[std::size_t(k)], mesh.V, cur_off[std::size_t(k)]);
        raster.render(mesh, crop[std::size_t(k)], cur[std::size_t(k)]);
      }
      if (evaluated) {
        FrameTerms t;
        for (int k = 0; k < views; ++k) {
          const Camera& cam = cams[std::size_t(k)];
          for (int v : rim_vertices(mesh, crop[std::size_t(k)], cur[std::size_t(k)])) {
            if (!in_region[std::size_t(v)]) continue;
            const double d = obs_.boundaryDistance(n, k, cam.project(mesh.V.row(v).transpose()));
            t.sil += std::min(d * d, cap2);
            ++t.nsil;
          }
          if (!prev_valid) continue;
          const RenderBuffers& b = prev[std::size_t(k)];
          const Eigen::Vector2i& o = prev_off[std::size_t(k)];
          const Eigen::Vector2d co = cur_off[std::size_t(k)].cast<double>();
          for (const FeaturePair& p : obs_.correspondences(n, k)) {
            const int x = int(std::lround(p.from.x())) - o.x(), y = int(std::lround(p.from.y())) - o.y();
            if (x < 0 || y < 0 || x >= b.width || y >= b.height) continue;
            const std::size_t at = std::size_t(y) * std::size_t(b.width) + std::size_t(x);
            const int face = b.face[at];
            if (face < 0 || !face_in[std::size_t(face)] || !detail::smooth_depth(b, x, y)) continue;
            const double b1 = b.bary[2 * at], b2 = b.bary[2 * at + 1];
            const Eigen::Vector3d X = detail::surface_point(mesh, face, Eigen::Vector3d(1 - b1 - b2, b1, b2));
            if (!(cam.depth(X) > 0)) continue;
            const Eigen::Vector2d q = cam.project(X);
            if (!visible(cur[std::size_t(k)], q - co, cam.depth(X))) continue;  // occluded at frame n: the feature cannot be this point
            const double d2 = (q - p.to.cast<double>()).squaredNorm();
            t.sift += std::min(d2, cap2);
            ++t.nsift;
          }
        }
        const double es = t.nsil ? t.sil / double(t.nsil) : 0.0, ef = t.nsift ? t.sift / double(t.nsift) : 0.0;
        e.sum += options_.alpha * es + options_.beta * ef;
        e.sil += es;
        e.sift += ef;
        e.rim_samples += t.nsil;
        e.feature_samples += t.nsift;
        ++e.frames;
      }
      std::swap(prev, cur);
      std::swap(prev_off, cur_off);
      prev_valid = true;
    }
  };
  // With a window the windows are independent simulations. Every (sample, window) pair is one
  // simulation: they run in parallel (and dealt over the processes of a work share), each
  // sample's summed in window order, so the result depends on neither the thread nor the
  // process count.
  // Windows [n0, n1): with P phases the window grid is laid P times, shifted by W·p/P frames (the
  // first window of a shifted grid is shorter), and every scored frame of every phase is averaged.
  std::vector<std::pair<int, int>> spans;
  if (W <= 0) spans.push_back({0, frames});
  for (int p = 0, P = options_.window_phases; W > 0 && p < P; ++p) {
    const int shift = W * p / P;
    if (shift > 0) spans.push_back({0, std::min(frames, shift)});
    for (int n0 = shift; n0 < frames; n0 += W) spans.push_back({n0, std::min(frames, n0 + W)});
  }
  const long nwin = long(spans.size()), items = long(rhos.size()) * nwin;
  const int size = share_.size, rank = share_.rank;
  std::vector<long> mine;  // the simulations this process runs
  for (long k = 0; k < items; ++k)
    if (k % size == rank) mine.push_back(k);
  std::vector<Partial> part(static_cast<std::size_t>(items));
  std::vector<std::exception_ptr> err(static_cast<std::size_t>(items));
#pragma omp parallel for schedule(dynamic, 1) if (mine.size() > 1)
  for (std::size_t q = 0; q < mine.size(); ++q) {
    const long k = mine[q];
    const auto& sp = spans[std::size_t(k % nwin)];
    try {
      run(models[std::size_t(k / nwin)], sp.first, sp.second, part[std::size_t(k)]);
    } catch (...) {
      err[std::size_t(k)] = std::current_exception();
    }
  }
  if (size > 1) share_results(share_, part, err);
  for (const std::exception_ptr& e : err)  // the lowest simulation's error, with its type (a cancel stays a cancel)
    if (e) std::rethrow_exception(e);
  std::vector<ClothFitEnergy> out(rhos.size());
  for (std::size_t i = 0; i < rhos.size(); ++i) {
    ClothFitEnergy& e = out[i];
    double sum = 0, sum_sil = 0, sum_sift = 0;
    for (long w = 0; w < nwin; ++w) {
      const Partial& p = part[std::size_t(long(i) * nwin + w)];
      sum += p.sum;
      sum_sil += p.sil;
      sum_sift += p.sift;
      e.rim_samples += p.rim_samples;
      e.feature_samples += p.feature_samples;
      e.frames += p.frames;
    }
    if (e.frames) {
      e.e_fit = sum / e.frames;
      e.e_sil = sum_sil / e.frames;
      e.e_sift = sum_sift / e.frames;
    }
  }
  return out;
}

}  // namespace tbsp
