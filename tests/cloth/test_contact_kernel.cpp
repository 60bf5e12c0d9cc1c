// The four-lane candidate tests of PbdClothSimulator's self-contact search
// (pcl_ext/src/cloth/pbd_contact_kernel.h): the entries it passes are exactly those the scalar
// tests pass, in scan order, whatever the runs' lengths and where they end.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "pbd_contact_kernel.h"

using tbsp::detail::contact_candidates;
using tbsp::detail::ContactEntries;

// (names unique among the test files a unity build compiles together)
namespace {

struct ContactGrid {
  std::vector<double> x, y, z, travel;
  std::vector<int> j;
  explicit ContactGrid(std::size_t n) : x(n + 3), y(n + 3), z(n + 3), travel(n + 3), j(n + 3) {}  // + 3: the kernel's padding
  ContactEntries view() const { return {x.data(), y.data(), z.data(), travel.data(), j.data()}; }
};

// the scalar tests, written out from the kernel's contract
std::vector<int> scalar_candidates(const ContactGrid& g, const std::vector<int>& b, const std::vector<int>& e, const double p[3], double ti, int i,
                           double reach2) {
  std::vector<int> out;
  for (std::size_t r = 0; r < b.size(); ++r)
    for (int q = b[r]; q < e[r]; ++q) {
      if (g.travel[q] > ti || (g.travel[q] == ti && g.j[q] >= i)) continue;
      const double dx = p[0] - g.x[q], dy = p[1] - g.y[q], dz = p[2] - g.z[q];
      if ((dx * dx + dy * dy) + dz * dz > reach2) continue;
      out.push_back(q);
    }
  return out;
}

std::vector<int> kernel_candidates(const ContactGrid& g, const std::vector<int>& b, const std::vector<int>& e, const double p[3], double ti, int i,
                            double reach2) {
  int total = 0;
  for (std::size_t r = 0; r < b.size(); ++r) total += e[r] - b[r];
  std::vector<int> out(std::size_t(total) + 4, -1);
  const int n = contact_candidates(g.view(), b.data(), e.data(), int(b.size()), p, ti, i, reach2, out.data());
  out.resize(std::size_t(n));
  return out;
}

}  // namespace

TEST(PbdContactKernel, PassesExactlyTheEntriesTheScalarTestsPassInScanOrder) {
  const std::size_t n = 301;  // not a multiple of four: the last run reads into the padding
  ContactGrid g(n);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  for (std::size_t q = 0; q < n; ++q) {
    g.x[q] = u(rng), g.y[q] = u(rng), g.z[q] = u(rng);
    g.travel[q] = std::round(4 * (u(rng) + 1)) / 8;  // few distinct values: many ties
    g.j[q] = int((q * 37) % n);                      // vertex indices in no order
  }
  std::uniform_int_distribution<int> len(0, 13);
  int passed = 0, tested = 0;
  for (int t = 0; t < 200; ++t) {
    // runs of 0-13 entries, some overlapping, the last one ending at the array's end
    std::vector<int> b, e;
    for (int r = 0; r < 1 + t % 9; ++r) {
      const int l = len(rng);
      const int s = std::uniform_int_distribution<int>(0, int(n) - l)(rng);
      b.push_back(s), e.push_back(s + l);
    }
    b.push_back(int(n) - 1 - t % 7), e.push_back(int(n));
    const double p[3] = {u(rng), u(rng), u(rng)};
    const int i = int(t % n);
    const double ti = g.travel[std::size_t(t % n)], reach2 = 0.5 * (u(rng) + 1.2);
    const std::vector<int> want = scalar_candidates(g, b, e, p, ti, i, reach2), got = kernel_candidates(g, b, e, p, ti, i, reach2);
    ASSERT_EQ(got, want) << "query " << t;
    passed += int(want.size());
    for (std::size_t r = 0; r < b.size(); ++r) tested += e[r] - b[r];
  }
  // the draw exercises both outcomes: a fair share passes, most do not
  EXPECT_GT(passed, tested / 20);
  EXPECT_LT(passed, tested / 2);
}

TEST(PbdContactKernel, TiesGoToTheLowerVertexAndTheReachIsInclusive) {
  ContactGrid g(6);
  const double p[3] = {0, 0, 0};
  // entry: position, travel, vertex. The query is vertex 10 with travel 1, reach² 25.
  auto put = [&](int q, double x, double y, double travel, int j) { g.x[q] = x, g.y[q] = y, g.z[q] = 0, g.travel[q] = travel, g.j[q] = j; };
  put(0, 3, 4, 1.0, 9);      // tie, lower vertex, exactly at the reach: passes
  put(1, 3, 4, 1.0, 11);     // tie, higher vertex: found from 11
  put(2, 1, 0, 1.0, 10);     // the vertex itself
  put(3, 1, 0, 1.5, 3);      // faster: found from 3
  put(4, 3, 4.0001, 0.5, 2); // just beyond the reach
  put(5, 0, 0, 0.5, 20);     // slower, on top: passes
  const std::vector<int> b{0}, e{6};
  EXPECT_EQ(kernel_candidates(g, b, e, p, 1.0, 10, 25.0), (std::vector<int>{0, 5}));
  // an empty run and a run of one
  EXPECT_EQ(kernel_candidates(g, {2, 5}, {2, 6}, p, 1.0, 10, 25.0), (std::vector<int>{5}));
}
