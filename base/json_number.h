// JSON numbers: ones that may be undefined, and integers narrowed to a field's C++ type.
//
// JSON has no NaN or infinity, so a non-finite double is written as null and null is read back as
// NaN (the reports of evaluate/, docs/evaluation.md).
//
// nlohmann's get<uint32_t>() casts without a check (2^32 + 12 reads as 12), and an integer of
// 2^64 or more parses as a double that a schema's "integer" accepts (and that get<uint64_t>()
// turns into anything). Every reader narrows through JsonInteger instead, so an integer outside
// its field's type is refused with the raw value rather than silently wrapped.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>

#include "base/status.h"

namespace handdb {

inline nlohmann::json NumberOrNull(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

inline double NumberOrNaN(const nlohmann::json& j) {
  return j.is_null() ? std::numeric_limits<double>::quiet_NaN() : j.get<double>();
}

// True when `j` holds an integer that T represents exactly. A float (1e3, 2^64 parsed as a
// double) is not an integer here even when integral: our writers never write integers as floats.
template <typename T>
bool JsonIntegerFits(const nlohmann::json& j) {
  static_assert(std::is_integral_v<T> && !std::is_same_v<T, bool>);
  if (j.is_number_unsigned()) {
    return j.get<uint64_t>() <= static_cast<uint64_t>(std::numeric_limits<T>::max());
  }
  if (j.is_number_integer()) {
    const int64_t v = j.get<int64_t>();
    if constexpr (std::is_signed_v<T>) {
      return v >= static_cast<int64_t>(std::numeric_limits<T>::min()) &&
             v <= static_cast<int64_t>(std::numeric_limits<T>::max());
    } else {
      return v >= 0 &&
             static_cast<uint64_t>(v) <= static_cast<uint64_t>(std::numeric_limits<T>::max());
    }
  }
  return false;
}

// "<field> is <raw>, not an integer in <min>..<max>" (the raw value cut to 60 characters).
template <typename T>
std::string JsonIntegerRangeMessage(const nlohmann::json& j, std::string_view field) {
  std::string raw = j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  if (raw.size() > 60) raw = raw.substr(0, 57) + "...";
  return std::string(field) + " is " + raw + ", not an integer in " +
         std::to_string(std::numeric_limits<T>::min()) + ".." +
         std::to_string(std::numeric_limits<T>::max());
}

// The integer `j` as T, or kOutOfRange "<what>: <field> is <raw>, not an integer in lo..hi".
template <typename T>
Result<T> JsonInteger(const nlohmann::json& j, const std::string& what, std::string_view field) {
  if (!JsonIntegerFits<T>(j)) {
    return Status(StatusCode::kOutOfRange, what + ": " + JsonIntegerRangeMessage<T>(j, field));
  }
  return j.get<T>();
}

// The same for readers that parse many fields inside one try block: throws JsonRangeError, whose
// what() is "<field> is <raw>, not an integer in lo..hi".
class JsonRangeError : public std::out_of_range {
 public:
  using std::out_of_range::out_of_range;
};

template <typename T>
T JsonIntegerOrThrow(const nlohmann::json& j, std::string_view field) {
  if (!JsonIntegerFits<T>(j)) throw JsonRangeError(JsonIntegerRangeMessage<T>(j, field));
  return j.get<T>();
}

}  // namespace handdb
