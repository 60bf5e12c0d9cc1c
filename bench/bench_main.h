#pragma once
// main() of tbsp's Google Benchmark programs: huge pages for the heap, as the tbsp CLI
// (tbsp/core/huge_pages.h; run with TBSP_NO_HUGE_PAGES=1 to compare), then the benchmarks.
#include <benchmark/benchmark.h>

#include "tbsp/core/huge_pages.h"

#define TBSP_BENCHMARK_MAIN()                                               \
  int main(int argc, char** argv) {                                         \
    tbsp::reexec_with_huge_pages(argv);                                     \
    benchmark::Initialize(&argc, argv);                                     \
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;       \
    benchmark::RunSpecifiedBenchmarks();                                    \
    benchmark::Shutdown();                                                  \
    return 0;                                                               \
  }
