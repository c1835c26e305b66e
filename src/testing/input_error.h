#pragma once
// Test support for refusals: the one-line message of the InputError a call throws.
#include <string>

#include "core/error.h"

namespace sd::testing {

// What `fn` throws as an InputError, or "" when it throws none (other exceptions pass through).
template <typename Fn>
std::string InputErrorOf(Fn&& fn) {
  try {
    fn();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace sd::testing
