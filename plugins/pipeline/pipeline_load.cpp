// parse_pipeline / load_pipeline: YAML -> validated Pipeline. Every check that can be made before
// a frame is read is made here, each failure naming the line and the fix (pipeline.h).
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "tbsp/io/studio.h"
#include "tbsp/plugins/pipeline.h"

namespace fs = std::filesystem;

namespace tbsp::pipeline {
namespace {

struct PipelineCtx {
  std::string file, base;
  [[noreturn]] void fail(const YAML::Node& n, const std::string& msg) const { throw PipelineError(file, line(n), msg); }
  static int line(const YAML::Node& n) { return n.Mark().line >= 0 ? n.Mark().line + 1 : 0; }
  std::string resolve(const std::string& p) const {
    if (p.empty() || fs::path(p).is_absolute()) return p;
    return (fs::path(base) / p).lexically_normal().string();
  }
};

// Levenshtein distance, for "did you mean" hints.
std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diag = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}
std::string did_you_mean(const std::string& s, const std::vector<std::string>& options) {
  std::string best;
  std::size_t bd = 3;  // at most two edits away
  for (const auto& o : options) {
    const std::size_t d = edit_distance(s, o);
    if (d < bd) { bd = d; best = o; }
  }
  return best.empty() ? std::string() : " (did you mean '" + best + "'?)";
}
std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : ", ") + x;
  return s;
}

void check_keys(const PipelineCtx& c, const YAML::Node& map, const std::vector<std::string>& allowed, const std::string& where) {
  for (const auto& kv : map) {
    const std::string k = kv.first.Scalar();
    if (std::find(allowed.begin(), allowed.end(), k) == allowed.end())
      c.fail(kv.first, "unknown key '" + k + "' in " + where + did_you_mean(k, allowed) + "; allowed: " + join(allowed));
  }
}

std::string scalar(const PipelineCtx& c, const YAML::Node& n, const std::string& what) {
  if (!n.IsScalar()) c.fail(n, what + " must be a single value, not a " + (n.IsMap() ? "map" : n.IsSequence() ? "list" : "null"));
  return n.Scalar();
}

// Converts one written value (file or default) to the parameter's type, checking range/choices.
// `where` is the node to blame (nullptr: a default, i.e. a bug in the plugin).
Params::Value convert(const PipelineCtx& c, const ParamSpec& p, const std::string& text, const YAML::Node* where,
                      const std::string& stage) {
  auto bad = [&](const std::string& why) -> Params::Value {
    const std::string msg = "parameter '" + p.name + "' of stage '" + stage + "': " + why;
    if (where) c.fail(*where, msg);
    throw InvalidInput("stage plugin bug: default of " + msg);
  };
  auto range = [&](double v) {
    if (v < p.min || v > p.max) {
      std::ostringstream os;
      os << "value " << text << " is outside [" << p.min << ", " << p.max << "]";
      bad(os.str());
    }
  };
  switch (p.type) {
    case ParamType::Bool: {
      std::string t = text;
      std::transform(t.begin(), t.end(), t.begin(), [](unsigned char ch) { return char(std::tolower(ch)); });
      if (t == "true" || t == "yes" || t == "on") return true;
      if (t == "false" || t == "no" || t == "off") return false;
      return bad("'" + text + "' is not a bool (write true or false)");
    }
    case ParamType::Int: {
      std::size_t used = 0;
      long long v = 0;
      try { v = std::stoll(text, &used); } catch (const std::exception&) { used = 0; }
      if (used == 0 || used != text.size()) return bad("'" + text + "' is not an integer");
      range(double(v));
      return v;
    }
    case ParamType::Real: {
      std::size_t used = 0;
      double v = 0;
      try { v = std::stod(text, &used); } catch (const std::exception&) { used = 0; }
      if (used == 0 || used != text.size() || !std::isfinite(v)) return bad("'" + text + "' is not a finite number");
      range(v);
      return v;
    }
    case ParamType::Text:
      if (!p.choices.empty() && std::find(p.choices.begin(), p.choices.end(), text) == p.choices.end())
        return bad("'" + text + "' is not one of " + join(p.choices) + did_you_mean(text, p.choices));
      return text;
    case ParamType::InputPath: {
      const std::string r = c.resolve(text);
      if (r.find('%') == std::string::npos) {
        std::error_code ec;
        if (!fs::exists(r, ec)) return bad("input '" + r + "' does not exist (paths are relative to the pipeline file's folder)");
      }
      return r;
    }
    case ParamType::OutputPath: {
      const std::string r = c.resolve(text);
      if (r.find('%') != std::string::npos) {
        try { expand_frame_pattern(r, 0); } catch (const InvalidInput& e) { return bad(e.what()); }
      }
      const fs::path dir = fs::path(r).parent_path();
      std::error_code ec;
      if (!dir.empty() && fs::exists(dir, ec) && !fs::is_directory(dir, ec))
        return bad("'" + dir.string() + "' is a file, not a folder");
      return r;
    }
  }
  return bad("unknown parameter type");
}

Params read_params(const PipelineCtx& c, const StageInfo& info, const YAML::Node& node, const YAML::Node& at) {
  Params out;
  std::vector<std::string> names;
  for (const auto& p : info.params) names.push_back(p.name);
  if (node && !node.IsNull() && !node.IsMap()) c.fail(node, "'params' of stage '" + info.name + "' must be a map name: value");
  if (node && node.IsMap())
    for (const auto& kv : node) {
      const std::string k = kv.first.Scalar();
      if (std::find(names.begin(), names.end(), k) == names.end())
        c.fail(kv.first, "stage '" + info.name + "' has no parameter '" + k + "'" + did_you_mean(k, names) + "; its parameters: " +
                             (names.empty() ? "none" : join(names)) + " (`tbsp plugins` documents them)");
    }
  for (const auto& p : info.params) {
    const YAML::Node v = node && node.IsMap() ? node[p.name] : YAML::Node();
    if (v && !v.IsNull()) {
      out.set(p.name, convert(c, p, scalar(c, v, "parameter '" + p.name + "'"), &v, info.name));
    } else if (!p.default_value.empty()) {
      out.set(p.name, convert(c, p, p.default_value, nullptr, info.name));
    } else if (p.required) {
      c.fail(at, "stage '" + info.name + "' needs parameter '" + p.name + "' (" + to_string(p.type) + ": " + p.doc + ")");
    }
  }
  return out;
}

// "node" or "node.port" -> (node, port); the port is resolved later against the node's outputs.
std::pair<std::string, std::string> split_ref(const std::string& r) {
  const std::size_t dot = r.rfind('.');
  if (dot == std::string::npos) return {r, ""};
  return {r.substr(0, dot), r.substr(dot + 1)};
}

struct Raw {
  Node node;
  std::map<std::string, int> input_lines;  // port -> line of the reference
};

}  // namespace

Pipeline parse_pipeline(const std::string& text, const std::string& base_dir, const std::string& file, const Registry& reg) {
  PipelineCtx c{file, base_dir};
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw PipelineError(file, e.mark.line >= 0 ? e.mark.line + 1 : 0, "YAML syntax: " + e.msg + " (check indentation and ':' after keys)");
  }
  if (!root.IsMap()) c.fail(root, "a pipeline file is a map with a 'stages:' list (docs/pipelines.md)");
  check_keys(c, root, {"stages", "frames", "report"}, "the pipeline");
  Pipeline out;
  out.file = file;
  if (const YAML::Node f = root["frames"]) {
    const std::string s = scalar(c, f, "'frames'");
    const std::size_t colon = s.find(':');
    try {
      std::size_t u1 = 0, u2 = 0;
      if (colon == std::string::npos) {
        out.first = out.last = std::stoi(s, &u1);
        if (u1 != s.size()) throw std::invalid_argument("trailing");
      } else {
        const std::string a = s.substr(0, colon), b = s.substr(colon + 1);
        if (!a.empty()) { out.first = std::stoi(a, &u1); if (u1 != a.size()) throw std::invalid_argument("a"); }
        if (!b.empty()) { out.last = std::stoi(b, &u2); if (u2 != b.size()) throw std::invalid_argument("b"); }
      }
    } catch (const std::exception&) {
      c.fail(f, "'frames: " + s + "' is not a frame range; write first:last (inclusive), first:, :last or one frame number");
    }
    if (out.first < -1 || out.last < -1 || (out.first >= 0 && out.last >= 0 && out.last < out.first))
      c.fail(f, "'frames: " + s + "' is empty or negative; write first:last with 0 <= first <= last");
  }
  if (const YAML::Node r = root["report"]) out.report = c.resolve(scalar(c, r, "'report'"));

  const YAML::Node stages = root["stages"];
  if (!stages || !stages.IsSequence() || stages.size() == 0)
    c.fail(stages ? stages : root, "'stages:' must be a non-empty list of '- id: NAME, stage: STAGE' entries");

  std::vector<Raw> raw;
  std::map<std::string, std::size_t> by_id;
  std::vector<std::string> stage_names;
  for (const auto* s : reg.stages()) stage_names.push_back(s->name);
  for (const auto& sn : stages) {
    if (!sn.IsMap()) c.fail(sn, "each entry of 'stages' is a map with 'id', 'stage', 'params' and 'input'/'inputs'");
    check_keys(c, sn, {"id", "stage", "params", "input", "inputs"}, "a stage entry");
    Raw r;
    r.node.line = PipelineCtx::line(sn);
    if (!sn["stage"]) c.fail(sn, "stage entry without 'stage:' (the stage to run; `tbsp plugins` lists them)");
    r.node.stage = scalar(c, sn["stage"], "'stage'");
    const StageInfo* info = reg.find(r.node.stage);
    if (!info)
      c.fail(sn["stage"], "unknown stage '" + r.node.stage + "'" + did_you_mean(r.node.stage, stage_names) +
                              "; `tbsp plugins` lists the stages (plugins are searched in $TBSP_PLUGIN_PATH)");
    r.node.id = sn["id"] ? scalar(c, sn["id"], "'id'") : r.node.stage;
    if (r.node.id.empty() || r.node.id.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-") != std::string::npos)
      c.fail(sn["id"] ? sn["id"] : sn, "id '" + r.node.id + "' may only hold letters, digits, '_' and '-' (give each stage an 'id:')");
    if (by_id.count(r.node.id))
      c.fail(sn["id"] ? sn["id"] : sn, "id '" + r.node.id + "' is used twice (first on line " + std::to_string(raw[by_id[r.node.id]].node.line) +
                                           "); give each stage its own 'id:'");
    r.node.params = read_params(c, *info, sn["params"], sn);
    // connections
    if (sn["input"] && sn["inputs"]) c.fail(sn, "write either 'input: NODE' (one input) or 'inputs: {port: NODE}', not both");
    if (const YAML::Node in = sn["input"]) {
      const std::string ref = scalar(c, in, "'input'");
      const auto required = std::count_if(info->inputs.begin(), info->inputs.end(), [](const PortSpec& p) { return !p.optional; });
      if (info->inputs.empty()) c.fail(in, "stage '" + info->name + "' takes no input");
      if (required > 1) {
        std::vector<std::string> ports;
        for (const auto& p : info->inputs) ports.push_back(p.name);
        c.fail(in, "stage '" + info->name + "' has several inputs (" + join(ports) + "): write 'inputs: {PORT: NODE, ...}'");
      }
      auto target = std::find_if(info->inputs.begin(), info->inputs.end(), [](const PortSpec& p) { return !p.optional; });
      if (target == info->inputs.end()) target = info->inputs.begin();
      r.node.inputs[target->name] = split_ref(ref);
      r.input_lines[target->name] = PipelineCtx::line(in);
    }
    if (const YAML::Node in = sn["inputs"]) {
      if (!in.IsMap()) c.fail(in, "'inputs' must be a map PORT: NODE (or NODE.PORT)");
      std::vector<std::string> ports;
      for (const auto& p : info->inputs) ports.push_back(p.name);
      for (const auto& kv : in) {
        const std::string port = kv.first.Scalar();
        if (std::find(ports.begin(), ports.end(), port) == ports.end())
          c.fail(kv.first, "stage '" + info->name + "' has no input '" + port + "'" + did_you_mean(port, ports) + "; its inputs: " +
                               (ports.empty() ? "none" : join(ports)));
        r.node.inputs[port] = split_ref(scalar(c, kv.second, "input '" + port + "'"));
        r.input_lines[port] = PipelineCtx::line(kv.second);
      }
    }
    for (const auto& p : info->inputs)
      if (!p.optional && !r.node.inputs.count(p.name))
        c.fail(sn, "stage '" + info->name + "' needs its input '" + p.name + "' (" + to_string(p.type) + ") connected: add 'inputs: {" +
                       p.name + ": NODE}'");
    by_id[r.node.id] = raw.size();
    raw.push_back(std::move(r));
  }

  // Resolve references and check types.
  std::vector<std::string> ids;
  for (const auto& r : raw) ids.push_back(r.node.id);
  for (auto& r : raw) {
    const StageInfo& info = *reg.find(r.node.stage);
    for (auto& [port, ref] : r.node.inputs) {
      const int line = r.input_lines[port];
      auto it = by_id.find(ref.first);
      if (it == by_id.end())
        throw PipelineError(file, line, "input '" + port + "' of '" + r.node.id + "' names no stage id '" + ref.first + "'" +
                                            did_you_mean(ref.first, ids) + "; ids in this file: " + join(ids));
      const StageInfo& src = *reg.find(raw[it->second].node.stage);
      if (src.outputs.empty()) throw PipelineError(file, line, "stage '" + ref.first + "' (" + src.name + ") has no output to connect");
      const PortSpec* out = nullptr;
      if (ref.second.empty()) {  // NODE alone: its first (main) output
        out = &src.outputs.front();
        ref.second = out->name;
      } else {
        for (const auto& o : src.outputs)
          if (o.name == ref.second) out = &o;
        if (!out) {
          std::vector<std::string> names;
          for (const auto& o : src.outputs) names.push_back(o.name);
          throw PipelineError(file, line, "'" + ref.first + "' (" + src.name + ") has no output '" + ref.second + "'; its outputs: " + join(names));
        }
      }
      const std::string& port_name = port;  // (C++17: lambdas cannot capture structured bindings)
      const PortSpec& in = *std::find_if(info.inputs.begin(), info.inputs.end(), [&](const PortSpec& p) { return p.name == port_name; });
      if (in.type != out->type)
        throw PipelineError(file, line, "type mismatch: input '" + port + "' of '" + r.node.id + "' (" + info.name + ") takes a " +
                                            to_string(in.type) + ", but '" + ref.first + "." + out->name + "' gives a " + to_string(out->type) +
                                            (in.type == DataType::Mesh ? "" : " (convert with a stage that outputs a cloud)"));
    }
  }

  // Topological order (Kahn, in file order among ready nodes); what is left is a cycle.
  const std::size_t n = raw.size();
  std::vector<int> indeg(n, 0);
  std::vector<std::vector<std::size_t>> users(n);
  for (std::size_t i = 0; i < n; ++i)
    for (const auto& [port, ref] : raw[i].node.inputs) {
      ++indeg[i];
      users[by_id[ref.first]].push_back(i);
    }
  std::vector<char> done(n, 0);
  for (std::size_t k = 0; k < n; ++k) {
    std::size_t pick = n;
    for (std::size_t i = 0; i < n && pick == n; ++i)
      if (!done[i] && indeg[i] == 0) pick = i;
    if (pick == n) {
      std::string cyc;
      std::size_t first = n;
      for (std::size_t i = 0; i < n; ++i)
        if (!done[i]) { cyc += (cyc.empty() ? "" : ", ") + raw[i].node.id; if (first == n) first = i; }
      throw PipelineError(file, raw[first].node.line, "the stages " + cyc + " feed each other in a cycle; a pipeline must flow one way");
    }
    done[pick] = 1;
    for (std::size_t u : users[pick]) --indeg[u];
    out.nodes.push_back(raw[pick].node);
  }
  return out;
}

Pipeline load_pipeline(const std::string& path, const Registry& registry) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw FileError("'" + path + "': cannot open the pipeline file");
  std::ostringstream ss;
  ss << in.rdbuf();
  const fs::path dir = fs::absolute(fs::path(path)).parent_path();
  return parse_pipeline(ss.str(), dir.string(), path, registry);
}

}  // namespace tbsp::pipeline
