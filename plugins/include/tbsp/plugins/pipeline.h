#pragma once
/// \file pipeline.h
/// \brief YAML pipelines of stages: load + validate the whole file, then stream frames through
/// it (docs/pipelines.md).
///
/// \code
/// tbsp::pipeline::Registry reg;
/// reg.load_default_path();                                   // built-in + plugin stages
/// auto p = tbsp::pipeline::load_pipeline("replay.yaml", reg);  // throws PipelineError naming the line
/// tbsp::pipeline::RunReport r = tbsp::pipeline::run_pipeline(p, reg);
/// \endcode
#include <map>
#include <string>
#include <vector>

#include "tbsp/core/error.h"
#include "tbsp/core/progress.h"
#include "tbsp/plugins/stage.h"

namespace tbsp::pipeline {

/// A pipeline file that cannot run: the message starts with "FILE:LINE:" and says the fix.
class PipelineError : public InvalidInput {
public:
  PipelineError(const std::string& file, int line, const std::string& what)
      : InvalidInput(file + ":" + std::to_string(line) + ": " + what), line_(line) {}
  int line() const { return line_; }

private:
  int line_;
};

/// One stage of a loaded pipeline.
struct Node {
  std::string id;     ///< unique name in the file
  std::string stage;  ///< registry name
  int line = 0;       ///< 1-based line of the node in the file
  Params params;      ///< validated, defaults filled in, paths resolved
  /// input port -> (node id, output port)
  std::map<std::string, std::pair<std::string, std::string>> inputs;
};

/// A validated pipeline: nodes in an order where every node comes after its inputs.
struct Pipeline {
  std::string file;          ///< the YAML file (for messages)
  std::vector<Node> nodes;   ///< topologically sorted
  int first = -1, last = -1; ///< `frames: a:b` (inclusive; -1 = open)
  std::string report;        ///< `report:` JSON path ("" = none), resolved
};

/// Parses and validates a pipeline from YAML text; `base_dir` resolves relative paths and `file`
/// names the source in messages. Checks, before anything runs: YAML syntax, known keys, unique
/// ids, known stages, every parameter (name, type, range, choices, required), input files exist,
/// connections (known node and port, matching types, required inputs connected), no cycle.
/// \throws PipelineError naming the line and the fix.
Pipeline parse_pipeline(const std::string& yaml_text, const std::string& base_dir, const std::string& file,
                        const Registry& registry);
/// Reads `path` and calls parse_pipeline with its folder. \throws FileError when unreadable.
Pipeline load_pipeline(const std::string& path, const Registry& registry);

struct RunOptions {
  int first = -1, last = -1;  ///< frame range override (inclusive; -1 = the file's / all)
  ProgressCallback progress;  ///< fraction of this process's frames done, "frame F node: ..."; false cancels
  /// Frame-parallel share (MPI ranks, see docs/pipelines.md): this process runs the frames at
  /// positions k of the frame list with k % ranks == rank. Default: all frames.
  int rank = 0, ranks = 1;
  /// Worker threads, each with its own stage objects, taking frames k % threads (within this
  /// process's share); each worker's stages get hardware threads / threads OpenMP threads.
  /// 0 = one per hardware thread when no stage keeps state across frames, else 1.
  int threads = 1;
  /// false: outputs stay staged (RunReport::staged) for the caller to gather and commit, and the
  /// report file is not written (MPI rank 0 does both for all ranks).
  bool commit = true;
  /// Folder for staged files ("" = next to each target). MPI ranks other than 0 stage privately.
  std::string stage_dir;
};

/// Per-frame timings and the numbers stages noted (FrameContext::numbers).
struct FrameReport {
  int frame = 0;
  double seconds = 0;
  std::map<std::string, double> node_seconds;                   ///< node id -> s
  std::map<std::string, std::map<std::string, double>> numbers;  ///< node id -> notes
};
/// A sink's output waiting to be renamed onto its target.
struct StagedFile {
  std::string temp, target;
};
struct RunReport {
  std::vector<FrameReport> frames;   ///< the frames run by this process, by frame number
  std::vector<std::string> outputs;  ///< files written (after the rename)
  std::vector<StagedFile> staged;    ///< with RunOptions::commit = false: not yet renamed
  int threads = 1;                   ///< worker threads used
  double seconds = 0;
};

/// Runs the pipeline: creates the Stage objects, takes the frame list from the frame sources
/// (their intersection, restricted to the range; one frame numbered 0 without any source), and
/// streams the frames one at a time through the nodes. Outputs are staged and renamed onto their
/// targets only when every frame succeeded; a failure removes them and rethrows with
/// "frame F, node 'id' (line L): ..." in front. Writes the report JSON when the file asks.
/// \throws InvalidInput when `ranks` or `threads` > 1 and a stage keeps state from frame to
/// frame (naming the node; such pipelines run in order in one worker).
RunReport run_pipeline(const Pipeline& pipeline, const Registry& registry, const RunOptions& options = {});

/// The run report as JSON text (frames sorted by number): what `report:` receives.
std::string run_report_json(const Pipeline& pipeline, const RunReport& report);
/// Renames staged files onto their targets, in order; returns the targets. \throws FileError.
std::vector<std::string> commit_staged(const std::vector<StagedFile>& files);
/// Removes staged files (no error when one is already gone).
void discard_staged(const std::vector<StagedFile>& files);

/// The stage list as Markdown (docs/stages.md is generated with it) or plain text.
std::string describe_stages(const Registry& registry, bool markdown);

}  // namespace tbsp::pipeline
