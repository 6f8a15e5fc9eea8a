#include "base/progress.h"

#include <unistd.h>

#include <cstdio>

namespace handdb {
namespace {
std::string FormatDuration(double seconds) {
  if (seconds < 0 || seconds > 1e7) return "?";
  auto s = static_cast<long>(seconds + 0.5);
  char buf[32];
  if (s >= 3600) {
    std::snprintf(buf, sizeof(buf), "%ld:%02ld:%02ld", s / 3600, (s / 60) % 60, s % 60);
  } else {
    std::snprintf(buf, sizeof(buf), "%ld:%02ld", s / 60, s % 60);
  }
  return buf;
}
}  // namespace

Progress::Progress(std::string label, uint64_t total, bool enabled, std::string unit)
    : label_(std::move(label)),
      unit_(std::move(unit)),
      total_(total),
      enabled_(enabled),
      tty_(::isatty(STDERR_FILENO) != 0),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_) {}

Progress::~Progress() { Finish(); }

void Progress::SetTotal(uint64_t total) { total_ = total; }

void Progress::QuietUnlessSlow(std::chrono::steady_clock::time_point since) {
  std::lock_guard<std::mutex> lock(mu_);
  quiet_unless_slow_ = true;
  hold_until_ = since + (tty_ ? std::chrono::milliseconds(1000) : std::chrono::milliseconds(5000));
  last_draw_ = since;
}

void Progress::Add(uint64_t n) {
  done_ += n;
  if (!enabled_) return;
  auto now = std::chrono::steady_clock::now();
  const auto interval = tty_ ? std::chrono::milliseconds(200) : std::chrono::milliseconds(5000);
  std::unique_lock<std::mutex> lock(mu_, std::try_to_lock);
  if (!lock.owns_lock() || now - last_draw_ < interval) return;
  if (quiet_unless_slow_ && now < hold_until_) return;
  last_draw_ = now;
  Draw(false);
}

void Progress::Finish() {
  std::lock_guard<std::mutex> lock(mu_);
  if (finished_ || !enabled_) {
    finished_ = true;
    return;
  }
  finished_ = true;
  if (quiet_unless_slow_ && !drawn_) return;
  Draw(true);
}

void Progress::Draw(bool final) {
  drawn_ = true;
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  const uint64_t done = done_.load();
  const uint64_t total = total_.load();
  const double rate = elapsed > 0 ? static_cast<double>(done) / elapsed : 0.0;
  const double pct = total > 0 ? 100.0 * static_cast<double>(done) / static_cast<double>(total) : 0;
  std::string eta = final ? FormatDuration(elapsed)
                          : (rate > 0 && total >= done
                                 ? "ETA " + FormatDuration(static_cast<double>(total - done) / rate)
                                 : "ETA ?");
  std::fprintf(stderr,
               "%s%-10s %llu/%llu %5.1f%%  %.1f %s/s  %s%s",
               tty_ ? "\r\033[K" : "",
               label_.c_str(),
               static_cast<unsigned long long>(done),
               static_cast<unsigned long long>(total),
               pct,
               rate,
               unit_.c_str(),
               eta.c_str(),
               (final || !tty_) ? "\n" : "");
  std::fflush(stderr);
}

}  // namespace handdb
