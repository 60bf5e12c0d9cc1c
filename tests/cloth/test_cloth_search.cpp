// The material searches of ClothParameterEstimation (cloth_search.h) on analytic energies of the
// unit cube: where the minimum is known, how many evaluations they take, memoization, determinism.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <set>
#include <stdexcept>

#include "cloth_search.h"

using tbsp::detail::MemoEnergy;
using tbsp::detail::UnitPoint;

namespace {

// A valley like the cloth energy's: steep along axis 2 (k_bend), shallow along 0 and 1 (the drags),
// minimum at c; optionally a ripple of relative amplitude `ripple` at a short scale (the noise a
// chaotic simulation leaves).
struct Valley {
  UnitPoint c{0.3, 0.7, 0.62};
  double ripple = 0;
  int calls = 0, batches = 0;
  std::set<UnitPoint> asked;
  double operator()(const UnitPoint& u) const {
    const double q = 0.02 * (u[0] - c[0]) * (u[0] - c[0]) + 0.05 * (u[1] - c[1]) * (u[1] - c[1]) + 4.0 * (u[2] - c[2]) * (u[2] - c[2]);
    return 100.0 * (1.0 + q) * (1.0 + ripple * std::sin(157.0 * u[2]) * std::sin(91.0 * u[0] + 1.3));
  }
  tbsp::detail::BatchEnergy batch() {
    return [this](const std::vector<UnitPoint>& us) {
      ++batches;
      std::vector<double> e;
      for (const UnitPoint& u : us) {
        EXPECT_TRUE(asked.insert(u).second) << "a point was evaluated twice";
        for (double x : u) EXPECT_TRUE(x >= 0 && x <= 1);
        ++calls;
        e.push_back((*this)(u));
      }
      return e;
    };
  }
};

}  // namespace

TEST(ClothSearch, BobyqaFindsTheValleyFloorWithinItsBudget) {
  Valley v;
  MemoEnergy e(v.batch());
  const UnitPoint best = tbsp::detail::bobyqa_search(e, 8, 40, 0.01, 1);
  std::printf("valley: %d evaluations, E %.5f at (%.4f %.4f %.4f)\n", e.evaluations(), e.bestEnergy(), best[0], best[1], best[2]);
  EXPECT_LE(e.evaluations(), 40);
  EXPECT_EQ(e.evaluations(), v.calls);
  EXPECT_NEAR(best[2], v.c[2], 0.01);          // the steep axis to 1 % of the box
  EXPECT_LT(e.bestEnergy(), 100.0 * 1.0005);    // within 0.05 % of the minimum
  EXPECT_EQ(e.bestEnergy(), v(best));
}

TEST(ClothSearch, ThesisSearchSpendsItsSamplesAndReturnsTheMeanParticle) {
  Valley v;
  MemoEnergy e(v.batch());
  const UnitPoint mean = tbsp::detail::thesis_search(e, 4, 192, 1, 2);
  EXPECT_EQ(e.evaluations(), v.calls);
  EXPECT_GE(e.evaluations(), 64 + 150);  // grid + greedy draws (clamped duplicates are memoized)
  EXPECT_LE(e.evaluations(), 64 + 192);
  EXPECT_NEAR(mean[2], v.c[2], 0.03);
  // the greedy phase improves on the grid's best (the grid's k_bend cells are 0.125 from 0.62)
  EXPECT_LT(e.bestEnergy(), v(UnitPoint{0.375, 0.625, 0.625}));
}

// With a ±1 % ripple on the valley, ours ends within the ripple of the true floor in ≤ 40
// evaluations, as low as the thesis search's best in 256, and the same seed gives the same points.
TEST(ClothSearch, OnARippledValleyOursIsAsLowAsTheThesisSearchInFarFewerEvaluations) {
  Valley a;
  a.ripple = 0.01;
  MemoEnergy ea(a.batch());
  const UnitPoint ours = tbsp::detail::bobyqa_search(ea, 8, 40, 0.01, 3);
  Valley b;
  b.ripple = 0.01;
  MemoEnergy eb(b.batch());
  tbsp::detail::thesis_search(eb, 4, 192, 3, 2);
  std::printf("rippled valley: ours %d evaluations, E %.4f at (%.3f %.3f %.3f); thesis %d, best E %.4f\n", ea.evaluations(), ea.bestEnergy(),
              ours[0], ours[1], ours[2], eb.evaluations(), eb.bestEnergy());
  EXPECT_LE(ea.evaluations(), 40);
  EXPECT_GT(eb.evaluations(), 5 * ea.evaluations());
  EXPECT_LT(ea.bestEnergy(), 100.0 * 1.01);
  EXPECT_NEAR(ours[2], a.c[2], 0.05);
  EXPECT_LT(ea.bestEnergy(), eb.bestEnergy() * 1.005);
  Valley c;
  c.ripple = 0.01;
  MemoEnergy ec(c.batch());
  const UnitPoint again = tbsp::detail::bobyqa_search(ec, 8, 40, 0.01, 3);
  EXPECT_EQ(again, ours);
  EXPECT_EQ(c.asked, a.asked);
}

TEST(ClothSearch, MemoAnswersRepeatedPointsAndErrorsPropagate) {
  int calls = 0;
  MemoEnergy e([&](const std::vector<UnitPoint>& us) {
    calls += int(us.size());
    return std::vector<double>(us.size(), 1.0);
  });
  e(std::vector<UnitPoint>{{0.1, 0.2, 0.3}, {0.1, 0.2, 0.3}, {0.4, 0.5, 0.6}});
  e(UnitPoint{0.4, 0.5, 0.6});
  EXPECT_EQ(calls, 2);
  EXPECT_EQ(e.evaluations(), 2);
  EXPECT_EQ(e.best(), (UnitPoint{0.1, 0.2, 0.3}));  // the first of equal energies
  MemoEnergy bad([](const std::vector<UnitPoint>& us) -> std::vector<double> {
    if (us.size() == 1) throw std::runtime_error("simulation failed");
    return std::vector<double>(us.size(), 1.0);
  });
  EXPECT_THROW(tbsp::detail::bobyqa_search(bad, 8, 40, 0.01, 1), std::runtime_error);
}
