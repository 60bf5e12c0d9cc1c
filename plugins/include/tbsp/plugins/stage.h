#pragma once
/// \file stage.h
/// \brief The stage plugin interface of tbsp pipelines (docs/plugins.md, docs/pipelines.md).
///
/// A *stage* is one step of a pipeline: it declares typed parameters and typed input/output
/// ports (StageInfo), and a StageFactory makes one Stage object per pipeline node from validated
/// parameters. The pipeline runner hands frames to the stages one at a time in dependency order.
///
/// A *plugin* is a shared library that registers stage factories with TBSP_STAGE_PLUGIN; the
/// built-in stages (readers, PCL filters, template fitting, writers) ship as such a plugin too.
/// Everything a plugin needs from this header is inline, so a plugin compiled against the
/// installed headers does not depend on how the host program was linked.
///
/// \code
/// class Scale : public tbsp::pipeline::Stage {
///  public:
///   explicit Scale(double s) : s_(s) {}
///   tbsp::pipeline::Ports process(tbsp::pipeline::FrameContext&, const tbsp::pipeline::Ports& in) override {
///     auto m = std::make_shared<tbsp::TriMesh>(*in.at("mesh").mesh);
///     m->V *= s_;
///     return {{"mesh", tbsp::pipeline::Data::of(m)}};
///   }
///  private:
///   double s_;
/// };
/// TBSP_STAGE_PLUGIN(registry) {
///   tbsp::pipeline::StageInfo info{"my.scale", "scales a mesh"};
///   info.params = {tbsp::pipeline::ParamSpec::real("factor", "1", "scale factor", 1e-9, 1e9)};
///   info.inputs = {{"mesh", tbsp::pipeline::DataType::Mesh, "input mesh"}};
///   info.outputs = {{"mesh", tbsp::pipeline::DataType::Mesh, "scaled mesh"}};
///   registry.add(info, [](const tbsp::pipeline::Params& p) { return std::make_unique<Scale>(p.real("factor")); });
/// }
/// \endcode

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <variant>
#include <vector>

#include "tbsp/core/error.h"
#include "tbsp/core/progress.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp::pipeline {

/// Bumped whenever a type in this header changes layout; a plugin built against another version
/// is refused when loaded (with a message naming the plugin and both versions).
constexpr int kPluginAbiVersion = 2;  // 2: Stage::needs_input

/// What flows along an edge of the pipeline, one value per frame.
enum class DataType {
  Cloud,  ///< pcl::PointCloud<pcl::PointNormal>; `has_normals` says whether the normals are real
  Mesh,   ///< tbsp::TriMesh (vertices, faces, optional normals/colours)
};
inline const char* to_string(DataType t) { return t == DataType::Cloud ? "cloud" : "mesh"; }

/// One value on a port for one frame. Values are shared read-only between the stages that use
/// them: a stage that changes data makes its own copy.
struct Data {
  DataType type = DataType::Cloud;
  pcl::PointCloud<pcl::PointNormal>::ConstPtr cloud;  ///< set when type == Cloud
  bool has_normals = false;                           ///< the cloud's normals are meaningful
  std::shared_ptr<const TriMesh> mesh;                ///< set when type == Mesh

  static Data of(pcl::PointCloud<pcl::PointNormal>::ConstPtr c, bool normals) {
    Data d;
    d.type = DataType::Cloud;
    d.cloud = std::move(c);
    d.has_normals = normals;
    return d;
  }
  static Data of(std::shared_ptr<const TriMesh> m) {
    Data d;
    d.type = DataType::Mesh;
    d.mesh = std::move(m);
    return d;
  }
};
/// Port name -> value.
using Ports = std::map<std::string, Data>;

/// Parameter types. Values are written in the pipeline file as YAML scalars.
enum class ParamType {
  Bool,        ///< true/false (also yes/no, on/off)
  Int,         ///< integer within [min, max]
  Real,        ///< finite number within [min, max]
  Text,        ///< any string; with `choices`, one of them
  InputPath,   ///< a file or folder that must exist before the run (relative to the pipeline file)
  OutputPath,  ///< a file to write (relative to the pipeline file); may hold a printf frame pattern like %04d
};
inline const char* to_string(ParamType t) {
  switch (t) {
    case ParamType::Bool: return "bool";
    case ParamType::Int: return "int";
    case ParamType::Real: return "real";
    case ParamType::Text: return "text";
    case ParamType::InputPath: return "input path";
    case ParamType::OutputPath: return "output path";
  }
  return "?";
}

/// One parameter of a stage: name, type, default (as it would be written in the file; empty and
/// `required` = must be given), range, choices and a one-line meaning.
struct ParamSpec {
  std::string name;
  ParamType type = ParamType::Real;
  std::string default_value;  ///< "" = no default (optional unless `required`)
  std::string doc;
  double min = -std::numeric_limits<double>::infinity();
  double max = std::numeric_limits<double>::infinity();
  std::vector<std::string> choices;  ///< Text only: the allowed values
  bool required = false;

  static ParamSpec boolean(std::string n, bool def, std::string d) {
    return make(std::move(n), ParamType::Bool, def ? "true" : "false", std::move(d));
  }
  static ParamSpec integer(std::string n, std::string def, std::string d, double lo, double hi) {
    return ranged(make(std::move(n), ParamType::Int, std::move(def), std::move(d)), lo, hi);
  }
  static ParamSpec real(std::string n, std::string def, std::string d, double lo, double hi) {
    return ranged(make(std::move(n), ParamType::Real, std::move(def), std::move(d)), lo, hi);
  }
  static ParamSpec text(std::string n, std::string def, std::string d, std::vector<std::string> ch = {}) {
    ParamSpec p = make(std::move(n), ParamType::Text, std::move(def), std::move(d));
    p.choices = std::move(ch);
    return p;
  }
  static ParamSpec input_path(std::string n, std::string d, bool req) {
    ParamSpec p = make(std::move(n), ParamType::InputPath, "", std::move(d));
    p.required = req;
    return p;
  }
  static ParamSpec output_path(std::string n, std::string d) {
    ParamSpec p = make(std::move(n), ParamType::OutputPath, "", std::move(d));
    p.required = true;
    return p;
  }

private:
  static ParamSpec make(std::string n, ParamType t, std::string def, std::string d) {
    ParamSpec p;
    p.name = std::move(n);
    p.type = t;
    p.default_value = std::move(def);
    p.doc = std::move(d);
    return p;
  }
  static ParamSpec ranged(ParamSpec p, double lo, double hi) {
    p.min = lo;
    p.max = hi;
    return p;
  }
};

/// A stage's validated parameter values (every parameter with a default is present; paths are
/// already resolved against the pipeline file's folder). Accessors throw InvalidInput when the
/// name is not a parameter of that type, which is a bug in the stage, not in the user's file.
class Params {
public:
  using Value = std::variant<bool, long long, double, std::string>;
  void set(const std::string& name, Value v) { values_[name] = std::move(v); }
  bool has(const std::string& name) const { return values_.count(name) != 0; }
  bool boolean(const std::string& name) const { return get<bool>(name); }
  long long integer(const std::string& name) const { return get<long long>(name); }
  double real(const std::string& name) const { return get<double>(name); }
  /// Text and path parameters; "" when an optional one was not given.
  std::string text(const std::string& name) const { return has(name) ? get<std::string>(name) : std::string(); }
  const std::map<std::string, Value>& values() const { return values_; }

private:
  template <class T>
  const T& get(const std::string& name) const {
    auto it = values_.find(name);
    if (it == values_.end() || !std::holds_alternative<T>(it->second))
      throw InvalidInput("stage parameter '" + name + "' is not set or has another type (a bug in the stage plugin)");
    return std::get<T>(it->second);
  }
  std::map<std::string, Value> values_;
};

/// One input or output port.
struct PortSpec {
  PortSpec() = default;
  PortSpec(std::string n, DataType t, std::string d, bool opt = false)
      : name(std::move(n)), type(t), doc(std::move(d)), optional(opt) {}
  std::string name;
  DataType type = DataType::Cloud;
  std::string doc;
  bool optional = false;  ///< inputs only: may be left unconnected
};

/// Everything the registry, the validator, `tbsp plugins` and the docs know about a stage.
struct StageInfo {
  StageInfo() = default;
  StageInfo(std::string n, std::string s) : name(std::move(n)), summary(std::move(s)) {}
  std::string name;     ///< unique, e.g. "pcl.voxel-grid" (plugins should prefix their own name)
  std::string summary;  ///< one line
  std::vector<ParamSpec> params;
  std::vector<PortSpec> inputs, outputs;
  /// The stage keeps state from one frame to the next (e.g. warm start from the last fit), so a
  /// pipeline holding it runs its frames in order, in one process.
  bool frame_ordered = false;
  std::string plugin;  ///< filled in by the registry: the library the stage came from
};

/// What a stage sees of the run while it processes one frame.
struct FrameContext {
  int frame = 0;               ///< the frame number (from the pipeline's frame sources; 0 without any)
  std::string node;            ///< the pipeline node's id (for messages)
  ProgressCallback progress;   ///< report_progress(ctx.progress, fraction, stage); false = cancel
  /// Sinks: returns the temporary path to write `final_path` to. The runner renames every staged
  /// file onto its target only after the whole run succeeded, and removes them otherwise, so a
  /// failed run never replaces an earlier good output. Keeps the extension.
  std::function<std::string(const std::string& final_path)> stage_output;
  /// Notes for the run report (numbers, short strings), e.g. {"hausdorff_rel", 0.002}.
  std::map<std::string, double> numbers;
};

/// One pipeline node's worker. Made by the factory with validated parameters; lives for the run.
class Stage {
public:
  virtual ~Stage() = default;
  /// Frame sources only: the frame numbers this source delivers, ascending (called once before
  /// the run). Stages with inputs, and sources whose value is the same for every frame (a
  /// template mesh), return an empty list.
  virtual std::vector<int> frames() { return {}; }
  /// Processes one frame. `in` holds every connected input port; the result must hold every
  /// output port with its declared type. Throw InvalidInput (bad data) or NumericalFailure; the
  /// runner adds the frame number and node to the message.
  virtual Ports process(FrameContext& ctx, const Ports& in) = 0;
  /// For stages whose StageInfo says `frame_ordered`: whether this object, with its parameters,
  /// really carries state from frame to frame (e.g. `fit` only with warm_start). Pipelines
  /// without such a stage may split their frames over threads and MPI ranks.
  virtual bool keeps_state() const { return true; }
  /// Whether the next call of `process` reads the connected input `port` (asked before each
  /// frame). When no stage needs a node's outputs in a frame, the runner skips that node for the
  /// frame, e.g. `fit` with warm_start reads its template only on the first frame, so a template
  /// built from the first frame's data is built once. A port answered `false` is absent from `in`.
  /// Default: every connected input is read.
  virtual bool needs_input(const std::string& port) const {
    (void)port;
    return true;
  }
};

using StageMaker = std::function<std::unique_ptr<Stage>(const Params&)>;

/// The stage list: built-in and plugin stages by name.
class Registry {
public:
  /// Adds a stage. \throws InvalidInput when a stage of that name is already registered.
  void add(StageInfo info, StageMaker make) {
    if (info.name.empty()) throw InvalidInput("a stage without a name cannot be registered");
    if (stages_.count(info.name))
      throw InvalidInput("stage '" + info.name + "' is registered twice (" + stages_.at(info.name).info.plugin + " and " +
                         current_plugin_ + "); rename one of them");
    info.plugin = current_plugin_;
    const std::string name = info.name;  // (C++17 evaluates the right side of '=' first)
    stages_[name] = Entry{std::move(info), std::move(make)};
  }
  /// nullptr when unknown.
  const StageInfo* find(const std::string& name) const {
    auto it = stages_.find(name);
    return it == stages_.end() ? nullptr : &it->second.info;
  }
  /// Makes a stage. \throws InvalidInput when unknown.
  std::unique_ptr<Stage> create(const std::string& name, const Params& p) const {
    auto it = stages_.find(name);
    if (it == stages_.end()) throw InvalidInput("unknown stage '" + name + "'");
    return it->second.make(p);
  }
  /// All stages, sorted by name.
  std::vector<const StageInfo*> stages() const {
    std::vector<const StageInfo*> out;
    for (const auto& [n, e] : stages_) out.push_back(&e.info);
    return out;
  }
  /// Loads one plugin library (dlopen) and registers its stages. \throws FileError / InvalidInput
  /// naming the file: not loadable, no TBSP_STAGE_PLUGIN entry point, another ABI version.
  void load(const std::string& library_path);
  /// Loads every `*.so` in each folder (missing folders are skipped); returns how many loaded.
  int load_folder(const std::string& folder);
  /// Loads the default plugin path: the folders in $TBSP_PLUGIN_PATH (':'-separated), then
  /// `<prefix>/lib/tbsp/plugins` next to the running program (installed) or the build tree's
  /// plugin folder. Libraries with the same file name are loaded once (the first one found).
  void load_default_path();
  /// The folders load_default_path() searches, in order.
  static std::vector<std::string> default_path();

  /// Set while a plugin registers (for messages and `tbsp plugins`).
  void set_current_plugin(std::string p) { current_plugin_ = std::move(p); }

  Registry() = default;
  Registry(const Registry&) = delete;
  Registry& operator=(const Registry&) = delete;
  ~Registry() { stages_.clear(); }  // the factories' code lives in the libraries: drop them first

private:
  struct Entry {
    StageInfo info;
    StageMaker make;
  };
  std::vector<std::shared_ptr<void>> libraries_;  // dlopen handles, closed after stages_ is gone
  std::map<std::string, Entry> stages_;
  std::vector<std::string> loaded_names_;
  std::string current_plugin_ = "(program)";
};

}  // namespace tbsp::pipeline

/// Declares a plugin's entry point:
/// `TBSP_STAGE_PLUGIN(registry) { registry.add(info, maker); ... }`.
#define TBSP_STAGE_PLUGIN(registry)                                                                  \
  extern "C" __attribute__((visibility("default"))) int tbsp_plugin_abi_version() {                 \
    return ::tbsp::pipeline::kPluginAbiVersion;                                                      \
  }                                                                                                  \
  extern "C" __attribute__((visibility("default"))) void tbsp_register_stages(::tbsp::pipeline::Registry& registry)
