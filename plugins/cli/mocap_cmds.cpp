#include "mocap_cmds.h"

#include "command.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/mocap_io.h"

namespace fs = std::filesystem;

namespace tbsp::cli {

namespace {

// Gaps of one marker: frames missing, number of runs of missing frames, longest run.
struct MarkerGaps {
  int missing = 0, gaps = 0, longest = 0;
};
MarkerGaps marker_gaps(const MarkerTrajectories& m, int k) {
  MarkerGaps g;
  int run = 0;
  for (int f = 0; f < m.numFrames(); ++f) {
    if (m.valid(f, k)) {
      run = 0;
      continue;
    }
    ++g.missing;
    if (run++ == 0) ++g.gaps;
    g.longest = std::max(g.longest, run);
  }
  return g;
}

int markers_cmd(const MocapArgs& a) {
  const MarkerTrajectories m = read_markers(a.input);
  std::vector<MarkerGaps> gaps;
  int with_gaps = 0, missing = 0;
  for (int k = 0; k < m.numMarkers(); ++k) {
    gaps.push_back(marker_gaps(m, k));
    with_gaps += gaps.back().missing > 0;
    missing += gaps.back().missing;
  }
  if (!a.quiet) {
    std::cout << a.input << ": " << m.numMarkers() << " markers, " << m.numFrames() << " frames at " << m.frame_rate
              << " Hz (first frame " << m.first_frame << ", " << m.numFrames() / m.frame_rate << " s), units '"
              << (m.units.empty() ? "?" : m.units) << "'\n";
    std::cout << "  gaps: " << with_gaps << " of " << m.numMarkers() << " markers have gaps, " << missing << " of "
              << std::size_t(m.numFrames()) * std::size_t(m.numMarkers()) << " samples missing\n";
    std::vector<int> order(std::size_t(m.numMarkers()));
    for (int k = 0; k < m.numMarkers(); ++k) order[std::size_t(k)] = k;
    std::stable_sort(order.begin(), order.end(), [&](int x, int y) { return gaps[std::size_t(x)].missing > gaps[std::size_t(y)].missing; });
    for (std::size_t i = 0; i < order.size() && i < 10 && gaps[std::size_t(order[i])].missing > 0; ++i) {
      const auto& g = gaps[std::size_t(order[i])];
      std::cout << "    " << m.names[std::size_t(order[i])] << ": " << g.missing << " frames missing in " << g.gaps
                << " gap(s), longest " << g.longest << "\n";
    }
  }
  if (!a.json.empty()) {
    nlohmann::json j = {{"file", a.input},         {"kind", "markers"},     {"markers", m.numMarkers()},
                        {"frames", m.numFrames()}, {"frame_rate", m.frame_rate}, {"first_frame", m.first_frame},
                        {"units", m.units},        {"missing_samples", missing}};
    for (int k = 0; k < m.numMarkers(); ++k) {
      const auto& g = gaps[std::size_t(k)];
      j["per_marker"].push_back({{"name", m.names[std::size_t(k)]}, {"missing", g.missing}, {"gaps", g.gaps}, {"longest_gap", g.longest}});
    }
    write_text_file_atomic(a.json, j.dump(2) + "\n");
  }
  if (!a.out.empty()) {
    const std::string oe = lower_ext(a.out);
    if (oe == ".trc") write_trc(a.out, m);
    else if (oe == ".c3d") write_c3d(a.out, m);
    else throw InvalidInput("--out " + a.out + ": marker trajectories convert to .trc or .c3d");
    if (!a.quiet) std::cout << "  wrote " << a.out << "\n";
  }
  return 0;
}

int bvh_cmd(const MocapArgs& a) {
  const BvhMotion b = read_bvh(a.input);
  int end_sites = 0;
  for (const auto& jn : b.joints) end_sites += jn.end_site;
  const Eigen::MatrixX3d P0 = b.numFrames() > 0 ? b.jointPositions(0) : Eigen::MatrixX3d();
  if (!a.quiet) {
    std::cout << a.input << ": skeleton of " << b.numJoints() << " joints (+" << end_sites << " end sites), root '"
              << (b.joints.empty() ? "" : b.joints.front().name) << "', " << b.numChannels() << " channels; " << b.numFrames()
              << " frames, frame time " << b.frame_time << " s (" << (b.frame_time > 0 ? 1.0 / b.frame_time : 0) << " fps)\n";
    if (P0.rows() > 0) {
      const Eigen::RowVector3d ext = P0.colwise().maxCoeff() - P0.colwise().minCoeff();
      std::cout << "  frame 0: joint positions span " << ext(0) << " x " << ext(1) << " x " << ext(2) << " (file units)\n";
    }
  }
  // joint positions of every frame as marker trajectories (joints = markers)
  std::vector<int> keep;
  for (std::size_t k = 0; k < b.joints.size(); ++k)
    if (a.end_sites || !b.joints[k].end_site) keep.push_back(int(k));
  if (!a.json.empty()) {
    nlohmann::json j = {{"file", a.input}, {"kind", "skeleton"}, {"joints", b.numJoints()}, {"end_sites", end_sites},
                        {"channels", b.numChannels()}, {"frames", b.numFrames()}, {"frame_time", b.frame_time}};
    for (const auto& jn : b.joints)
      j["per_joint"].push_back({{"name", jn.name}, {"parent", jn.parent}, {"channels", jn.channels.size()}, {"end_site", jn.end_site}});
    write_text_file_atomic(a.json, j.dump(2) + "\n");
  }
  if (a.out.empty()) return 0;
  const std::string oe = lower_ext(a.out);
  if (oe != ".trc" && oe != ".c3d" && oe != ".csv")
    throw InvalidInput("--out " + a.out + ": BVH joint positions are written as .trc, .c3d (joints as markers) or .csv");
  if (!(b.frame_time > 0)) throw InvalidInput(a.input + ": Frame Time is not positive; cannot write a trajectory file");
  MarkerTrajectories m;
  m.frame_rate = 1.0 / b.frame_time;
  m.first_frame = 1;
  m.units = a.units.empty() ? "unknown" : a.units;  // a BVH file does not state its units
  m.data.resize(b.numFrames(), 3 * Eigen::Index(keep.size()));
  for (int k : keep) m.names.push_back(b.joints[std::size_t(k)].name + (b.joints[std::size_t(k)].end_site ? "_end" : ""));
  for (int f = 0; f < b.numFrames(); ++f) {
    const Eigen::MatrixX3d P = b.jointPositions(f);
    for (std::size_t i = 0; i < keep.size(); ++i) m.data.block<1, 3>(f, 3 * Eigen::Index(i)) = P.row(keep[i]);
  }
  if (oe == ".trc") write_trc(a.out, m);
  else if (oe == ".c3d") write_c3d(a.out, m);
  else {
    std::ostringstream os;
    os << std::setprecision(9) << "frame,time";
    for (const auto& n : m.names) os << ',' << n << "_x," << n << "_y," << n << "_z";
    os << '\n';
    for (int f = 0; f < m.numFrames(); ++f) {
      os << f << ',' << f * b.frame_time;
      for (Eigen::Index c = 0; c < m.data.cols(); ++c) os << ',' << m.data(f, c);
      os << '\n';
    }
    write_text_file_atomic(a.out, os.str());
  }
  if (!a.quiet) std::cout << "  wrote " << a.out << " (" << keep.size() << " joint trajectories)\n";
  return 0;
}

}  // namespace

void add_mocap(CLI::App& app, MocapArgs& a, CLI::App*& sub) {
  sub = app.add_subcommand("mocap",
                           "inspect motion capture (TRC/C3D markers: frames, rate, gaps; BVH: joints, frames) and convert it "
                           "(C3D <-> TRC; BVH -> joint positions as TRC/C3D/CSV)");
  sub->add_option("input", a.input, ".trc, .c3d or .bvh file")->required()->check(CLI::ExistingFile);
  sub->add_option("--out", a.out, "convert: .trc or .c3d (markers or BVH joints), .csv (BVH joint positions); written atomically");
  sub->add_option("--json", a.json, "report as JSON (per-marker gaps / per-joint channels)");
  sub->add_flag("--end-sites", a.end_sites, "BVH: also write the End Site points");
  sub->add_option("--units", a.units, "BVH: units label of the written trajectories, e.g. cm (BVH files do not state it; default 'unknown')");
  sub->add_flag("-q,--quiet", a.quiet, "no summary");
}

int cmd_mocap(const MocapArgs& a) {
  const std::string ext = lower_ext(a.input);
  if (ext == ".trc" || ext == ".c3d") return markers_cmd(a);
  if (ext == ".bvh") return bvh_cmd(a);
  throw InvalidInput("'" + a.input + "': unknown motion-capture format '" + ext + "' (tbsp mocap reads .trc, .c3d and .bvh)");
}

void add_mocap_commands(CLI::App& app, CommandTable& table) {
  register_command<MocapArgs>(app, table, add_mocap, cmd_mocap);
}

}  // namespace tbsp::cli
