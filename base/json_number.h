// JSON numbers that may be undefined: JSON has no NaN or infinity, so a non-finite double is
// written as null and null is read back as NaN (the reports of evaluate/, docs/evaluation.md).
#pragma once

#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>

namespace handdb {

inline nlohmann::json NumberOrNull(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

inline double NumberOrNaN(const nlohmann::json& j) {
  return j.is_null() ? std::numeric_limits<double>::quiet_NaN() : j.get<double>();
}

}  // namespace handdb
