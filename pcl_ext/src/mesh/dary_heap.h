#pragma once
// Internal: the min-heap of the Dijkstra searches (geodesics, deformation-graph binding):
// Boost.Heap's 4-ary heap (Boost comes with PCL).
//
// It pops the same sequence as std::priority_queue<T, std::vector<T>, std::greater<T>> for items
// that are totally ordered by operator< (distinct items compare unequal; equal items are
// interchangeable), so a search's settle order, and with it every distance and predecessor, is
// unchanged. Four children per node halve the depth of a binary heap and keep a node's children
// in one or two cache lines (41k-vertex searches 1.6-1.9 x faster, docs/dev/fitting_experiments.md).

#include <boost/heap/d_ary_heap.hpp>
#include <functional>

namespace tbsp {
namespace detail {

template <typename T>
using DaryMinHeap = boost::heap::d_ary_heap<T, boost::heap::arity<4>, boost::heap::compare<std::greater<T>>>;

}  // namespace detail
}  // namespace tbsp
