#include "track/frames.h"

#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <mutex>
#include <optional>
#include <system_error>

#include "base/atomic_file.h"
#include "base/plugin.h"
#include "track/videoio_plugin.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// The number a file name's stem ends in, if any.
std::optional<int64_t> TrailingNumber(const fs::path& file) {
  const std::string stem = file.stem().string();
  size_t b = stem.size();
  while (b > 0 && std::isdigit(static_cast<unsigned char>(stem[b - 1]))) --b;
  if (b == stem.size() || stem.size() - b > 12) return std::nullopt;
  int64_t n = 0;
  std::from_chars(stem.data() + b, stem.data() + stem.size(), n);
  return n;
}

class FolderSource : public FrameSource {
 public:
  FolderSource(std::vector<fs::path> files, std::vector<int64_t> indices, double fps)
      : files_(std::move(files)), indices_(std::move(indices)), fps_(fps) {}

  Result<bool> Next(Frame* frame) override {
    if (next_file_ >= files_.size()) return false;
    *frame = Frame{};
    frame->index = next_index_;
    frame->time_s = static_cast<double>(next_index_) / fps_;
    if (indices_[next_file_] > next_index_) {
      // A number missing from the folder's run: a gap of one frame.
      frame->name =
          (files_[next_file_].parent_path() / ("#" + std::to_string(next_index_))).string();
      frame->error =
          Status(StatusCode::kNotFound,
                 "frame " + std::to_string(next_index_) + " is missing (no file before " +
                     files_[next_file_].filename().string() + ")");
    } else {
      frame->path = files_[next_file_];
      frame->name = frame->path.string();
      ++next_file_;
    }
    ++next_index_;
    return true;
  }
  int64_t size_hint() const override { return indices_.empty() ? 0 : indices_.back() + 1; }
  double fps() const override { return fps_; }

 private:
  std::vector<fs::path> files_;
  std::vector<int64_t> indices_;
  double fps_;
  size_t next_file_ = 0;
  int64_t next_index_ = 0;
};

// The plugin's functions, loaded once per process.
struct VideoPlugin {
  decltype(&handdb_videoio_abi) abi = nullptr;
  decltype(&handdb_video_open) open = nullptr;
  decltype(&handdb_video_info) info = nullptr;
  decltype(&handdb_video_read) read = nullptr;
  decltype(&handdb_video_close) close = nullptr;
};

constexpr const char* kPluginName = "libhanddb_videoio.so";
constexpr const char* kPluginEnv = "HANDDB_VIDEOIO_PLUGIN";

Result<const VideoPlugin*> LoadVideoPlugin() {
  static std::once_flag once;
  static VideoPlugin plugin;
  static Status error;
  std::call_once(once, [] {
    auto lib = OpenPlugin(kPluginName, kPluginEnv, "reading a video");
    if (!lib.ok()) {
      error = lib.status().code() == StatusCode::kNotFound
                  ? Status(StatusCode::kNotFound,
                           lib.status().message() + " or give a folder of frames")
                  : lib.status();
      return;
    }
    VideoPlugin p;
    p.abi = reinterpret_cast<decltype(p.abi)>(::dlsym(*lib, "handdb_videoio_abi"));
    p.open = reinterpret_cast<decltype(p.open)>(::dlsym(*lib, "handdb_video_open"));
    p.info = reinterpret_cast<decltype(p.info)>(::dlsym(*lib, "handdb_video_info"));
    p.read = reinterpret_cast<decltype(p.read)>(::dlsym(*lib, "handdb_video_read"));
    p.close = reinterpret_cast<decltype(p.close)>(::dlsym(*lib, "handdb_video_close"));
    if (p.abi == nullptr || p.open == nullptr || p.info == nullptr || p.read == nullptr ||
        p.close == nullptr || p.abi() != HANDDB_VIDEOIO_ABI) {
      error = Status(StatusCode::kNotFound,
                     PluginFile(*lib, kPluginName) + " is not a video plugin of this handdb (ABI " +
                         std::to_string(HANDDB_VIDEOIO_ABI) + ")");
      return;
    }
    plugin = p;
  });
  if (plugin.open == nullptr) return error;
  return &plugin;
}

class VideoSource : public FrameSource {
 public:
  VideoSource(const VideoPlugin* plugin, handdb_video* video, std::string name)
      : plugin_(plugin), video_(video), name_(std::move(name)) {
    plugin_->info(video_, &fps_, &frame_count_);
  }
  ~VideoSource() override { plugin_->close(video_); }

  Result<bool> Next(Frame* frame) override {
    *frame = Frame{};
    const uint8_t* bgr = nullptr;
    int width = 0, height = 0;
    size_t row_bytes = 0;
    double time_s = fps_ > 0 ? static_cast<double>(next_) / fps_ : 0;
    const int rc = plugin_->read(video_, &bgr, &width, &height, &row_bytes, &time_s);
    if (rc == 0) return false;
    frame->index = next_++;
    frame->time_s = time_s;
    frame->name = name_ + "#" + std::to_string(frame->index);
    if (rc < 0) {
      frame->error = Status(StatusCode::kBadImage, frame->name + ": the frame does not decode");
      return true;
    }
    frame->has_pixels = true;
    frame->pixels = {width, height, 3, bgr, row_bytes};
    return true;
  }
  int64_t size_hint() const override { return frame_count_; }
  double fps() const override { return fps_ > 0 ? fps_ : 30; }

 private:
  const VideoPlugin* plugin_;
  handdb_video* video_;
  std::string name_;
  double fps_ = 0;
  int64_t frame_count_ = -1;
  int64_t next_ = 0;
};

}  // namespace

bool FrameSourceOptions::Check() const {
  CHECK_OPTION(folder_fps > 0 && folder_fps <= 10000);
  return true;
}

bool IsFrameFileName(const std::string& name) {
  const std::string ext = Lower(fs::path(name).extension().string());
  for (const char* e : {".png", ".jpg", ".jpeg", ".pnm", ".pgm", ".ppm", ".bmp"}) {
    if (ext == e) return true;
  }
  return false;
}

std::vector<fs::path> VideoPluginCandidates() { return PluginCandidates(kPluginName, kPluginEnv); }

Result<std::unique_ptr<FrameSource>> OpenFrameFolder(const fs::path& dir,
                                                     const FrameSourceOptions& options) {
  if (!options.Check()) {
    return Status(StatusCode::kInvalidArgument,
                  "invalid frame source options (see the line above)");
  }
  std::vector<fs::path> files;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (IsFrameFileName(it->path().filename().string()) && it->is_regular_file(ec)) {
      files.push_back(it->path());
    }
  }
  if (ec) {
    return Status(StatusCode::kIoError, dir.string() + ": cannot list the folder: " + ec.message());
  }
  if (files.empty()) {
    return Status(StatusCode::kNotFound, dir.string() + ": no frames (PNG/JPEG/PNM/BMP files)");
  }
  std::sort(files.begin(), files.end());
  std::vector<int64_t> numbers;
  for (const fs::path& f : files) {
    const auto n = TrailingNumber(f);
    if (!n) break;
    numbers.push_back(*n);
  }
  std::vector<int64_t> indices(files.size());
  bool numbered = numbers.size() == files.size();
  for (size_t i = 1; numbered && i < numbers.size(); ++i) {
    numbered = numbers[i] > numbers[i - 1] && numbers[i] - numbers[0] < (int64_t{1} << 31);
  }
  for (size_t i = 0; i < files.size(); ++i) {
    indices[i] = numbered ? numbers[i] - numbers[0] : static_cast<int64_t>(i);
  }
  return std::unique_ptr<FrameSource>(
      new FolderSource(std::move(files), std::move(indices), options.folder_fps));
}

Result<std::unique_ptr<FrameSource>> OpenVideo(const fs::path& video) {
  if (Status s = CheckRegularFile(video); !s.ok()) return s;
  Result<const VideoPlugin*> plugin = LoadVideoPlugin();
  if (!plugin.ok())
    return Status(plugin.status().code(), video.string() + ": " + plugin.status().message());
  char error[512] = {0};
  handdb_video* v = (*plugin)->open(video.c_str(), error, sizeof(error));
  if (v == nullptr) {
    return Status(StatusCode::kBadImage, video.string() + ": " + error);
  }
  return std::unique_ptr<FrameSource>(new VideoSource(*plugin, v, video.string()));
}

Result<std::unique_ptr<FrameSource>> OpenFrames(const fs::path& video_or_dir,
                                                const FrameSourceOptions& options) {
  std::error_code ec;
  const fs::file_status st = fs::status(video_or_dir, ec);
  if (ec || !fs::exists(st)) {
    return Status(StatusCode::kNotFound, video_or_dir.string() + ": no such video or folder");
  }
  if (fs::is_directory(st)) return OpenFrameFolder(video_or_dir, options);
  return OpenVideo(video_or_dir);
}

}  // namespace handdb
