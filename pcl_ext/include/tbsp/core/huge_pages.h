#pragma once
/// \file huge_pages.h
/// \brief Transparent huge pages for the heap of a tbsp program (Linux, glibc ≥ 2.35).
///
/// A fresh process touches every page of its large allocations once (the Laplacian, the
/// Cholesky factor); where a page fault is expensive (virtual machines) that first touch is
/// half of a one-shot run: the deformation survey's 40k-vertex plane takes 0.73-0.80 s with
/// 4 KiB pages and 0.37-0.44 s with 2 MiB pages on the 2-core CI machine (docs/benchmarks.md).
/// glibc's malloc asks the kernel for transparent huge pages when the environment has
/// `GLIBC_TUNABLES=glibc.malloc.hugetlb=1`, read once at program start, so a program that wants
/// them re-executes itself with the tunable set (the benchmarks do), or is started by a program
/// that sets it: the `tbsp` command is a small launcher (libc and libstdc++ only) that sets the
/// tunable and executes the CLI proper, `tbsp-cli`, so that the CLI's ~300 shared libraries are
/// loaded once instead of twice (a re-executed `tbsp --help` took 1.3 s, 0.7 s of it the second
/// load). Library users can set the variable themselves (it changes no result, only page sizes).

namespace tbsp {

/// \brief Sets `glibc.malloc.hugetlb=1` in GLIBC_TUNABLES for programs this process executes
/// next, under the same conditions as reexec_with_huge_pages(). Returns true when it changed
/// the environment, false when nothing is needed or wanted (or setenv failed). It does not
/// change this process' own malloc (glibc reads the tunable once, at start).
bool request_huge_pages();

/// \brief At the start of main(): re-executes the program (/proc/self/exe, same argv and
/// environment) with `glibc.malloc.hugetlb=1` added to GLIBC_TUNABLES, unless it is set already,
/// the kernel's transparent huge pages mode is not `madvise` (`always` needs no asking, `never` gives none), or `TBSP_NO_HUGE_PAGES` is set (any value).
/// Returns only when nothing was re-executed (including when execv fails: the program simply
/// continues with normal pages). Not thread-safe: call it before starting threads.
void reexec_with_huge_pages(char** argv);

}  // namespace tbsp
