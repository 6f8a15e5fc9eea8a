// Two error tiers (docs/conventions.md "Errors and CLI"):
//  - THROW_CHECK*: a broken precondition in our own code -> throws std::logic_error with file:line.
//  - Status / Result<T>: bad bytes or bad files from outside -> a specific code and a message
//    naming the file, the offset and the raw values seen.
//    Never abort on outside input.
#pragma once

#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <variant>

namespace handdb {

enum class StatusCode {
  kOk = 0,
  kIoError,                 // open/read/write/fsync/rename failed (errno text in message)
  kNotFound,                // a file or directory that must exist does not
  kBadMagic,                // leading or trailing magic wrong
  kUnsupportedVersion,      // major version newer than this reader
  kUnknownRequiredFeature,  // a required-feature bit or required section this reader does not know
  kTruncated,               // fewer bytes than the structure claims
  kSizeMismatch,            // sizes/counts disagree with each other
  kChecksumMismatch,        // stored and computed checksums differ
  kBadLayout,               // overlap, hole, misalignment, non-monotonic offsets
  kOutOfRange,              // a value outside its documented range (coordinates, labels, ids)
  kNonZeroReserved,         // a reserved field is not zero
  kBadJson,                 // unparsable JSON
  kSchemaViolation,         // JSON that does not match its schema
  kBadImage,                // unreadable image / wrong channels / wrong size
  kNoHand,                  // an image in which no hand was found
  kExternalToolFailed,      // Blender or another subprocess failed
  kInvalidArgument,         // a bad user-supplied option value
  kCancelled,
};

const char* StatusCodeName(StatusCode code);

class Status {
 public:
  Status() = default;
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}
  static Status Ok() { return Status(); }

  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }
  // "kChecksumMismatch: shard-00003.hdb: section 'points' ..."
  std::string ToString() const;

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value) : value_(std::move(value)) {}         // NOLINT(google-explicit-constructor)
  Result(Status status) : status_(std::move(status)) {  // NOLINT(google-explicit-constructor)
    if (status_.ok())
      throw std::logic_error("Result constructed from an OK status without a value");
  }
  bool ok() const { return value_.has_value(); }
  const Status& status() const { return status_; }
  T& value() & { return checked(); }
  const T& value() const& { return const_cast<Result*>(this)->checked(); }
  T&& value() && { return std::move(checked()); }
  T* operator->() { return &checked(); }
  const T* operator->() const { return &const_cast<Result*>(this)->checked(); }
  T& operator*() { return checked(); }
  // The value, or `fallback` when this holds an error (the error is dropped).
  T value_or(T fallback) && { return value_ ? std::move(*value_) : std::move(fallback); }

 private:
  T& checked() {
    if (!value_) throw std::logic_error("Result::value() on an error: " + status_.ToString());
    return *value_;
  }
  std::optional<T> value_;
  Status status_;
};

namespace internal {
[[noreturn]] void ThrowCheckFailure(const char* file, int line, const std::string& what);
}  // namespace internal

}  // namespace handdb

#define THROW_CHECK(cond)                                                                \
  do {                                                                                   \
    if (!(cond))                                                                         \
      ::handdb::internal::ThrowCheckFailure(__FILE__, __LINE__, "Check failed: " #cond); \
  } while (0)

#define THROW_CHECK_MSG(cond, msg)                                                       \
  do {                                                                                   \
    if (!(cond)) {                                                                       \
      std::ostringstream handdb_check_os_;                                               \
      handdb_check_os_ << "Check failed: " #cond ": " << msg;                            \
      ::handdb::internal::ThrowCheckFailure(__FILE__, __LINE__, handdb_check_os_.str()); \
    }                                                                                    \
  } while (0)

#define THROW_CHECK_OP(a, op, b) \
  THROW_CHECK_MSG((a)op(b), #a " " #op " " #b " (" << (a) << " vs " << (b) << ")")
#define THROW_CHECK_EQ(a, b) THROW_CHECK_OP(a, ==, b)
#define THROW_CHECK_NE(a, b) THROW_CHECK_OP(a, !=, b)
#define THROW_CHECK_LT(a, b) THROW_CHECK_OP(a, <, b)
#define THROW_CHECK_LE(a, b) THROW_CHECK_OP(a, <=, b)
#define THROW_CHECK_GT(a, b) THROW_CHECK_OP(a, >, b)
#define THROW_CHECK_GE(a, b) THROW_CHECK_OP(a, >=, b)

// For Options::Check(): logs the failing rule to stderr and returns false.
#define CHECK_OPTION(cond)                                             \
  do {                                                                 \
    if (!(cond)) {                                                     \
      ::handdb::internal::LogOptionFailure(__FILE__, __LINE__, #cond); \
      return false;                                                    \
    }                                                                  \
  } while (0)
#define CHECK_OPTION_GT(a, b) CHECK_OPTION((a) > (b))
#define CHECK_OPTION_GE(a, b) CHECK_OPTION((a) >= (b))
#define CHECK_OPTION_LE(a, b) CHECK_OPTION((a) <= (b))
#define CHECK_OPTION_LT(a, b) CHECK_OPTION((a) < (b))

namespace handdb::internal {
void LogOptionFailure(const char* file, int line, const char* cond);
}  // namespace handdb::internal

// Propagate an error Status from an expression returning Status.
#define HANDDB_RETURN_IF_ERROR(expr)                 \
  do {                                               \
    ::handdb::Status handdb_status_ = (expr);        \
    if (!handdb_status_.ok()) return handdb_status_; \
  } while (0)
