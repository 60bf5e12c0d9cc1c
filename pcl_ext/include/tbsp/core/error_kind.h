#pragma once
/// \file error_kind.h
/// \brief tbsp's exceptions (error.h) carried between processes: a kind number and the message
/// go over the wire, and the receiver throws the same type with the same message
/// (ClothWorkShare, `tbsp cloth estimate` under mpirun).

#include <cstddef>
#include <exception>
#include <functional>
#include <string>
#include <vector>

#include "tbsp/core/error.h"

namespace tbsp {

/// An exception's kind as a small number, to send to another process (ClothWorkShare, `tbsp
/// cloth estimate` under mpirun): 0 none (null), 1 any other, 2 InvalidInput (FileError
/// included), 3 NumericalFailure, 4 Cancelled.
inline int error_kind(const std::exception_ptr& e) {
  if (!e) return 0;
  try {
    std::rethrow_exception(e);
  } catch (const Cancelled&) {
    return 4;
  } catch (const InvalidInput&) {
    return 2;
  } catch (const NumericalFailure&) {
    return 3;
  } catch (...) {
    return 1;
  }
}

/// The exit code of the tbsp CLI for an exception (docs/errors.md): 2 invalid input, 3
/// numerical failure, 130 cancelled, 1 anything else; 0 for none (null).
inline int exit_code_of(const std::exception_ptr& e) {
  switch (error_kind(e)) {
    case 0: return 0;
    case 2: return 2;
    case 3: return 3;
    case 4: return 130;
    default: return 1;
  }
}

/// The message of an exception (what(); "unknown error" for one not derived from std::exception).
inline std::string error_message(const std::exception_ptr& e) {
  try {
    std::rethrow_exception(e);
  } catch (const std::exception& x) {
    return x.what();
  } catch (...) {
    return "unknown error";
  }
}

/// The exception of `kind` (error_kind; 1 and unknown kinds: tbsp::Error) with `message`: an
/// error another process threw, to be thrown here with the same type.
inline std::exception_ptr error_of_kind(int kind, const std::string& message) {
  switch (kind) {
    case 4: return std::make_exception_ptr(Cancelled(message));
    case 2: return std::make_exception_ptr(InvalidInput(message));
    case 3: return std::make_exception_ptr(NumericalFailure(message));
    default: return std::make_exception_ptr(Error(message));
  }
}

/// One process's error, thrown alike on every process. Collective: every process calls it at the
/// same point with the same `kind` (error_kind of the error; already agreed, e.g. through `sum`);
/// `mine` is the error on the process that had it (`owner`), ignored elsewhere. Its message
/// travels through `sum` — an elementwise sum over the processes (MPI_Allreduce with MPI_SUM) —
/// as character codes (at most `max_chars` − 1 of them). Returns the exception of `kind` with
/// `prefix` + that message: the same on every process.
inline std::exception_ptr share_error(int kind, bool owner, const std::exception_ptr& mine, const std::function<void(std::vector<double>&)>& sum,
                                      const std::string& prefix = "", std::size_t max_chars = 2048) {
  std::vector<double> text(max_chars, 0.0);
  if (owner) {
    const std::string m = error_message(mine);
    for (std::size_t i = 0; i < m.size() && i + 1 < max_chars; ++i) text[i] = double(static_cast<unsigned char>(m[i]));
  }
  sum(text);
  std::string msg = prefix;
  for (double c : text) {
    if (c == 0) break;
    msg += char(static_cast<unsigned char>(c));
  }
  return error_of_kind(kind, msg);
}

}  // namespace tbsp
