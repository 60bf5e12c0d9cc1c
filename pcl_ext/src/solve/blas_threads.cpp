#include "tbsp/solve/blas_threads.h"

#include <dlfcn.h>

namespace tbsp {

namespace {
using SetFn = void (*)(int);
using GetFn = int (*)();
SetFn set_fn() { return reinterpret_cast<SetFn>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads")); }
GetFn get_fn() { return reinterpret_cast<GetFn>(dlsym(RTLD_DEFAULT, "openblas_get_num_threads")); }
}  // namespace

ScopedBlasThreads::ScopedBlasThreads(int threads) {
  const SetFn set = set_fn();
  const GetFn get = get_fn();
  if (!set || !get || threads < 1) return;
  previous_ = get();
  if (previous_ < 1) { previous_ = 0; return; }
  if (previous_ != threads) set(threads);
}

ScopedBlasThreads::~ScopedBlasThreads() {
  if (previous_ < 1) return;
  if (const SetFn set = set_fn()) set(previous_);
}

}  // namespace tbsp
