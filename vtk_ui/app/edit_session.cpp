#include "edit_session.h"

#include <algorithm>
#include <chrono>
#include <omp.h>
#include <Eigen/Geometry>
#include <Eigen/SVD>

#include "tbsp/core/error.h"
#include "tbsp/deform/deformation_transfer.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/tet_mesh_io.h"
#include "tbsp/plugins/constraints_json.h"
#include "tbsp/plugins/tet_job_json.h"
#include "tbsp/solve/blas_threads.h"

namespace tbsp::studio {

namespace {

bool is_tet_path(const std::string& p) { return p.size() > 5 && p.compare(p.size() - 5, 5, ".mesh") == 0; }

// The documents without the handles' motions: when only motions differ, the deformer keeps
// its factorization and iterates on from where it is.
std::string structure_key(const nlohmann::json& handles, const nlohmann::json& rigid, const nlohmann::json& stiffness) {
  nlohmann::json h = handles;
  if (h.contains("handles"))
    for (auto& e : h["handles"]) {
      e.erase("translate");
      e.erase("rotate");
    }
  h.erase("iterations");
  return h.dump() + "|" + rigid.dump() + "|" + stiffness.dump();
}

nlohmann::json motion_json(const Eigen::Vector3d& t, const Eigen::Vector3d& axis, double degrees, const Eigen::Vector3d& c) {
  nlohmann::json j;
  j["translate"] = {t.x(), t.y(), t.z()};
  if (degrees != 0) j["rotate"] = {{"axis", {axis.x(), axis.y(), axis.z()}}, {"degrees", degrees}, {"center", {c.x(), c.y(), c.z()}}};
  return j;
}

}  // namespace

RigidMotion best_rigid_motion(const Eigen::MatrixX3d& rest, const Eigen::MatrixX3d& now) {
  RigidMotion m;
  if (rest.rows() == 0) return m;
  const Eigen::RowVector3d ca = rest.colwise().mean(), cb = now.colwise().mean();
  m.center = ca.transpose();
  m.translation = (cb - ca).transpose();
  if (rest.rows() < 3) return m;
  const Eigen::Matrix3d H = (rest.rowwise() - ca).transpose() * (now.rowwise() - cb);
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  if ((svd.matrixV() * svd.matrixU().transpose()).determinant() < 0) D(2, 2) = -1;
  const Eigen::Matrix3d R = svd.matrixV() * D * svd.matrixU().transpose();
  const Eigen::AngleAxisd aa(R);
  m.axis = aa.axis();
  m.angle = aa.angle();
  return m;
}

EditSession::EditSession() { worker_ = std::thread([this] { workerLoop(); }); }

EditSession::~EditSession() { stopWorker(); }

void EditSession::stopWorker() {
  {
    std::lock_guard<std::mutex> lk(m_);
    stop_ = true;
  }
  cv_.notify_all();
  shown_cv_.notify_all();
  if (worker_.joinable()) worker_.join();
}

const TetJobSetup& EditSession::setup() const {
  if (!setup_) throw InvalidInput("no mesh is open: open a closed surface or a .mesh tet mesh first");
  return *setup_;
}

// The surface solver needs no tet mesh: regions resolve against the surface's own vertices.
static std::unique_ptr<TetJobSetup> surface_setup(const std::string& path) {
  auto s = std::make_unique<TetJobSetup>();
  s->surface = read_mesh(path);
  if (s->surface.F.rows() == 0) throw InvalidInput(path + ": has no faces: surface editing needs a triangle mesh");
  s->tets.V = s->surface.V;
  s->to_input.resize(std::size_t(s->surface.V.rows()));
  for (std::size_t i = 0; i < s->to_input.size(); ++i) s->to_input[i] = Eigen::Index(i);
  s->dist.assign(s->to_input.size(), 0.0);
  s->snap = 1e-12;
  return s;
}

void EditSession::open(const std::string& path, long target_tets, EditSolver solver) {
  waitIdle();
  if (solver == EditSolver::Surface && is_tet_path(path))
    throw InvalidInput(path + ": a tet mesh is edited with the tet solver, not the surface solver");
  auto s = solver == EditSolver::Surface ? surface_setup(path)
           : std::make_unique<TetJobSetup>(is_tet_path(path) ? tet_job_setup(read_tet_mesh(path))
                                                              : tet_job_setup(read_mesh(path), int(target_tets), path));
  std::lock_guard<std::mutex> lk(m_);
  setup_ = std::move(s);
  path_ = path;
  target_tets_ = target_tets;
  solver_ = solver;
  ++setup_serial_;
  docs_ = Docs{{{"handles", nlohmann::json::array()}}, nlohmann::json(), nlohmann::json(), false};
  undo_.clear();
  redo_.clear();
  worker_docs_ = docs_;
  ++version_;
  surface_ = setup_->surface.V;
  iterations_ = 0;
}

TetJob EditSession::parseDocs(const Docs& d) const {
  TetJobFiles f;
  f.handles = "handles";
  f.handles_doc = d.handles;
  if (!d.rigid.is_null()) {
    f.rigid = "rigid";
    f.rigid_doc = d.rigid;
  }
  if (!d.stiffness.is_null()) {
    f.stiffness = "stiffness";
    f.stiffness_doc = d.stiffness;
  }
  if (d.handles["handles"].empty()) return TetJob{};
  return f.parse(setup().numInputVertices());
}

void EditSession::edit(const std::function<void(Docs&)>& change, bool undoable) {
  setup();
  Docs next = docs_;
  change(next);
  parseDocs(next);  // the CLI's validation: throws naming the item, nothing changes
  std::lock_guard<std::mutex> lk(m_);
  if (undoable || undo_.empty()) undo_.push_back(docs_);
  redo_.clear();
  docs_ = std::move(next);
  worker_docs_ = docs_;
  ++version_;
}

int EditSession::addHandle(const nlohmann::json& region) {
  const auto& s = setup();
  // which tet vertices the region takes: refuse an empty one before it becomes a document
  TetJob probe;
  parse_tet_handles({{"handles", {region}}}, s.numInputVertices(), "new handle", probe);
  const auto vs = resolve_region_vertices(probe.handles[0].region, s.tets.V, s.to_input, s.dist, s.snap);
  if (vs.empty())
    throw InvalidInput("the region selects no vertex of the tet mesh (" + std::to_string(s.tets.V.rows()) +
                       " vertices): select a larger region");
  // hold the region where it is now (least-squares rigid motion of its vertices)
  const std::vector<int> sv = [&] {
    std::vector<int> out;
    for (int v : vs)
      if (s.from_tets || !s.decimated) { if (v < s.surface.V.rows()) out.push_back(v); }
      else out.push_back(int(s.to_input[std::size_t(v)]));
    return out;
  }();
  const Eigen::MatrixX3d now = currentSurface();
  Eigen::MatrixX3d a(Eigen::Index(sv.size()), 3), b(Eigen::Index(sv.size()), 3);
  for (std::size_t k = 0; k < sv.size(); ++k) {
    a.row(Eigen::Index(k)) = s.surface.V.row(sv[k]);
    b.row(Eigen::Index(k)) = now.row(sv[k]);
  }
  const RigidMotion m = best_rigid_motion(a, b);
  nlohmann::json h = region;
  if ((b - a).cwiseAbs().maxCoeff() > 0) h.update(motion_json(m.translation, m.axis, m.angle * 180.0 / M_PI, m.center));
  int index = 0;
  edit([&](Docs& d) {
    d.handles["handles"].push_back(h);
    index = int(d.handles["handles"].size()) - 1;
  });
  return index;
}

void EditSession::setHandleMotion(int i, const Eigen::Vector3d& t, const Eigen::Vector3d& axis, double degrees,
                                  const Eigen::Vector3d& c, bool undoable) {
  if (i < 0 || i >= numHandles())
    throw InvalidInput("handle " + std::to_string(i) + " does not exist (" + std::to_string(numHandles()) + " handles)");
  edit([&](Docs& d) {
    auto& h = d.handles["handles"][std::size_t(i)];
    h.erase("translate");
    h.erase("rotate");
    h.update(motion_json(t, axis, degrees, c));
  }, undoable);
}

RigidMotion EditSession::handleMotion(int i) const {
  if (i < 0 || i >= numHandles()) throw InvalidInput("handle " + std::to_string(i) + " does not exist");
  return parseDocs(docs_).handles[std::size_t(i)].motion;
}

void EditSession::removeHandle(int i) {
  if (i < 0 || i >= numHandles()) throw InvalidInput("handle " + std::to_string(i) + " does not exist");
  edit([&](Docs& d) { d.handles["handles"].erase(std::size_t(i)); });
}

int EditSession::numHandles() const { return int(docs_.handles["handles"].size()); }

std::vector<int> EditSession::handleSurfaceVertices(int i) const {
  const auto& s = setup();
  const TetJob job = parseDocs(docs_);
  if (i < 0 || i >= int(job.handles.size())) return {};
  const auto vs = resolve_region_vertices(job.handles[std::size_t(i)].region, s.tets.V, s.to_input, s.dist, s.snap);
  std::vector<int> out;
  for (int v : vs) {
    if (s.from_tets || !s.decimated) { if (v < s.surface.V.rows()) out.push_back(v); }
    else out.push_back(int(s.to_input[std::size_t(v)]));
  }
  return out;
}

void EditSession::addRigid(const nlohmann::json& region) {
  const auto& s = setup();
  if (solver_ == EditSolver::Surface)
    throw InvalidInput("rigid regions belong to the tet solver: open the mesh for volumetric editing to use them");
  TetJob probe;
  parse_tet_rigid({{"rigid", {region}}}, s.numInputVertices(), "new rigid region", probe);
  if (resolve_region_tets(probe.rigid[0], s.tets, s.to_input, s.dist, s.snap).empty())
    throw InvalidInput("the rigid region contains no tetrahedron: select a larger region");
  edit([&](Docs& d) {
    if (d.rigid.is_null()) d.rigid = {{"rigid", nlohmann::json::array()}};
    d.rigid["rigid"].push_back(region);
  });
}

void EditSession::addStiffness(const nlohmann::json& region, double st) {
  if (solver_ == EditSolver::Surface)
    throw InvalidInput("stiffness belongs to the tet solver: open the mesh for volumetric editing to use it");
  if (!(st > 0) || !std::isfinite(st)) throw InvalidInput("stiffness must be > 0 and finite, got " + std::to_string(st));
  edit([&](Docs& d) {
    if (d.stiffness.is_null()) d.stiffness = {{"default", 1.0}, {"regions", nlohmann::json::array()}};
    nlohmann::json r = region;
    r["stiffness"] = st;
    d.stiffness["regions"].push_back(r);
  });
}

void EditSession::setRotationInterpolation(bool on) {
  edit([&](Docs& d) { d.handles["rotation_interpolation"] = on; });
}

void EditSession::loadHandles(const std::string& handles_path, const std::string& rigid_path, const std::string& stiffness_path) {
  const auto& s = setup();
  // the CLI's reader and parser, with the real file names in the messages
  const TetJobFiles f = TetJobFiles::load(handles_path, rigid_path, stiffness_path);
  const TetJob job = f.parse(s.numInputVertices());
  if (solver_ == EditSolver::Surface && (!job.rigid.empty() || !job.stiffness.empty()))
    throw InvalidInput(handles_path + ": rigid regions and stiffness belong to the tet solver (surface editing is open)");
  for (const auto& h : job.handles) {
    if (h.kind != TetHandleSpec::Region)
      throw FileError(handles_path + ": " + h.where + ": tbsp-studio edits region handles (vertices, sphere, box); "
                      "vertex and point handles are for tbsp tetdeform");
    if (resolve_region_vertices(h.region, s.tets.V, s.to_input, s.dist, s.snap).empty())
      throw FileError(handles_path + ": " + h.where + ": the region selects no vertex of the mesh; enlarge it");
  }
  edit([&](Docs& d) {
    d.handles = f.handles_doc;
    d.rigid = rigid_path.empty() ? nlohmann::json() : f.rigid_doc;
    d.stiffness = stiffness_path.empty() ? nlohmann::json() : f.stiffness_doc;
  });
}

void EditSession::setRotationField(bool on) {
  edit([&](Docs& d) { d.rotation_field = on; });
}

nlohmann::json EditSession::constraintsDocOf(const Docs& d) const {
  const auto& s = setup();
  nlohmann::json c = {{"rotation_field", d.rotation_field}, {"constraints", nlohmann::json::array()},
                      {"comment", "tbsp-studio surface edit of " + path_ + ": tbsp deform --mesh MESH --constraints THIS"}};
  const TetJob job = parseDocs(d);
  for (const auto& h : job.handles) {
    const auto vs = resolve_region_vertices(h.region, s.tets.V, s.to_input, s.dist, s.snap);
    const Eigen::Matrix3d R = h.motion.R();
    const Eigen::Vector3d t = h.motion.center - R * h.motion.center + h.motion.translation;
    nlohmann::json M = nlohmann::json::array();
    for (int r = 0; r < 3; ++r) M.push_back({R(r, 0), R(r, 1), R(r, 2), t(r)});
    M.push_back({0.0, 0.0, 0.0, 1.0});
    c["constraints"].push_back({{"vertices", vs}, {"hard", true}, {"transform", M}});
  }
  return c;
}

nlohmann::json EditSession::constraintsDoc() const { return constraintsDocOf(docs_); }

bool EditSession::step(std::vector<Docs>& from, std::vector<Docs>& to) {
  std::lock_guard<std::mutex> lk(m_);
  if (from.empty()) return false;
  to.push_back(docs_);
  docs_ = from.back();
  from.pop_back();
  worker_docs_ = docs_;
  ++version_;
  return true;
}

bool EditSession::undo() { return step(undo_, redo_); }
bool EditSession::redo() { return step(redo_, undo_); }

void EditSession::setFrameCallback(FrameCallback cb) {
  std::lock_guard<std::mutex> in_call(callback_m_);  // a callback running now finishes first
  std::lock_guard<std::mutex> lk(m_);
  callback_ = std::move(cb);
}

void EditSession::requestIterations(int n) {
  if (n <= 0) return;
  {
    std::lock_guard<std::mutex> lk(m_);
    pending_ += n;
  }
  cv_.notify_all();
}

void EditSession::frameShown() {
  {
    std::lock_guard<std::mutex> lk(m_);
    frames_shown_ = frames_out_;
  }
  shown_cv_.notify_all();
}

void EditSession::waitIdle() {
  std::unique_lock<std::mutex> lk(m_);
  idle_cv_.wait(lk, [&] { return pending_ == 0 && !working_; });
}

bool EditSession::busy() const {
  std::lock_guard<std::mutex> lk(m_);
  return pending_ > 0 || working_;
}

Eigen::MatrixX3d EditSession::currentSurface() const {
  std::lock_guard<std::mutex> lk(m_);
  return surface_;
}

void EditSession::workerLoop() {
  // Leave a core to the UI thread: the view must keep rendering while this thread iterates
  // (OpenMP's and OpenBLAS's spinning workers would otherwise starve it on a small machine).
  omp_set_num_threads(std::max(1, int(std::thread::hardware_concurrency()) - 1));
  ScopedBlasThreads one_blas_thread(1);
  std::unique_ptr<TetDeformer> d;
  std::unique_ptr<LaplacianDeformer> lap;
  std::unique_ptr<DeformationTransfer> transfer;
  long transfer_for = -1;  // setup serial the transfer was precomputed for
  std::string applied_key;
  long applied_version = -1;
  for (;;) {
    Docs docs;
    long version = 0;
    bool changed = false;
    const TetJobSetup* s = nullptr;
    EditSolver solver = EditSolver::Tet;
    long version_of_setup = 0;
    {
      std::unique_lock<std::mutex> lk(m_);
      cv_.wait(lk, [&] { return stop_ || pending_ > 0; });
      if (stop_) return;
      working_ = true;
      version = version_;
      changed = version != applied_version;
      if (changed) docs = worker_docs_;
      s = setup_.get();
      solver = solver_;
      version_of_setup = setup_serial_;
    }
    EditFrame fr;
    bool stop_now = false;
    const auto t0 = std::chrono::steady_clock::now();
    try {
      if (s == nullptr) throw InvalidInput("no mesh is open");
      if (solver == EditSolver::Surface) {
        // one linear solve per change; the factorization is kept while only motions change
        if (docs.handles["handles"].empty()) {
          lap.reset();
          applied_key.clear();
          fr.surface = s->surface.V;
          fr.rebuilt = true;
        } else {
          const DeformJob job = parse_constraints_json(constraintsDocOf(docs), s->surface, "constraints");
          const std::string key = structure_key(docs.handles, docs.rigid, docs.stiffness) + (docs.rotation_field ? "|rf" : "") +
                                   "|" + std::to_string(version_of_setup);
          if (!lap || key != applied_key) {
            lap = std::make_unique<LaplacianDeformer>();
            if (job.weights) lap->setLaplacianWeights(*job.weights);
            lap->setMesh(s->surface);
            for (const auto& c : job.constraints) lap->addConstraint(c);
            lap->setUseRotationField(job.rotation_field.value_or(false));
            lap->setScale(job.scale);
            applied_key = key;
            fr.rebuilt = true;
          } else {
            for (std::size_t i = 0; i < job.constraints.size(); ++i) {
              lap->setPositionTarget(int(i), job.constraints[i].target);
              lap->setConstraintRotation(int(i), job.constraints[i].rotation);
            }
          }
          fr.surface = lap->deform();
          fr.iteration = ++iterations_;
        }
        applied_version = version;
        stop_now = true;
      } else if (changed) {
        if (docs.handles["handles"].empty()) {
          d.reset();  // nothing holds the shape: back to rest
          applied_key.clear();
          iterations_ = 0;
          stop_now = true;
          fr.surface = s->surface.V;
          fr.rebuilt = true;
        } else {
          const TetJob job = parseDocs(docs);
          const std::string key = structure_key(docs.handles, docs.rigid, docs.stiffness) + "|" + std::to_string(version_of_setup);
          if (!d || key != applied_key) {
            d = std::make_unique<TetDeformer>();
            d->setMesh(s->tets);
            d->setOptions(tet_job_options(job));
            TetJobFiles names;
            names.handles = "handles";
            names.rigid = "rigid";
            names.stiffness = "stiffness";
            apply_tet_job(*s, job, names, *d);
            applied_key = key;
            fr.rebuilt = true;
            iterations_ = 0;
          } else {
            for (std::size_t i = 0; i < job.handles.size(); ++i) d->setRegionMotion(int(i), job.handles[i].motion);
          }
        }
        applied_version = version;
      }
      if (solver == EditSolver::Surface) {
      } else if (d && !stop_now) {
        fr.e_nonrigid = d->iterate();
        fr.iteration = ++iterations_;
        if (s->from_tets || !s->decimated) {
          fr.surface = d->positions().topRows(s->surface.V.rows());
        } else {
          if (transfer_for != version_of_setup) {
            transfer = std::make_unique<DeformationTransfer>();
            transfer->precompute(s->tets, s->surface.V);
            transfer_for = version_of_setup;
          }
          fr.surface = transfer->apply(d->inputPositions());
        }
        const auto& mm = d->report().max_move;
        if (!mm.empty() && mm.back() < d->options().tolerance) stop_now = true;  // converged: nothing moves
      } else if (!d) {
        stop_now = true;
      }
    } catch (const std::exception& e) {
      fr.error = e.what();
      stop_now = true;
      d.reset();
      lap.reset();
      applied_key.clear();
    }
    fr.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    {
      std::lock_guard<std::mutex> lk(m_);
      if (fr.surface.rows() > 0) surface_ = fr.surface;
      // stop (converged, one surface solve done, an error) only if no edit came in meanwhile:
      // an edit made while this iteration ran still gets its iterations
      if (version_ != version) pending_ = std::max(pending_ - 1, 1);
      else pending_ = stop_now ? 0 : std::max(0, pending_ - 1);
      working_ = false;
    }
    idle_cv_.notify_all();
    if (fr.surface.rows() > 0 || !fr.error.empty()) {
      long out = 0;
      bool called = false;
      {
        std::lock_guard<std::mutex> in_call(callback_m_);
        FrameCallback cb;
        {
          std::lock_guard<std::mutex> lk(m_);
          cb = callback_;
          if (cb) out = ++frames_out_;
        }
        if (cb) {
          cb(fr);
          called = true;
        }
      }
      if (called && lockstep_) {
        std::unique_lock<std::mutex> lk(m_);
        shown_cv_.wait_for(lk, std::chrono::milliseconds(250), [&] { return stop_ || frames_shown_ >= out; });
      }
    }
  }
}

TriMesh EditSession::replay(int iterations) const {
  const auto& s = setup();
  TriMesh out = s.surface;
  if (docs_.handles["handles"].empty()) return out;
  if (solver_ == EditSolver::Surface) {  // the steps of `tbsp deform` (plugins/cli/deform_cmds.cpp)
    const DeformJob job = parse_constraints_json(constraintsDoc(), s.surface, "constraints");
    LaplacianDeformer lap;
    if (job.weights) lap.setLaplacianWeights(*job.weights);
    lap.setMesh(s.surface);
    for (const auto& c : job.constraints) lap.addConstraint(c);
    lap.setUseRotationField(job.rotation_field.value_or(false));
    lap.setScale(job.scale);
    out.V = lap.deform();
    out.N.resize(0, 3);
    return out;
  }
  // the steps of `tbsp tetdeform` (plugins/cli/tet_cmds.cpp), in the same order
  const TetJob job = parseDocs(docs_);
  TetDeformer d;
  d.setMesh(s.tets);
  d.setOptions(tet_job_options(job));
  TetJobFiles names;
  names.handles = "handles";
  names.rigid = "rigid";
  names.stiffness = "stiffness";
  apply_tet_job(s, job, names, d);
  d.deform(iterations);
  return deformed_surface(s, d);
}

void EditSession::save(const std::string& mesh_path, const std::string& handles_path, const std::string& rigid_path,
                       const std::string& stiffness_path, int iterations, const std::string& constraints_path) const {
  if (docs_.handles["handles"].empty()) throw InvalidInput("nothing to save: the edit has no handle yet");
  const TriMesh out = replay(iterations);
  nlohmann::json h = docs_.handles;
  h["iterations"] = iterations;
  write_text_file_atomic(handles_path, h.dump(2) + "\n");
  if (!rigid_path.empty() && !docs_.rigid.is_null()) write_text_file_atomic(rigid_path, docs_.rigid.dump(2) + "\n");
  if (!stiffness_path.empty() && !docs_.stiffness.is_null())
    write_text_file_atomic(stiffness_path, docs_.stiffness.dump(2) + "\n");
  if (!constraints_path.empty() && solver_ == EditSolver::Surface)
    write_text_file_atomic(constraints_path, constraintsDoc().dump(2) + "\n");
  write_mesh(mesh_path, out);
}

}  // namespace tbsp::studio
