// bench_cloth: PbdClothSimulator throughput on a ~5k-vertex skirt (issue 26 goal: ≥ 500 frames/s
// with n_iter = 16 on 2 cores). The skirt is an open flared tube hanging from a waist ring that
// turns and sways (kinematic, δ = 0), two leg capsules swing inside it (proxies). Prints a table:
// frames/s for each configuration and thread count, the largest edge strain, contacts and a hash
// of the final state (equal hashes: the same simulation, bit for bit).
//
//   bench_cloth [--frames N] [--rings R] [--segments S] [--only WORD] [--threads N]
//   (--only: the configurations whose name contains WORD; --threads: that thread count only)
#include <omp.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "tbsp/cloth/pbd_cloth_simulator.h"

using namespace tbsp;

namespace {

struct Skirt {
  Eigen::MatrixX3d V;
  Eigen::MatrixX3i F;
  Eigen::VectorXd delta;
  int segments = 0;
};

// rings × segments vertices; ring 0 is the waist (radius 0.16 m at y = 1.0), the hem (radius
// 0.36 m) 0.6 m lower
Skirt make_skirt(int rings, int segments) {
  Skirt s;
  s.segments = segments;
  s.V.resize(rings * segments, 3);
  for (int r = 0; r < rings; ++r) {
    const double t = double(r) / (rings - 1);
    const double radius = 0.16 + 0.2 * t, y = 1.0 - 0.6 * t;
    for (int k = 0; k < segments; ++k) {
      const double a = 2 * M_PI * k / segments;
      s.V.row(r * segments + k) << radius * std::cos(a), y, radius * std::sin(a);
    }
  }
  s.F.resize(2 * (rings - 1) * segments, 3);
  int f = 0;
  for (int r = 0; r + 1 < rings; ++r)
    for (int k = 0; k < segments; ++k) {
      const int a = r * segments + k, b = r * segments + (k + 1) % segments, c = a + segments, d = b + segments;
      s.F.row(f++) << a, c, d;
      s.F.row(f++) << a, d, b;
    }
  s.delta = Eigen::VectorXd::Ones(s.V.rows());
  for (int k = 0; k < segments; ++k) s.delta(k) = 0;
  return s;
}

// the waist turns (±60°) and sways; legs swing ±25°
void pose(double time, const Skirt& s, Eigen::MatrixX3d& targets, std::vector<RoundCone>& legs) {
  const double turn = (M_PI / 3) * std::sin(2 * M_PI * 0.5 * time);
  const Eigen::Vector3d shift(0.05 * std::sin(2 * M_PI * time), 0, 0.3 * time);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(turn, Eigen::Vector3d::UnitY()).toRotationMatrix();
  targets = s.V;
  for (Eigen::Index i = 0; i < s.V.rows(); ++i) targets.row(i) = (R * s.V.row(i).transpose() + shift).transpose();
  legs.clear();
  for (int side : {-1, 1}) {
    const double swing = side * 0.45 * std::sin(2 * M_PI * time);
    const Eigen::Vector3d hip = R * Eigen::Vector3d(0.07 * side, 0.92, 0) + shift;
    const Eigen::Vector3d knee = hip + R * Eigen::Vector3d(0, -0.45 * std::cos(swing), 0.45 * std::sin(swing));
    legs.push_back({hip, knee, 0.065, 0.05});
  }
}

struct Row {
  double fps;
  double strain, strain99;
  int contacts;
  std::uint32_t state;  // FNV-1a of the final positions' bits: equal rows ran the same simulation
};

std::uint32_t fnv1a(const Eigen::MatrixX3d& X) {
  std::uint32_t h = 2166136261u;
  const auto* bytes = reinterpret_cast<const unsigned char*>(X.data());
  for (std::size_t i = 0; i < std::size_t(X.size()) * sizeof(double); ++i) h = (h ^ bytes[i]) * 16777619u;
  return h;
}

Row run(const Skirt& s, const PbdSettings& st, int frames, int threads) {
  omp_set_num_threads(threads);
  PbdClothSimulator sim;
  sim.setMesh(s.V, s.F);
  sim.setSettings(st);
  sim.setClothness(s.delta);
  sim.setMaterial({2.0, 4.0, 0.3});
  Eigen::MatrixX3d targets;
  std::vector<RoundCone> legs;
  pose(0, s, targets, legs);
  sim.reset(targets);
  double strain = 0, strain99 = 0;
  int contacts = 0;
  const auto t0 = std::chrono::steady_clock::now();
  for (int f = 1; f <= frames; ++f) {
    pose(f * st.time_step, s, targets, legs);
    sim.step(targets, legs);
    strain = std::max(strain, sim.maxStrain());
    strain99 = std::max(strain99, sim.strainQuantile(0.99));
    contacts = std::max(contacts, sim.numProxyContacts());
  }
  const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // the strain statistics are O(#edges) per frame, inside the timing (a few % of a frame)
  return {frames / sec, strain, strain99, contacts, fnv1a(sim.positions())};
}

}  // namespace

int main(int argc, char** argv) {
  int frames = 200, rings = 50, segments = 100, only_threads = 0;
  std::string only;
  // every flag takes a value; anything else (--help, a flag without its value) prints the usage
  for (int i = 1; i < argc; i += 2) {
    const bool has_value = i + 1 < argc;
    if (has_value && !std::strcmp(argv[i], "--frames")) frames = std::atoi(argv[i + 1]);
    else if (has_value && !std::strcmp(argv[i], "--rings")) rings = std::atoi(argv[i + 1]);
    else if (has_value && !std::strcmp(argv[i], "--segments")) segments = std::atoi(argv[i + 1]);
    else if (has_value && !std::strcmp(argv[i], "--only")) only = argv[i + 1];
    else if (has_value && !std::strcmp(argv[i], "--threads")) only_threads = std::atoi(argv[i + 1]);
    else {
      std::fprintf(stderr, "usage: bench_cloth [--frames N] [--rings R] [--segments S] [--only WORD] [--threads N]\n");
      return 2;
    }
  }
  if (frames < 1 || rings < 3 || segments < 8) {
    std::fprintf(stderr, "bench_cloth: need frames >= 1, rings >= 3, segments >= 8\n");
    return 2;
  }
  const Skirt s = make_skirt(rings, segments);
  std::printf("skirt: %lld vertices, %lld faces; %d frames at 40 fps; n_iter = 16 sweeps per frame\n",
              (long long)s.V.rows(), (long long)s.F.rows(), frames);
  std::printf("%-44s %7s %10s %10s %10s %9s %9s\n", "configuration", "threads", "frames/s", "max strain", "p99 strain", "contacts",
              "state");
  struct Config {
    const char* name;
    int iterations, substeps;
    bool self;
    bool legs = true;
  };
  for (const Config& c : {Config{"16 sub-steps x 1 sweep, self-collision", 1, 16, true},
                          Config{"16 sub-steps x 1 sweep, no self-collision", 1, 16, false},
                          Config{"thesis: 1 step x 16 sweeps, self-collision", 16, 1, true},
                          Config{"4 sub-steps x 4 sweeps, self-collision", 4, 4, true}}) {
    if (!only.empty() && std::string(c.name).find(only) == std::string::npos) continue;
    PbdSettings st;
    st.iterations = c.iterations;
    st.substeps = c.substeps;
    st.self_collision = c.self;
    for (int threads : {1, 2}) {
      if (only_threads > 0 && threads != only_threads) continue;
      const Row r = run(s, st, frames, threads);
      std::printf("%-44s %7d %10.1f %10.3f %10.3f %9d  %08x\n", c.name, threads, r.fps, r.strain, r.strain99, r.contacts, r.state);
    }
  }
  return 0;
}
