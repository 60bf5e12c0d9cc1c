// `tbsp run` under mpirun (docs/pipelines.md, "Distribution"): the frames are split over the
// ranks (frame k of the list to rank k mod N); every rank stages its outputs privately; when all
// ranks succeeded, rank 0 gathers the files and the frame reports, writes them and renames them
// into place. When a rank fails, it tells the others to stop at their next stage, every rank
// discards its outputs, rank 0 prints each failing rank's message (frame, node, line) and all
// ranks exit with the error's code. Built only with Open MPI (TBSP_WITH_MPI).
// the C API only (Open MPI / MPICH would otherwise pull in their deprecated C++ bindings)
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>
#include <stdlib.h>
#include <unistd.h>

#include <climits>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "pipeline_mpi.h"
#include "progress_bar.h"
#include "tbsp/core/error.h"
#include "tbsp/core/error_kind.h"
#include "tbsp/io/atomic_file.h"

namespace fs = std::filesystem;

namespace tbsp::cli {
namespace {

constexpr int kTagAbort = 71, kTagFiles = 72, kTagData = 73;

void send_string(const std::string& s, int to, int tag) {
  if (s.size() > std::size_t(INT_MAX)) throw InvalidInput("an output of " + std::to_string(s.size()) + " bytes is too large to send over MPI (2 GB limit)");
  MPI_Send(s.data(), int(s.size()), MPI_CHAR, to, tag, MPI_COMM_WORLD);
}
std::string recv_string(int from, int tag) {
  MPI_Status st;
  MPI_Probe(from, tag, MPI_COMM_WORLD, &st);
  int n = 0;
  MPI_Get_count(&st, MPI_CHAR, &n);
  std::string s(std::size_t(n), '\0');
  MPI_Recv(s.data(), n, MPI_CHAR, from, tag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
  return s;
}
std::string read_file(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) throw FileError("'" + p + "': cannot read a staged output back");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::vector<pipeline::FrameReport> frames_from_json(const std::string& text) {
  std::vector<pipeline::FrameReport> out;
  const nlohmann::json j = nlohmann::json::parse(text);
  for (const auto& f : j.at("frames")) {
    pipeline::FrameReport r;
    r.frame = f.at("frame").get<int>();
    r.seconds = f.at("seconds").get<double>();
    r.node_seconds = f.at("node_seconds").get<std::map<std::string, double>>();
    if (f.contains("numbers")) r.numbers = f.at("numbers").get<std::map<std::string, std::map<std::string, double>>>();
    out.push_back(std::move(r));
  }
  return out;
}

}  // namespace

int run_distributed(const pipeline::Pipeline& p, const pipeline::Registry& reg, pipeline::RunOptions o, bool quiet) {
  int provided = 0;
  MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  MPI_Barrier(MPI_COMM_WORLD);
  const double t0 = MPI_Wtime();
  o.rank = rank;
  o.ranks = size;
  o.commit = false;
  o.threads = 1;  // the ranks are the frame-parallel workers; each rank's stages use its cores
  std::string private_dir;
  if (rank != 0) {
    char tmpl[] = "/tmp/tbsp-rank-XXXXXX";
    if (::mkdtemp(tmpl)) private_dir = tmpl;
    o.stage_dir = private_dir;
  }
  // a failing rank tells the others; they stop at their next stage
  bool stopped_by_peer = false;
  ProgressBar bar(rank == 0 && !quiet);
  const ProgressCallback user = rank == 0 ? bar.callback() : ProgressCallback();
  o.progress = [&](double f, const std::string& what) {
    int flag = 0;
    MPI_Iprobe(MPI_ANY_SOURCE, kTagAbort, MPI_COMM_WORLD, &flag, MPI_STATUS_IGNORE);
    if (flag) {
      stopped_by_peer = true;
      return false;
    }
    return !user || user(f, what);
  };

  int code = 0;
  std::string msg;
  pipeline::RunReport rep;
  try {
    rep = pipeline::run_pipeline(p, reg, o);
  } catch (...) {
    code = stopped_by_peer ? 0 : exit_code_of(std::current_exception());
    msg = error_message(std::current_exception());
    if (stopped_by_peer) code = -1;  // not an error of its own
  }
  std::vector<MPI_Request> reqs;
  int one = 1;
  if (code > 0)
    for (int r = 0; r < size; ++r)
      if (r != rank) {
        reqs.emplace_back();
        MPI_Isend(&one, 1, MPI_INT, r, kTagAbort, MPI_COMM_WORLD, &reqs.back());
      }
  int failed = code > 0 ? 1 : 0, failures = 0, worst = 0;
  MPI_Allreduce(&failed, &failures, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD);
  MPI_Allreduce(&code, &worst, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  for (int k = 0; k < failures - failed; ++k) {  // exactly one abort message per other failing rank
    int dummy = 0;
    MPI_Recv(&dummy, 1, MPI_INT, MPI_ANY_SOURCE, kTagAbort, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
  }
  if (!reqs.empty()) MPI_Waitall(int(reqs.size()), reqs.data(), MPI_STATUSES_IGNORE);

  int result = 0;
  if (failures > 0) {
    pipeline::discard_staged(rep.staged);
    // rank 0 prints every failing rank's message
    const std::string mine = code > 0 ? msg : std::string();
    if (rank == 0) {
      bar.finish();
      if (code > 0) std::cerr << "tbsp run: error (rank 0 of " << size << "): " << mine << "\n";
      for (int r = 1; r < size; ++r) {
        const std::string m = recv_string(r, kTagData);
        if (!m.empty()) std::cerr << "tbsp run: error (rank " << r << " of " << size << "): " << m << "\n";
      }
      std::cerr << "tbsp run: " << failures << " rank(s) failed; no output was written\n";
    } else {
      send_string(mine, 0, kTagData);
    }
    result = worst;
  } else if (rank != 0) {
    // send the staged files, then this rank's frame reports
    try {
      const std::string n = std::to_string(rep.staged.size());
      send_string(n, 0, kTagFiles);
      for (const auto& f : rep.staged) {
        send_string(f.target, 0, kTagFiles);
        send_string(read_file(f.temp), 0, kTagData);
      }
      send_string(pipeline::run_report_json(p, rep), 0, kTagData);
    } catch (const std::exception& e) {
      std::cerr << "tbsp run: error (rank " << rank << "): " << e.what() << "\n";
      MPI_Abort(MPI_COMM_WORLD, 1);  // rank 0 waits for these messages: do not leave it hanging
    }
    pipeline::discard_staged(rep.staged);
  } else {
    // rank 0: stage what the others computed next to its targets, write the report, commit all
    std::vector<pipeline::StagedFile> all = rep.staged;
    const double compute = rep.seconds, tg = MPI_Wtime();
    double bytes_in = 0;
    try {
      for (int r = 1; r < size; ++r) {
        const int n = std::stoi(recv_string(r, kTagFiles));
        for (int k = 0; k < n; ++k) {
          const std::string target = recv_string(r, kTagFiles), bytes = recv_string(r, kTagData);
          bytes_in += double(bytes.size());
          const fs::path t(target);
          if (!t.parent_path().empty()) fs::create_directories(t.parent_path());
          const std::string tmp = (t.parent_path() / (".tbsp-run-" + std::to_string(::getpid()) + "-r" + std::to_string(r) + "-" +
                                                      t.filename().string())).string();
          all.push_back({tmp, target});
          std::ofstream out(tmp, std::ios::binary);
          out.write(bytes.data(), std::streamsize(bytes.size()));
          if (!out) throw FileError("'" + tmp + "': cannot write an output gathered from rank " + std::to_string(r));
        }
        for (auto& f : frames_from_json(recv_string(r, kTagData))) rep.frames.push_back(std::move(f));
      }
      rep.seconds = MPI_Wtime() - t0;
      if (!p.report.empty()) {
        const std::string tmp = p.report + ".tbsp-run-" + std::to_string(::getpid());
        all.push_back({tmp, p.report});
        nlohmann::json j = nlohmann::json::parse(pipeline::run_report_json(p, rep));
        j["ranks"] = size;
        // for docs/scaling.md: rank 0's own frames, then receiving the other ranks' outputs
        j["rank0_compute_seconds"] = compute;
        j["gather_seconds"] = MPI_Wtime() - tg;
        j["gathered_bytes"] = bytes_in;
        std::ofstream(tmp) << j.dump(2) << "\n";
      }
      const auto written = pipeline::commit_staged(all);
      bar.finish();
      if (!quiet)
        std::cout << p.file << ": " << rep.frames.size() << " frames on " << size << " ranks in " << rep.seconds << " s ("
                  << double(rep.frames.size()) / std::max(rep.seconds, 1e-9) << " frames/s), " << written.size() << " files written\n";
    } catch (const std::exception& e) {
      pipeline::discard_staged(all);
      std::cerr << "tbsp run: error (rank 0, gathering the outputs): " << e.what() << "\n";
      MPI_Abort(MPI_COMM_WORLD, 1);  // other ranks may still be sending: do not leave them hanging
    }
  }
  if (!private_dir.empty()) {
    std::error_code ec;
    fs::remove_all(private_dir, ec);
  }
  MPI_Finalize();
  return result;
}

}  // namespace tbsp::cli
