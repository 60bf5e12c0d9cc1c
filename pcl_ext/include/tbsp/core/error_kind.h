#pragma once
/// \file error_kind.h
/// \brief tbsp's exceptions (error.h) carried between processes: a kind number and the message
/// go over the wire, and the receiver throws the same type with the same message
/// (ClothWorkShare, `tbsp cloth estimate` under mpirun).

#include <exception>
#include <string>

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

}  // namespace tbsp
