// run_pipeline: streams frames through a validated pipeline; staged outputs are renamed onto
// their targets only when every frame succeeded (pipeline.h). describe_stages: `tbsp plugins`.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>

#include "tbsp/core/logging.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/plugins/pipeline.h"

namespace fs = std::filesystem;

namespace tbsp::pipeline {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Files written during the run: temp path per target; committed (renamed) or removed.
class StagedOutputs {
public:
  ~StagedOutputs() { discard(); }
  std::string stage(const std::string& target, const std::string& who) {
    if (auto it = owner_.find(target); it != owner_.end())
      throw InvalidInput(who + " writes '" + target + "' again (already written by " + it->second +
                         "); give the path a frame pattern such as %04d so that every frame has its own file");
    owner_[target] = who;
    const fs::path t(target);
    std::error_code ec;
    if (!t.parent_path().empty()) fs::create_directories(t.parent_path(), ec);
    if (ec) throw FileError("'" + t.parent_path().string() + "': cannot create the output folder: " + ec.message());
    const std::string tmp = (t.parent_path() / (".tbsp-run-" + std::to_string(::getpid()) + "-" + std::to_string(files_.size()) + "-" +
                                                t.filename().string())).string();
    files_.push_back({tmp, target});
    return tmp;
  }
  std::vector<std::string> commit() {
    std::vector<std::string> out;
    for (const auto& [tmp, target] : files_) {
      std::error_code ec;
      if (!fs::exists(tmp, ec)) continue;  // a sink that decided not to write
      fs::rename(tmp, target, ec);
      if (ec) throw FileError("'" + target + "': cannot move the finished output into place: " + ec.message());
      out.push_back(target);
    }
    files_.clear();
    return out;
  }
  void discard() {
    for (const auto& f : files_) {
      std::error_code ec;
      fs::remove(f.first, ec);
    }
    files_.clear();
  }

private:
  std::vector<std::pair<std::string, std::string>> files_;
  std::map<std::string, std::string> owner_;
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

}  // namespace

RunReport run_pipeline(const Pipeline& p, const Registry& reg, const RunOptions& opt) {
  const auto t0 = Clock::now();
  // One stage object per node.
  std::vector<std::unique_ptr<Stage>> stages;
  for (const auto& n : p.nodes) {
    try {
      stages.push_back(reg.create(n.stage, n.params));
    } catch (...) {
      rethrow_with(where(p, n) + ": ");
    }
  }
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

  StagedOutputs staged;
  RunReport report;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const int frame = frames[k];
    const auto tf = Clock::now();
    FrameReport fr;
    fr.frame = frame;
    std::map<std::string, Ports> values;  // node id -> its outputs for this frame
    for (std::size_t i = 0; i < p.nodes.size(); ++i) {
      const Node& n = p.nodes[i];
      const std::string prefix = "frame " + std::to_string(frame) + ", " + where(p, n) + ": ";
      FrameContext ctx;
      ctx.frame = frame;
      ctx.node = n.id;
      const double base = double(k) / double(frames.size()), span = 1.0 / double(frames.size());
      ctx.progress = [&, base, span](double f, const std::string& what) {
        return !opt.progress || opt.progress(base + span * std::clamp(f, 0.0, 1.0), "frame " + std::to_string(frame) + " " + n.id + ": " + what);
      };
      ctx.stage_output = [&staged, prefix](const std::string& target) { return staged.stage(target, prefix.substr(0, prefix.size() - 2)); };
      Ports in;
      for (const auto& [port, ref] : n.inputs) in[port] = values.at(ref.first).at(ref.second);
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
        rethrow_with(prefix);  // `staged` removes every temporary file on the way out
      }
      fr.node_seconds[n.id] = since(ts);
      if (!ctx.numbers.empty()) fr.numbers[n.id] = ctx.numbers;
    }
    fr.seconds = since(tf);
    logger()->debug("pipeline {}: frame {} done in {:.3f} s", p.file, frame, fr.seconds);
    report.frames.push_back(std::move(fr));
    report_progress(opt.progress, double(k + 1) / double(frames.size()), "frame " + std::to_string(frame) + " done");
  }
  report.seconds = since(t0);
  if (!p.report.empty()) {
    nlohmann::json j;
    j["pipeline"] = p.file;
    j["frames"] = nlohmann::json::array();
    for (const auto& f : report.frames) {
      nlohmann::json jf{{"frame", f.frame}, {"seconds", f.seconds}, {"node_seconds", f.node_seconds}};
      if (!f.numbers.empty()) jf["numbers"] = f.numbers;
      j["frames"].push_back(jf);
    }
    j["seconds"] = report.seconds;
    const std::string tmp = staged.stage(p.report, "the run report");
    AtomicFile out(tmp);
    out.stream() << j.dump(2) << "\n";
    out.commit();
  }
  report.outputs = staged.commit();
  return report;
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
