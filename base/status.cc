#include "base/status.h"

#include <iostream>

namespace handdb {

const char* StatusCodeName(StatusCode code) {
  switch (code) {
    case StatusCode::kOk:
      return "kOk";
    case StatusCode::kIoError:
      return "kIoError";
    case StatusCode::kNotFound:
      return "kNotFound";
    case StatusCode::kBadMagic:
      return "kBadMagic";
    case StatusCode::kUnsupportedVersion:
      return "kUnsupportedVersion";
    case StatusCode::kUnknownRequiredFeature:
      return "kUnknownRequiredFeature";
    case StatusCode::kTruncated:
      return "kTruncated";
    case StatusCode::kSizeMismatch:
      return "kSizeMismatch";
    case StatusCode::kChecksumMismatch:
      return "kChecksumMismatch";
    case StatusCode::kBadLayout:
      return "kBadLayout";
    case StatusCode::kOutOfRange:
      return "kOutOfRange";
    case StatusCode::kNonZeroReserved:
      return "kNonZeroReserved";
    case StatusCode::kBadJson:
      return "kBadJson";
    case StatusCode::kSchemaViolation:
      return "kSchemaViolation";
    case StatusCode::kBadImage:
      return "kBadImage";
    case StatusCode::kNoHand:
      return "kNoHand";
    case StatusCode::kExternalToolFailed:
      return "kExternalToolFailed";
    case StatusCode::kInvalidArgument:
      return "kInvalidArgument";
    case StatusCode::kCancelled:
      return "kCancelled";
  }
  return "kUnknown";
}

std::string Status::ToString() const {
  if (ok()) return "OK";
  return message_;
}

namespace internal {

void ThrowCheckFailure(const char* file, int line, const std::string& what) {
  std::ostringstream os;
  os << file << ":" << line << ": " << what;
  throw std::logic_error(os.str());
}

void LogOptionFailure(const char* file, int line, const char* cond) {
  std::cerr << file << ":" << line << ": option check failed: " << cond << "\n";
}

}  // namespace internal
}  // namespace handdb
