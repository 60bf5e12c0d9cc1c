#pragma once
/// \file error.h
/// \brief The one error policy of tbsp (see docs/errors.md).
///
/// - Programmer errors and invalid data throw tbsp::InvalidInput; the message names the
///   method (`[tbsp::Class::method]`), the offending item and how to fix it.
/// - File problems throw tbsp::FileError (a kind of InvalidInput) naming the file and line.
/// - Solver failures throw tbsp::NumericalFailure with the reason; never silent.
/// - A user cancel (progress callback returned false) throws tbsp::Cancelled.
/// Outputs passed by reference are left untouched when any of these is thrown.

#include <exception>
#include <stdexcept>
#include <string>
#include <vector>

namespace tbsp {

/// Base class of every exception thrown by tbsp.
class Error : public std::runtime_error {
public:
  explicit Error(const std::string& what) : std::runtime_error(what) {}
};

/// Invalid argument or input data (bad index, empty cloud, NaN coordinates, ...).
class InvalidInput : public Error {
public:
  explicit InvalidInput(const std::string& what) : Error(what) {}
};

/// A file could not be read or written, or is malformed. The message names the file
/// (and the line or byte offset where known).
class FileError : public InvalidInput {
public:
  explicit FileError(const std::string& what) : InvalidInput(what) {}
};

/// A numerical method failed (factorization not positive definite, non-finite result).
class NumericalFailure : public Error {
public:
  explicit NumericalFailure(const std::string& what) : Error(what) {}
};

/// The operation was cancelled through its progress callback.
class Cancelled : public Error {
public:
  explicit Cancelled(const std::string& what = "operation cancelled") : Error(what) {}
};

/// Of the errors of parallel workers (null: the worker finished), the one to report: the first
/// that is not Cancelled (a worker stopped because another failed reports Cancelled), else the
/// first Cancelled; null when there is none.
inline std::exception_ptr first_real_error(const std::vector<std::exception_ptr>& errors) {
  std::exception_ptr cancelled;
  for (const auto& e : errors) {
    if (!e) continue;
    try {
      std::rethrow_exception(e);
    } catch (const Cancelled&) {
      if (!cancelled) cancelled = e;
    } catch (...) {
      return e;
    }
  }
  return cancelled;
}

}  // namespace tbsp
