#include "supernodal_solve.h"

#include <algorithm>
#include <exception>

#ifdef _OPENMP
#include <omp.h>
#endif

// The kernels are compiled twice, for x86-64-v3 (AVX2 + FMA) and the baseline, and the loader
// picks one per machine (GCC function multi-versioning): the loops are compute-bound on the
// baseline's 2-wide SSE2. Fused multiply-adds round differently, so results agree across
// machines to rounding, bit for bit on one machine. -DTBSP_NO_KERNEL_CLONES builds the baseline
// only (the results of a CPU without AVX2).
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__) && !defined(TBSP_NO_KERNEL_CLONES)
#define TBSP_KERNEL_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#define TBSP_INLINE __attribute__((always_inline)) inline
#else
#define TBSP_KERNEL_CLONES
#define TBSP_INLINE inline
#endif

namespace tbsp {
namespace detail {

namespace {

// Y: the permuted right-hand sides, row-major n x K (one row of L's order per unknown).
// G: one supernode's rows gathered column by column (G + c*m is right-hand side c, m = the
// supernode's row count), so the inner loops run over contiguous factor and G entries and
// vectorize: an axpy per column forwards, a dot product per column backwards.

// out[c] = sum over i in [from, to) of col[i] * G[c*m + i], for the K right-hand sides at once:
// one pass over the column with independent accumulators (vectorized; a fixed order, so the same
// input gives the same bits).
template <int K>
TBSP_INLINE void column_dots(const double* col, const double* G, std::ptrdiff_t m, int from, int to, double* out) {
  if constexpr (K == 3) {
    const double *g0 = G, *g1 = G + m, *g2 = G + 2 * m;
    double s0 = 0, s1 = 0, s2 = 0;
#pragma omp simd reduction(+ : s0, s1, s2)
    for (int i = from; i < to; ++i) {
      s0 += col[i] * g0[i];
      s1 += col[i] * g1[i];
      s2 += col[i] * g2[i];
    }
    out[0] = s0, out[1] = s1, out[2] = s2;
  } else if constexpr (K == 1) {
    double s0 = 0, s1 = 0;
    int i = from;
#pragma omp simd reduction(+ : s0, s1)
    for (int h = 0; h < (to - from) / 2; ++h) {
      s0 += col[from + 2 * h] * G[from + 2 * h];
      s1 += col[from + 2 * h + 1] * G[from + 2 * h + 1];
    }
    i = from + 2 * ((to - from) / 2);
    if (i < to) s0 += col[i] * G[i];
    out[0] = s0 + s1;
  } else {
    for (int c = 0; c < K; ++c) {
      const double* g = G + c * m;
      double s = 0;
#pragma omp simd reduction(+ : s)
      for (int i = from; i < to; ++i) s += col[i] * g[i];
      out[c] = s;
    }
  }
}

// One supernode's columns k1 .. k1 + nscol - 1, its m row indices (its own columns first) and
// its column-major m x nscol value block.
struct Supernode {
  Supernode(const SupernodalFactorView& L, int sn)
      : k1(L.super[sn]), nscol(L.super[sn + 1] - L.super[sn]), m(L.pi[sn + 1] - L.pi[sn]), rows(L.s + L.pi[sn]),
        blk(L.x + L.px[sn]) {}
  int k1, nscol, m;
  const int* rows;
  const double* blk;
};

// Forward step of one supernode: solve its diagonal block, then subtract its columns from its
// rows below. Those updates go to Y, or to `buf` (row top[r]) when the row belongs to the top
// of the tree that two parts share.
template <int K>
TBSP_INLINE void forward_supernode(const SupernodalFactorView& L, int sn, double* Y, double* G, int k, const int* top,
                       double* buf) {
  const Supernode S(L, sn);
  const int k1 = S.k1, nscol = S.nscol, m = S.m;
  const int* rows = S.rows;
  const double* blk = S.blk;
  for (int c = 0; c < k; ++c) {
    double* g = G + std::ptrdiff_t(c) * m;
    for (int i = 0; i < nscol; ++i) g[i] = Y[std::ptrdiff_t(k1 + i) * k + c];
    std::fill(g + nscol, g + m, 0.0);
  }
  for (int j = 0; j < nscol; ++j) {
    const double* col = blk + std::ptrdiff_t(j) * m;
    if constexpr (K > 0) {
      // one pass over the column updates all K right-hand sides
      double gj[K];
      double* g[K];
      for (int c = 0; c < K; ++c) {
        g[c] = G + std::ptrdiff_t(c) * m;
        gj[c] = g[c][j] /= col[j];
      }
#pragma omp simd
      for (int i = j + 1; i < m; ++i)
        for (int c = 0; c < K; ++c) g[c][i] -= col[i] * gj[c];
    } else {
      for (int c = 0; c < k; ++c) {
        double* g = G + std::ptrdiff_t(c) * m;
        const double gj = g[j] /= col[j];
        for (int i = j + 1; i < m; ++i) g[i] -= col[i] * gj;
      }
    }
  }
  for (int c = 0; c < k; ++c) {
    const double* g = G + std::ptrdiff_t(c) * m;
    for (int i = 0; i < nscol; ++i) Y[std::ptrdiff_t(k1 + i) * k + c] = g[i];
  }
  for (int i = nscol; i < m; ++i) {  // g holds -sum_j L(i, j) y_j
    const int r = rows[i];
    double* dst = buf && top[r] >= 0 ? buf + std::ptrdiff_t(top[r]) * k : Y + std::ptrdiff_t(r) * k;
    for (int c = 0; c < k; ++c) dst[c] += G[std::ptrdiff_t(c) * m + i];
  }
}

// Backward step of one supernode: its rows below are final; solve for its own columns.
template <int K>
TBSP_INLINE void backward_supernode(const SupernodalFactorView& L, int sn, double* Y, double* G, int k) {
  const Supernode S(L, sn);
  const int k1 = S.k1, nscol = S.nscol, m = S.m;
  const int* rows = S.rows;
  const double* blk = S.blk;
  for (int c = 0; c < k; ++c) {
    double* g = G + std::ptrdiff_t(c) * m;
    for (int i = nscol; i < m; ++i) g[i] = Y[std::ptrdiff_t(rows[i]) * k + c];
  }
  // the rows below the diagonal block, columns in memory order (streams the factor):
  // g[j] = y[j] - L(below, j)ᵀ x(below)
  for (int j = 0; j < nscol; ++j) {
    const double* col = blk + std::ptrdiff_t(j) * m;
    if constexpr (K > 0) {
      double out[K];
      column_dots<K>(col, G, m, nscol, m, out);
      for (int c = 0; c < K; ++c) G[std::ptrdiff_t(c) * m + j] = Y[std::ptrdiff_t(k1 + j) * K + c] - out[c];
    } else {
      for (int c = 0; c < k; ++c) {
        const double* g = G + std::ptrdiff_t(c) * m;
        double sum = 0;
        for (int i = nscol; i < m; ++i) sum += col[i] * g[i];
        G[std::ptrdiff_t(c) * m + j] = Y[std::ptrdiff_t(k1 + j) * k + c] - sum;
      }
    }
  }
  // the diagonal block's triangle, last column first
  for (int j = nscol - 1; j >= 0; --j) {
    const double* col = blk + std::ptrdiff_t(j) * m;
    if constexpr (K > 0) {
      double out[K];
      column_dots<K>(col, G, m, j + 1, nscol, out);
      for (int c = 0; c < K; ++c) G[std::ptrdiff_t(c) * m + j] = (G[std::ptrdiff_t(c) * m + j] - out[c]) / col[j];
    } else {
      for (int c = 0; c < k; ++c) {
        double* g = G + std::ptrdiff_t(c) * m;
        double sum = 0;
        for (int i = j + 1; i < nscol; ++i) sum += col[i] * g[i];
        g[j] = (g[j] - sum) / col[j];
      }
    }
  }
  for (int c = 0; c < k; ++c) {
    const double* g = G + std::ptrdiff_t(c) * m;
    for (int i = 0; i < nscol; ++i) Y[std::ptrdiff_t(k1 + i) * k + c] = g[i];
  }
}

// The supernodes of one list, forwards (in order) or backwards (in reverse), for k right-hand
// sides: the unit compiled per instruction set.
TBSP_KERNEL_CLONES void forward_list(const SupernodalFactorView& L, const std::vector<int>& list, double* Y, double* G,
                                     int k, const int* top, double* buf) {
  switch (k) {
    case 1: for (int sn : list) forward_supernode<1>(L, sn, Y, G, k, top, buf); break;
    case 2: for (int sn : list) forward_supernode<2>(L, sn, Y, G, k, top, buf); break;
    case 3: for (int sn : list) forward_supernode<3>(L, sn, Y, G, k, top, buf); break;
    default: for (int sn : list) forward_supernode<0>(L, sn, Y, G, k, top, buf); break;
  }
}

TBSP_KERNEL_CLONES void backward_list(const SupernodalFactorView& L, const std::vector<int>& list, double* Y, double* G,
                                      int k) {
  switch (k) {
    case 1: for (auto it = list.rbegin(); it != list.rend(); ++it) backward_supernode<1>(L, *it, Y, G, k); break;
    case 2: for (auto it = list.rbegin(); it != list.rend(); ++it) backward_supernode<2>(L, *it, Y, G, k); break;
    case 3: for (auto it = list.rbegin(); it != list.rend(); ++it) backward_supernode<3>(L, *it, Y, G, k); break;
    default: for (auto it = list.rbegin(); it != list.rend(); ++it) backward_supernode<0>(L, *it, Y, G, k); break;
  }
}

// Runs f(0) and f(1), on two threads when allowed; exceptions (none are expected from the
// kernels) are not allowed to cross the OpenMP region.
template <class F>
void run_two(bool threads, F&& f) {
#ifdef _OPENMP
  if (threads && !omp_in_parallel() && omp_get_max_threads() > 1) {
#pragma omp parallel num_threads(2)
    {
      const int t = omp_get_thread_num();
      if (omp_get_num_threads() < 2) {
        f(0);
        f(1);
      } else if (t < 2) {
        f(t);
      }
    }
    return;
  }
#endif
  (void)threads;
  f(0);
  f(1);
}

void solve_parts(const SupernodalFactorView& L, const SupernodalPlan& plan, int k, double* Y, double* work,
                 bool threads) {
  const int ntop = plan.top_rows;
  const std::ptrdiff_t gsize = std::ptrdiff_t(L.max_rows) * k;
  double* G[2] = {work, work + gsize};
  double* buf[2] = {work + 2 * gsize, work + 2 * gsize + std::ptrdiff_t(ntop) * k};
  // forward: the two parts (independent subtrees) side by side, their updates of the shared
  // top rows kept apart and added in a fixed order; then the top
  run_two(threads, [&](int p) {
    std::fill(buf[p], buf[p] + std::ptrdiff_t(ntop) * k, 0.0);
    forward_list(L, plan.part[p], Y, G[p], k, plan.top_index.data(), buf[p]);
  });
  for (int p = 0; p < 2; ++p)
    for (int t = 0; t < ntop; ++t)
      for (int c = 0; c < k; ++c) Y[std::ptrdiff_t(plan.top_row[std::size_t(t)]) * k + c] += buf[p][std::ptrdiff_t(t) * k + c];
  forward_list(L, plan.top, Y, G[0], k, nullptr, nullptr);
  // backward: the top, then the two parts side by side (they only read the top's rows)
  backward_list(L, plan.top, Y, G[0], k);
  run_two(threads, [&](int p) { backward_list(L, plan.part[p], Y, G[p], k); });
}

}  // namespace

SupernodalPlan make_supernodal_plan(const SupernodalFactorView& L) {
  SupernodalPlan plan;
  const int ns = L.nsuper;
  // supernodal elimination tree: the parent holds the first row below the diagonal block
  std::vector<int> owner(std::size_t(L.n), -1), parent(std::size_t(ns), -1);
  for (int sn = 0; sn < ns; ++sn)
    for (int c = L.super[sn]; c < L.super[sn + 1]; ++c) owner[std::size_t(c)] = sn;
  std::vector<std::vector<int>> children(static_cast<std::size_t>(ns));
  std::vector<int> roots;
  for (int sn = 0; sn < ns; ++sn) {
    const int nscol = L.super[sn + 1] - L.super[sn], m = L.pi[sn + 1] - L.pi[sn];
    if (m > nscol) {
      parent[std::size_t(sn)] = owner[std::size_t(L.s[L.pi[sn] + nscol])];
      children[std::size_t(parent[std::size_t(sn)])].push_back(sn);
    } else {
      roots.push_back(sn);
    }
  }
  // subtree work (stored values; children have smaller indices than their parent)
  std::vector<double> work(std::size_t(ns), 0.0);
  for (int sn = 0; sn < ns; ++sn) {
    work[std::size_t(sn)] += double(L.px[sn + 1] - L.px[sn]);
    if (parent[std::size_t(sn)] >= 0) work[std::size_t(parent[std::size_t(sn)])] += work[std::size_t(sn)];
  }
  // peel the heaviest subtree's root into the top until the remaining subtrees split into two
  // parts within 10 % of each other (largest first into the lighter part), or the top holds a
  // third of the work
  std::vector<char> in_top(std::size_t(ns), 0);
  std::vector<int> cand = roots;
  double total = 0, top_work = 0;
  for (int r : roots) total += work[std::size_t(r)];
  std::vector<int> assign;
  for (int round = 0; round < 4096; ++round) {
    std::sort(cand.begin(), cand.end(), [&](int a, int b) {
      return work[std::size_t(a)] != work[std::size_t(b)] ? work[std::size_t(a)] > work[std::size_t(b)] : a < b;
    });
    double bin[2] = {0, 0};
    assign.assign(cand.size(), 0);
    for (std::size_t i = 0; i < cand.size(); ++i) {
      const int b = bin[1] < bin[0] ? 1 : 0;
      assign[i] = b;
      bin[b] += work[std::size_t(cand[i])];
    }
    const double heavy = std::max(bin[0], bin[1]), sum = bin[0] + bin[1];
    if (cand.empty() || heavy <= 0.55 * sum || top_work > total / 3) break;
    const int r = cand.front();  // heaviest: peel its root
    const double own = double(L.px[r + 1] - L.px[r]);
    if (children[std::size_t(r)].empty()) break;
    in_top[std::size_t(r)] = 1;
    top_work += own;
    cand.erase(cand.begin());
    for (int ch : children[std::size_t(r)]) cand.push_back(ch);
  }
  // part membership by subtree (the candidates' descendants), in increasing supernode order
  std::vector<int> part_of(std::size_t(ns), -1);
  for (std::size_t i = 0; i < cand.size(); ++i) part_of[std::size_t(cand[i])] = assign.empty() ? 0 : assign[i];
  for (int sn = ns - 1; sn >= 0; --sn)
    if (part_of[std::size_t(sn)] < 0 && !in_top[std::size_t(sn)] && parent[std::size_t(sn)] >= 0)
      part_of[std::size_t(sn)] = part_of[std::size_t(parent[std::size_t(sn)])];
  plan.top_index.assign(std::size_t(L.n), -1);
  for (int sn = 0; sn < ns; ++sn) {
    if (in_top[std::size_t(sn)] || part_of[std::size_t(sn)] < 0) {
      plan.top.push_back(sn);
      for (int c = L.super[sn]; c < L.super[sn + 1]; ++c) {
        plan.top_index[std::size_t(c)] = int(plan.top_row.size());
        plan.top_row.push_back(c);
      }
    } else {
      plan.part[part_of[std::size_t(sn)]].push_back(sn);
    }
  }
  plan.top_rows = int(plan.top_row.size());
  return plan;
}

std::size_t supernodal_work_size(const SupernodalFactorView& L, const SupernodalPlan& plan, int K) {
  return (std::size_t(L.n) + 2 * std::size_t(L.max_rows) + 2 * std::size_t(plan.top_rows)) * std::size_t(K);
}

void supernodal_solve(const SupernodalFactorView& L, const SupernodalPlan& plan, int K, const double* B,
                      std::ptrdiff_t ldb, double* X, std::ptrdiff_t ldx, double* work, bool threads) {
  const int n = L.n;
  double* Y = work;
  double* rest = work + std::ptrdiff_t(n) * K;
  // Y = P B, interleaved
  for (int r = 0; r < n; ++r) {
    const std::ptrdiff_t src = L.perm[r];
    for (int c = 0; c < K; ++c) Y[std::ptrdiff_t(r) * K + c] = B[src + c * ldb];
  }
  solve_parts(L, plan, K, Y, rest, threads);
  // X = P' Y
  for (int r = 0; r < n; ++r) {
    const std::ptrdiff_t dst = L.perm[r];
    for (int c = 0; c < K; ++c) X[dst + c * ldx] = Y[std::ptrdiff_t(r) * K + c];
  }
}

}  // namespace detail
}  // namespace tbsp
