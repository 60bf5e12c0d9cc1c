#pragma once
// Internal: a 4-ary min-heap for the Dijkstra searches (geodesics, deformation-graph binding).
//
// Pops the same sequence as std::priority_queue<T, std::vector<T>, std::greater<T>> for items
// that are totally ordered by operator< (distinct items compare unequal; equal items are
// interchangeable), so a search's settle order, and with it every distance and predecessor,
// is unchanged. Four children per node halve the depth of a binary heap and keep a node's
// children in one or two cache lines: fewer, cheaper levels per push and pop.

#include <cstddef>
#include <utility>
#include <vector>

namespace tbsp {
namespace detail {

template <typename T>
class DaryMinHeap {
 public:
  bool empty() const { return v_.empty(); }
  std::size_t size() const { return v_.size(); }
  const T& top() const { return v_.front(); }
  void reserve(std::size_t n) { v_.reserve(n); }
  void push(const T& x) {
    std::size_t i = v_.size();
    v_.push_back(x);
    while (i > 0) {
      const std::size_t p = (i - 1) / kD;
      if (!(x < v_[p])) break;
      v_[i] = v_[p];
      i = p;
    }
    v_[i] = x;
  }
  template <typename... A>
  void emplace(A&&... a) { push(T(std::forward<A>(a)...)); }
  void pop() {
    const T last = v_.back();
    v_.pop_back();
    const std::size_t n = v_.size();
    if (n == 0) return;
    std::size_t i = 0;
    for (;;) {
      const std::size_t c0 = kD * i + 1;
      if (c0 >= n) break;
      std::size_t best = c0;
      const std::size_t c_end = c0 + kD < n ? c0 + kD : n;
      for (std::size_t c = c0 + 1; c < c_end; ++c)
        if (v_[c] < v_[best]) best = c;
      if (!(v_[best] < last)) break;
      v_[i] = v_[best];
      i = best;
    }
    v_[i] = last;
  }

 private:
  static constexpr std::size_t kD = 4;
  std::vector<T> v_;
};

}  // namespace detail
}  // namespace tbsp
