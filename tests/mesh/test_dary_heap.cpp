// detail::DaryMinHeap (pcl_ext/src/mesh/dary_heap.h): the pop sequence of std::priority_queue
// with std::greater, on which the Dijkstra searches' settle order (and so their predecessors) rests.
#include <gtest/gtest.h>

#include <functional>
#include <queue>
#include <random>
#include <tuple>
#include <utility>
#include <vector>

#include "dary_heap.h"

TEST(DaryMinHeap, PopsWhatStdPriorityQueuePopsIncludingTiesAndInterleavedPushes) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> key(0, 40), vertex(0, 9), op(0, 2);
  using Item = std::pair<double, int>;
  tbsp::detail::DaryMinHeap<Item> ours;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> ref;
  int popped = 0;
  for (int step = 0; step < 20000; ++step) {
    if (ref.empty() || op(rng) > 0) {  // pushes twice as often as pops: the heap grows, with
      const Item x{0.25 * key(rng), vertex(rng)};  // many equal distances and duplicate items
      ours.push(x);
      ref.push(x);
    } else {
      ASSERT_EQ(ours.top(), ref.top()) << "step " << step;
      ours.pop();
      ref.pop();
      ++popped;
    }
    ASSERT_EQ(ours.size(), ref.size());
  }
  while (!ref.empty()) {
    ASSERT_EQ(ours.top(), ref.top());
    ours.pop();
    ref.pop();
  }
  EXPECT_TRUE(ours.empty());
  EXPECT_GT(popped, 5000);
  // tuples, as the deformation graph's multi-label search uses them
  tbsp::detail::DaryMinHeap<std::tuple<double, int, int>> t;
  t.push({1.0, 3, 2});
  t.push({1.0, 3, 1});
  t.push({0.5, 9, 0});
  t.emplace(1.0, 2, 7);
  EXPECT_EQ(t.top(), std::make_tuple(0.5, 9, 0));
  t.pop();
  EXPECT_EQ(t.top(), std::make_tuple(1.0, 2, 7));
  t.pop();
  EXPECT_EQ(t.top(), std::make_tuple(1.0, 3, 1));
}
