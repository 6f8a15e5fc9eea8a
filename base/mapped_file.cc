#include "base/mapped_file.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <mutex>
#include <string>
#include <utility>

#include "base/atomic_file.h"

namespace handdb {
namespace {

// Closes the descriptor on every return path of Open (the mapping outlives it).
struct FdCloser {
  int fd;
  ~FdCloser() { ::close(fd); }
};

// The registry the SIGBUS handler reads: fixed arrays of atomics and characters, so the handler
// allocates nothing and takes no lock (async-signal-safe). A slot is claimed (kFree -> kWriting),
// filled, then published (kReady); the handler reads only kReady slots.
constexpr int kRegistrySlots = 4096;
constexpr size_t kRegistryPathBytes = 512;
enum SlotState : int { kFree = 0, kWriting = 1, kReady = 2 };
struct RegistrySlot {
  std::atomic<int> state{kFree};
  std::atomic<uintptr_t> begin{0};
  std::atomic<uintptr_t> end{0};
  char path[kRegistryPathBytes] = {};
};
RegistrySlot g_registry[kRegistrySlots];
struct sigaction g_previous_sigbus {};

void WriteAll(const char* text, size_t size) {
  while (size > 0) {
    const ssize_t n = ::write(STDERR_FILENO, text, size);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return;
    text += n;
    size -= static_cast<size_t>(n);
  }
}

void OnSigbus(int sig, siginfo_t* info, void* context) {
  const auto addr = reinterpret_cast<uintptr_t>(info->si_addr);
  // si_code <= 0: sent by kill/raise, where si_addr means nothing.
  for (RegistrySlot& slot : g_registry) {
    if (info->si_code <= 0) break;
    if (slot.state.load(std::memory_order_acquire) != kReady) continue;
    if (addr < slot.begin.load(std::memory_order_relaxed) ||
        addr >= slot.end.load(std::memory_order_relaxed)) {
      continue;
    }
    static const char kPrefix[] = "handdb: ";
    static const char kSuffix[] = ": changed or truncated while being read\n";
    WriteAll(kPrefix, sizeof kPrefix - 1);
    WriteAll(slot.path, ::strnlen(slot.path, kRegistryPathBytes));
    WriteAll(kSuffix, sizeof kSuffix - 1);
    ::_exit(1);
  }
  // Not one of ours: hand it on as if this handler were not there.
  if (g_previous_sigbus.sa_flags & SA_SIGINFO) {
    if (g_previous_sigbus.sa_sigaction != nullptr) {
      g_previous_sigbus.sa_sigaction(sig, info, context);
      return;
    }
  } else if (g_previous_sigbus.sa_handler != SIG_DFL && g_previous_sigbus.sa_handler != SIG_IGN) {
    g_previous_sigbus.sa_handler(sig);
    return;
  }
  // The default action, at once (SA_NODEFER: the signal is not blocked in here).
  ::signal(SIGBUS, SIG_DFL);
  ::raise(sig);
}

void InstallSigbusHandler() {
  static std::once_flag once;
  std::call_once(once, [] {
    struct sigaction action {};
    action.sa_sigaction = OnSigbus;
    action.sa_flags = SA_SIGINFO | SA_NODEFER;
    sigemptyset(&action.sa_mask);
    ::sigaction(SIGBUS, &action, &g_previous_sigbus);
  });
}

int Register(const void* map, size_t size, const std::string& path) {
  InstallSigbusHandler();
  for (int i = 0; i < kRegistrySlots; ++i) {
    RegistrySlot& slot = g_registry[i];
    int expected = kFree;
    if (!slot.state.compare_exchange_strong(expected, kWriting, std::memory_order_acquire)) {
      continue;
    }
    const size_t n = std::min(path.size(), kRegistryPathBytes - 1);
    std::memcpy(slot.path, path.data(), n);
    slot.path[n] = '\0';
    slot.begin.store(reinterpret_cast<uintptr_t>(map), std::memory_order_relaxed);
    slot.end.store(reinterpret_cast<uintptr_t>(map) + size, std::memory_order_relaxed);
    slot.state.store(kReady, std::memory_order_release);
    return i;
  }
  return -1;  // full: the mapping works, a SIGBUS in it is not explained
}

void Unregister(int i) {
  if (i < 0) return;
  g_registry[i].state.store(kWriting, std::memory_order_release);
  g_registry[i].begin.store(0, std::memory_order_relaxed);
  g_registry[i].end.store(0, std::memory_order_relaxed);
  g_registry[i].state.store(kFree, std::memory_order_release);
}

}  // namespace

Result<MappedFile> MappedFile::Open(const std::filesystem::path& path, Advice advice) {
  const std::string name = path.string();
  // Refuse FIFOs and devices before open() (which would block on a FIFO); O_NONBLOCK and the
  // fstat below cover a path swapped in between.
  if (Status s = CheckRegularFile(path); !s.ok()) return s;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) {
    const StatusCode code = errno == ENOENT ? StatusCode::kNotFound : StatusCode::kIoError;
    return Status(code, name + ": cannot open: " + std::strerror(errno));
  }
  const FdCloser closer{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    return Status(StatusCode::kIoError, name + ": fstat failed: " + std::strerror(errno));
  }
  if (!S_ISREG(st.st_mode)) return Status(StatusCode::kIoError, name + ": not a regular file");
  MappedFile file;
  const auto size = static_cast<size_t>(st.st_size);
  if (size == 0) return file;
  void* map = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0);
  if (map == MAP_FAILED) {
    return Status(
        StatusCode::kIoError,
        name + ": mmap of " + std::to_string(size) + " bytes failed: " + std::strerror(errno));
  }
  file.map_ = map;
  file.size_ = size;
  file.registry_slot_ = Register(map, size, name);
  file.Advise(0, size, advice);
  return file;
}

void MappedFile::Advise(uint64_t begin, uint64_t end, Advice advice) const {
  THROW_CHECK_EQ(begin % 4096, 0u);
  end = std::min<uint64_t>(end, size_);
  if (map_ == nullptr || end <= begin) return;
  const int flag = advice == Advice::kSequential ? MADV_SEQUENTIAL
                   : advice == Advice::kDontNeed ? MADV_DONTNEED
                                                 : MADV_NORMAL;
  ::madvise(static_cast<uint8_t*>(map_) + begin, end - begin, flag);  // a hint: errors ignored
}

MappedFile::~MappedFile() { Reset(); }

MappedFile::MappedFile(MappedFile&& other) noexcept
    : map_(std::exchange(other.map_, nullptr)),
      size_(std::exchange(other.size_, 0)),
      registry_slot_(std::exchange(other.registry_slot_, -1)) {}

MappedFile& MappedFile::operator=(MappedFile&& other) noexcept {
  if (this != &other) {
    Reset();
    map_ = std::exchange(other.map_, nullptr);
    size_ = std::exchange(other.size_, 0);
    registry_slot_ = std::exchange(other.registry_slot_, -1);
  }
  return *this;
}

void MappedFile::Reset() {
  // Unlisted before the range is unmapped, so a new mapping at the same address is never
  // explained by this file's name.
  Unregister(std::exchange(registry_slot_, -1));
  if (map_ != nullptr) ::munmap(map_, size_);
  map_ = nullptr;
  size_ = 0;
}

}  // namespace handdb
