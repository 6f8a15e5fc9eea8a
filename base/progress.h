// A progress line on stderr for long work: "convert  1234/2236  55%  812 views/s  ETA 0:01".
// Redrawn in place on a terminal, printed every few seconds otherwise (CI logs), silent when
// disabled. Thread-safe: workers call Add() concurrently.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace handdb {

// Seconds of steady-clock time since `since`: how long work took (reports, query statistics).
inline double SecondsSince(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

class Progress {
 public:
  Progress(std::string label, uint64_t total, bool enabled = true, std::string unit = "items");
  ~Progress();  // prints the final line
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  // For work that is usually short (one query): nothing is drawn before `since` + 1 s on a
  // terminal or + 5 s otherwise (the normal cadence), and no final line unless a line was drawn,
  // so a fast run prints nothing and a slow one shows it is alive. `since` may be earlier than
  // this object (the start of the whole command).
  void QuietUnlessSlow(std::chrono::steady_clock::time_point since);

  void Add(uint64_t n = 1);
  void SetTotal(uint64_t total);
  void Finish();
  uint64_t done() const { return done_.load(); }

 private:
  void Draw(bool final);
  std::string label_;
  std::string unit_;
  std::atomic<uint64_t> total_;
  std::atomic<uint64_t> done_{0};
  bool enabled_;
  bool tty_;
  bool finished_ = false;
  bool quiet_unless_slow_ = false;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point hold_until_;
  std::mutex mu_;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_;
};

}  // namespace handdb
