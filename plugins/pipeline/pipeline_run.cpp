// run_pipeline: streams frames through a validated pipeline; staged outputs are renamed onto
// their targets only when every frame succeeded (pipeline.h). describe_stages: `tbsp plugins`.
#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <atomic>
#include <mutex>
#include <omp.h>
#include <sstream>
#include <thread>

#include "tbsp/core/logging.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/plugins/pipeline.h"

namespace fs = std::filesystem;

namespace tbsp::pipeline {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Files written during the run: temp path per target; committed (renamed) or removed. Shared by
// the worker threads.
class StagedOutputs {
public:
  explicit StagedOutputs(std::string dir) : dir_(std::move(dir)) {}
  ~StagedOutputs() { discard_staged(files_); }
  std::string stage(const std::string& target, const std::string& who) {
    std::lock_guard<std::mutex> lock(m_);
    if (auto it = owner_.find(target); it != owner_.end())
      throw InvalidInput("'" + target + "' was already written by " + it->second +
                         "; give the path a frame pattern such as %04d so that every frame has its own file");
    owner_[target] = who;
    const fs::path t(target);
    const fs::path folder = dir_.empty() ? t.parent_path() : fs::path(dir_);
    std::error_code ec;
    if (!folder.empty()) fs::create_directories(folder, ec);
    if (ec) throw FileError("'" + folder.string() + "': cannot create the output folder: " + ec.message());
    const std::string tmp = (folder / (".tbsp-run-" + std::to_string(::getpid()) + "-" + std::to_string(files_.size()) + "-" +
                                       t.filename().string())).string();
    files_.push_back({tmp, target});
    return tmp;
  }
  // Hands the staged list over (nothing is removed at destruction any more).
  std::vector<StagedFile> release() {
    std::lock_guard<std::mutex> lock(m_);
    std::vector<StagedFile> out;
    out.swap(files_);
    return out;
  }

private:
  std::string dir_;
  std::mutex m_;
  std::vector<StagedFile> files_;
  std::map<std::string, std::string> owner_;
};

// OpenBLAS's own thread pool is not safe for concurrent callers: with two frame workers
// factorizing at once (CHOLMOD -> BLAS), fit results changed from run to run; with BLAS on one
// thread per caller they are the bits of the one-worker run (measured, docs/pipelines.md). The
// frame workers therefore run BLAS single-threaded while they work. Looked up at run time: other
// BLAS libraries lack these symbols and are left alone.
class SingleThreadedBlas {
public:
  SingleThreadedBlas() {
    set_ = reinterpret_cast<void (*)(int)>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"));
    auto get = reinterpret_cast<int (*)()>(dlsym(RTLD_DEFAULT, "openblas_get_num_threads"));
    if (set_ && get) {
      saved_ = get();
      set_(1);
    } else {
      set_ = nullptr;
    }
  }
  ~SingleThreadedBlas() {
    if (set_) set_(saved_);
  }
  SingleThreadedBlas(const SingleThreadedBlas&) = delete;
  SingleThreadedBlas& operator=(const SingleThreadedBlas&) = delete;

private:
  void (*set_)(int) = nullptr;
  int saved_ = 1;
};

std::string where(const Pipeline& p, const Node& n) {
  return "node '" + n.id + "' (" + n.stage + ", " + p.file + ":" + std::to_string(n.line) + ")";
}

// Rethrows the current exception with the frame and node in front, keeping its kind.
[[noreturn]] void rethrow_with(const std::string& prefix) {
  try {
    throw;
  } catch (const Cancelled&) {
    throw;
  } catch (const FileError& e) {
    throw FileError(prefix + e.what());
  } catch (const InvalidInput& e) {
    throw InvalidInput(prefix + e.what());
  } catch (const NumericalFailure& e) {
    throw NumericalFailure(prefix + e.what());
  } catch (const std::exception& e) {
    throw Error(prefix + e.what());
  }
}

std::vector<std::unique_ptr<Stage>> make_stages(const Pipeline& p, const Registry& reg) {
  std::vector<std::unique_ptr<Stage>> stages;
  for (const auto& n : p.nodes) {
    try {
      stages.push_back(reg.create(n.stage, n.params));
    } catch (...) {
      rethrow_with(where(p, n) + ": ");
    }
  }
  return stages;
}

std::vector<std::string> stateful(const Pipeline& p, const Registry& reg, const std::vector<std::unique_ptr<Stage>>& stages) {
  std::vector<std::string> ids;
  for (std::size_t i = 0; i < p.nodes.size(); ++i)
    if (reg.find(p.nodes[i].stage)->frame_ordered && stages[i]->keeps_state()) ids.push_back(p.nodes[i].id);
  return ids;
}

// The nodes this frame has to run: every node whose outputs nobody reads (sinks and ends), and
// every node that a needed node reads from through a port it needs now (Stage::needs_input).
// Nodes are in dependency order, so one backward pass decides each node after its readers.
std::vector<bool> needed_nodes(const Pipeline& p, const std::vector<std::unique_ptr<Stage>>& stages) {
  std::map<std::string, std::size_t> index;
  for (std::size_t i = 0; i < p.nodes.size(); ++i) index[p.nodes[i].id] = i;
  std::vector<bool> read(p.nodes.size(), false), needed(p.nodes.size(), false);
  for (const auto& n : p.nodes)
    for (const auto& kv : n.inputs) read[index.at(kv.second.first)] = true;
  for (std::size_t i = p.nodes.size(); i-- > 0;) {
    if (!read[i]) needed[i] = true;
    if (!needed[i]) continue;
    for (const auto& [port, ref] : p.nodes[i].inputs)
      if (stages[i]->needs_input(port)) needed[index.at(ref.first)] = true;
  }
  return needed;
}

// Runs one frame through every node it needs.
FrameReport run_frame(const Pipeline& p, const Registry& reg, std::vector<std::unique_ptr<Stage>>& stages, int frame,
                      const ProgressCallback& progress, StagedOutputs& staged) {
  const auto tf = Clock::now();
  FrameReport fr;
  fr.frame = frame;
  std::map<std::string, Ports> values;  // node id -> its outputs for this frame
  const std::vector<bool> needed = needed_nodes(p, stages);
  for (std::size_t i = 0; i < p.nodes.size(); ++i) {
    const Node& n = p.nodes[i];
    if (!needed[i]) continue;
    const std::string prefix = "frame " + std::to_string(frame) + ", " + where(p, n) + ": ";
    FrameContext ctx;
    ctx.frame = frame;
    ctx.node = n.id;
    ctx.progress = [&progress, &n, frame](double f, const std::string& what) {
      return !progress || progress(std::clamp(f, 0.0, 1.0), "frame " + std::to_string(frame) + " " + n.id + ": " + what);
    };
    ctx.stage_output = [&staged, prefix](const std::string& target) { return staged.stage(target, prefix.substr(0, prefix.size() - 2)); };
    Ports in;
    for (const auto& [port, ref] : n.inputs)
      if (stages[i]->needs_input(port)) in[port] = values.at(ref.first).at(ref.second);
    const auto ts = Clock::now();
    try {
      report_progress(ctx.progress, 0.0, "start");
      Ports out = stages[i]->process(ctx, in);
      const StageInfo& info = *reg.find(n.stage);
      for (const auto& o : info.outputs) {
        auto it = out.find(o.name);
        if (it == out.end() || it->second.type != o.type || (o.type == DataType::Cloud ? !it->second.cloud : !it->second.mesh))
          throw Error("the stage did not produce its output '" + o.name + "' (" + to_string(o.type) + "): a bug in plugin " + info.plugin);
      }
      values[n.id] = std::move(out);
    } catch (...) {
      rethrow_with(prefix);
    }
    fr.node_seconds[n.id] = since(ts);
    if (!ctx.numbers.empty()) fr.numbers[n.id] = ctx.numbers;
  }
  fr.seconds = since(tf);
  logger()->debug("pipeline {}: frame {} done in {:.3f} s", p.file, frame, fr.seconds);
  return fr;
}

}  // namespace

RunReport run_pipeline(const Pipeline& p, const Registry& reg, const RunOptions& opt) {
  const auto t0 = Clock::now();
  if (opt.ranks < 1 || opt.rank < 0 || opt.rank >= opt.ranks) throw InvalidInput("run_pipeline: rank must be in [0, ranks)");
  std::vector<std::unique_ptr<Stage>> stages = make_stages(p, reg);
  // Frames: intersection of the frame sources' lists, within the range.
  const int first = opt.first >= 0 ? opt.first : p.first, last = opt.last >= 0 ? opt.last : p.last;
  std::vector<int> frames;
  bool have_source = false;
  for (std::size_t i = 0; i < p.nodes.size(); ++i) {
    std::vector<int> f;
    try {
      f = stages[i]->frames();
    } catch (...) {
      rethrow_with(where(p, p.nodes[i]) + ": ");
    }
    if (f.empty()) continue;
    std::sort(f.begin(), f.end());
    if (!have_source) {
      frames = f;
      have_source = true;
    } else {
      std::vector<int> both;
      std::set_intersection(frames.begin(), frames.end(), f.begin(), f.end(), std::back_inserter(both));
      frames.swap(both);
    }
  }
  if (!have_source) frames = {0};
  frames.erase(std::remove_if(frames.begin(), frames.end(), [&](int f) { return (first >= 0 && f < first) || (last >= 0 && f > last); }),
               frames.end());
  if (frames.empty())
    throw InvalidInput(p.file + ": no frame to run: the frame sources share no frame number in the range " + std::to_string(first) + ":" +
                       std::to_string(last) + " (check 'frames:' and --frames)");

  // This process's share, and the worker threads.
  const std::vector<std::string> ordered = stateful(p, reg, stages);
  std::string ordered_list;
  for (const auto& id : ordered) ordered_list += (ordered_list.empty() ? "'" : ", '") + id + "'";
  if (opt.ranks > 1 && !ordered.empty())
    throw InvalidInput(p.file + ": node " + ordered_list + " keeps state from frame to frame (e.g. fit with warm_start), so the frames "
                       "cannot be split over " + std::to_string(opt.ranks) + " MPI ranks: run it without mpirun, or set warm_start: false");
  std::vector<int> mine;
  for (std::size_t k = 0; k < frames.size(); ++k)
    if (int(k % std::size_t(opt.ranks)) == opt.rank) mine.push_back(frames[k]);
  int threads = opt.threads;
  if (threads == 0) threads = ordered.empty() ? int(std::max(1u, std::thread::hardware_concurrency())) : 1;
  if (threads > 1 && !ordered.empty())
    throw InvalidInput(p.file + ": node " + ordered_list + " keeps state from frame to frame, so its frames cannot run on " +
                       std::to_string(threads) + " threads: use one thread (the stages still use every core)");
  threads = std::max(1, std::min<int>(threads, int(mine.size())));

  StagedOutputs staged(opt.stage_dir);
  RunReport report;
  report.threads = threads;
  std::mutex m;
  std::size_t done = 0;
  auto progress_of = [&](double f, const std::string& what) {
    if (!opt.progress) return true;
    std::lock_guard<std::mutex> lock(m);
    return opt.progress((double(done) + f) / double(std::max<std::size_t>(1, mine.size())), what);
  };
  if (threads == 1) {
    for (int frame : mine) {
      FrameReport fr = run_frame(p, reg, stages, frame, progress_of, staged);
      report.frames.push_back(std::move(fr));
      ++done;
      report_progress(opt.progress, double(done) / double(mine.size()), "frame " + std::to_string(frame) + " done");
    }
  } else {
    // Worker t runs mine[t], mine[t + threads], ... with its own stage objects (worker 0 reuses
    // the ones made above); the first error stops the others at their next stage.
    std::vector<std::vector<FrameReport>> per(static_cast<std::size_t>(threads));
    std::vector<std::exception_ptr> errors(static_cast<std::size_t>(threads));
    std::atomic<bool> stop{false};
    const int omp_each = std::max(1, omp_get_max_threads() / threads);
    auto work = [&](int t, std::vector<std::unique_ptr<Stage>>* own) {
      omp_set_num_threads(omp_each);  // this thread's OpenMP regions only
      try {
        std::vector<std::unique_ptr<Stage>> made;
        if (!own) {
          made = make_stages(p, reg);
          own = &made;
        }
        auto prog = [&](double f, const std::string& what) {
          if (stop.load()) return false;
          return progress_of(f / double(threads), what);
        };
        for (std::size_t k = std::size_t(t); k < mine.size(); k += std::size_t(threads)) {
          per[std::size_t(t)].push_back(run_frame(p, reg, *own, mine[k], prog, staged));
          std::lock_guard<std::mutex> lock(m);
          ++done;
        }
      } catch (...) {
        errors[std::size_t(t)] = std::current_exception();
        stop = true;
      }
    };
    SingleThreadedBlas blas_guard;
    std::vector<std::thread> pool;
    for (int t = 1; t < threads; ++t) pool.emplace_back(work, t, nullptr);
    work(0, &stages);
    for (auto& th : pool) th.join();
    const std::exception_ptr first_error = first_real_error(errors);
    if (first_error) {
      discard_staged(staged.release());
      std::rethrow_exception(first_error);
    }
    for (auto& v : per)
      for (auto& f : v) report.frames.push_back(std::move(f));
    std::sort(report.frames.begin(), report.frames.end(), [](const FrameReport& a, const FrameReport& b) { return a.frame < b.frame; });
  }
  report.seconds = since(t0);
  if (!opt.commit) {
    report.staged = staged.release();
    return report;
  }
  if (!p.report.empty()) {
    const std::string tmp = staged.stage(p.report, "the run report");
    AtomicFile out(tmp);
    out.stream() << run_report_json(p, report);
    out.commit();
  }
  report.outputs = commit_staged(staged.release());
  return report;
}

std::string run_report_json(const Pipeline& p, const RunReport& report) {
  nlohmann::json j;
  j["pipeline"] = p.file;
  j["frames"] = nlohmann::json::array();
  std::vector<const FrameReport*> sorted;
  for (const auto& f : report.frames) sorted.push_back(&f);
  std::sort(sorted.begin(), sorted.end(), [](const FrameReport* a, const FrameReport* b) { return a->frame < b->frame; });
  for (const FrameReport* f : sorted) {
    nlohmann::json jf{{"frame", f->frame}, {"seconds", f->seconds}, {"node_seconds", f->node_seconds}};
    if (!f->numbers.empty()) jf["numbers"] = f->numbers;
    j["frames"].push_back(jf);
  }
  j["seconds"] = report.seconds;
  j["threads"] = report.threads;
  return j.dump(2) + "\n";
}

std::vector<std::string> commit_staged(const std::vector<StagedFile>& files) {
  std::vector<std::string> out;
  for (const auto& f : files) {
    std::error_code ec;
    if (!fs::exists(f.temp, ec)) continue;  // a sink that decided not to write
    fs::rename(f.temp, f.target, ec);
    if (ec) {  // another file system (a private staging folder): copy, then rename in place
      const std::string near = f.target + ".tbsp-tmp-" + std::to_string(::getpid());
      std::error_code ec2;
      fs::copy_file(f.temp, near, fs::copy_options::overwrite_existing, ec2);
      if (!ec2) fs::rename(near, f.target, ec2);
      if (ec2) {
        fs::remove(near, ec);
        throw FileError("'" + f.target + "': cannot move the finished output into place: " + ec2.message());
      }
      fs::remove(f.temp, ec);
    }
    out.push_back(f.target);
  }
  return out;
}

void discard_staged(const std::vector<StagedFile>& files) {
  for (const auto& f : files) {
    std::error_code ec;
    fs::remove(f.temp, ec);
  }
}

std::string describe_stages(const Registry& reg, bool md) {
  std::ostringstream os;
  auto num = [](double v) {
    if (std::isinf(v)) return std::string(v < 0 ? "-inf" : "inf");
    std::ostringstream s;
    s << v;
    return s.str();
  };
  for (const StageInfo* s : reg.stages()) {
    if (md) {
      os << "## `" << s->name << "`\n\n" << s->summary << "\n\n";
      os << "Plugin: `" << s->plugin << "`" << (s->frame_ordered ? "; keeps state from frame to frame (frames run in order)" : "") << ".\n\n";
      auto ports = [&](const char* title, const std::vector<PortSpec>& v) {
        if (v.empty()) return;
        os << title << ": ";
        for (std::size_t i = 0; i < v.size(); ++i)
          os << (i ? ", " : "") << "`" << v[i].name << "` (" << to_string(v[i].type) << (v[i].optional ? ", optional" : "") << ": " << v[i].doc << ")";
        os << ".\n\n";
      };
      ports("Inputs", s->inputs);
      ports("Outputs", s->outputs);
      if (!s->params.empty()) {
        os << "| parameter | type | default | range | meaning |\n|---|---|---|---|---|\n";
        for (const auto& q : s->params) {
          std::string range;
          if (q.type == ParamType::Int || q.type == ParamType::Real) range = "[" + num(q.min) + ", " + num(q.max) + "]";
          if (!q.choices.empty()) {
            for (const auto& c : q.choices) range += (range.empty() ? "" : ", ") + c;
          }
          os << "| `" << q.name << "` | " << to_string(q.type) << " | " << (q.required ? "required" : q.default_value.empty() ? "—" : "`" + q.default_value + "`")
             << " | " << range << " | " << q.doc << " |\n";
        }
        os << "\n";
      }
    } else {
      os << s->name << "  [" << s->plugin << "]\n  " << s->summary << "\n";
      for (const auto& i : s->inputs) os << "  in  " << i.name << " (" << to_string(i.type) << (i.optional ? ", optional" : "") << ")  " << i.doc << "\n";
      for (const auto& o : s->outputs) os << "  out " << o.name << " (" << to_string(o.type) << ")  " << o.doc << "\n";
      for (const auto& q : s->params) {
        os << "  " << q.name << " (" << to_string(q.type);
        if (q.required) os << ", required";
        else if (!q.default_value.empty()) os << ", default " << q.default_value;
        if (q.type == ParamType::Int || q.type == ParamType::Real) os << ", " << "[" << num(q.min) << ", " << num(q.max) << "]";
        for (std::size_t c = 0; c < q.choices.size(); ++c) os << (c ? "|" : ", one of ") << q.choices[c];
        os << ")  " << q.doc << "\n";
      }
      os << "\n";
    }
  }
  return os.str();
}

}  // namespace tbsp::pipeline
