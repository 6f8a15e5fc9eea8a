// handdb track DB VIDEO|DIR: a video's (or a folder of frames') hand poses, frame by frame, with
// a search that uses the frames before (track/tracker.h, docs/track.md).
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <span>
#include <string>

#include "base/atomic_file.h"
#include "base/json_schema.h"
#include "base/progress.h"
#include "base/thread_pool.h"
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "cli/photo_input_flags.h"
#include "generator/hand/database_rig.h"
#include "pose/sheet.h"
#include "query/searcher.h"
#include "track/frames.h"
#include "track/track_json.h"
#include "track/tracker.h"

namespace handdb::cli {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

struct TrackFlags {
  std::string db_dir;
  std::string input;
  std::string out;
  std::string overlay;
  std::string smooth = std::string(SmoothingName(Smoothing::kOnline));
  std::string search_mode = "exact";
  std::string fit = "auto";
  bool quiet = false;
  bool full_search = false;
  HandFlag hand;
  PhotoInputFlags picture;
  TrackOptions track;
  FrameSourceOptions source;

  void Add(CLI::App& app) {
    SearchOptions& search = picture.options.search;
    search.top_k = 10;
    app.add_option("DB", db_dir, "database directory (manifest.json + shards)")->required();
    app.add_option("VIDEO|DIR",
                   input,
                   "a video file (read by OpenCV through the video plugin) or a folder of frames "
                   "(PNG/JPEG/PNM/BMP, in name order; a number missing from their numbering is a "
                   "missing frame)")
        ->required();
    app.add_option(
        "--out", out, "write the JSON lines to this file (atomically) instead of stdout");
    app.add_option("--overlay",
                   overlay,
                   "write each frame as DIR/frame-NNNNNN.png with the answer's skeleton drawn");
    app.add_option(
           "--top", search.top_k, "matches per frame: the candidates the smoother chooses among")
        ->check(CLI::Range(1, 1000))
        ->capture_default_str();
    app.add_option("--smooth",
                   smooth,
                   "choose each frame's pose among its top matches over time: online (a look-back "
                   "window, frames printed as they come), offline (the whole sequence, printed at "
                   "the end) or off (each frame's best)")
        ->check(CLI::IsMember({"off", "online", "offline"}))
        ->capture_default_str();
    app.add_option("--window", track.window, "online smoothing: frames looked back over")
        ->check(CLI::Range(1, 1000))
        ->capture_default_str();
    app.add_flag(
        "--full-search", full_search, "search the whole database every frame (no local search)");
    app.add_flag_callback(
        "--no-landmark-tracking",
        [this] { track.landmark_tracking = false; },
        "find each frame's landmarks as a picture alone's (by default the network runs once, on "
        "the crop around the last frame's joints, while it finds the hand there)");
    app.add_option("--full-every",
                   track.full_every,
                   "a full search at least every N frames (0: only when the hand is lost or the "
                   "local search fails)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    app.add_option(
           "--refind-ratio",
           track.refind_ratio,
           "the local search fails (a full search follows) when its best D_c exceeds this times "
           "the previous frame's best plus --refind-margin px")
        ->check(CLI::Range(1.0, 1000.0))
        ->capture_default_str();
    app.add_option("--refind-margin", track.refind_margin_px, "see --refind-ratio (px)")
        ->check(CLI::Range(0.0, 1000.0))
        ->capture_default_str();
    app.add_option("--local-directions",
                   track.local.direction_deg,
                   "local search: view directions within this many degrees of the last answer's")
        ->check(CLI::Range(0.0, 180.0))
        ->capture_default_str();
    app.add_option("--local-rolls",
                   track.local.roll_steps,
                   "local search: rolls within this many steps of the last answer's")
        ->check(CLI::Range(0, 1000))
        ->capture_default_str();
    app.add_option("--local-joints",
                   track.local.joint_radius,
                   "local search: shapes whose joint angles are within this RMS distance (radians) "
                   "of the last answer's (-1: every shape)")
        ->capture_default_str();
    app.add_option("--fps", source.folder_fps, "a folder's frame rate (frame times)")
        ->check(CLI::Range(0.001, 10000.0))
        ->capture_default_str();
    app.add_option("--fit",
                   fit,
                   "fit the chosen pose to each frame's landmarks with the database's rig: auto "
                   "(when the database has it), on, off")
        ->check(CLI::IsMember({"auto", "on", "off"}))
        ->capture_default_str();
    app.add_option("--search",
                   search_mode,
                   "the full search: exact, or indexed (the database's index, handdb index)")
        ->check(CLI::IsMember({"exact", "indexed"}))
        ->capture_default_str();
    app.add_option("--threads", search.num_threads, "worker threads (-1: all cores)")
        ->capture_default_str();
    hand.Add(app, "the video");
    picture.Add(app, PhotoInputFlags::Which{true, false});
    app.add_flag("--quiet", quiet, "no progress line on stderr");
  }

  bool Finish() {
    SearchOptions& search = picture.options.search;
    if (search.num_threads == 0 || search.num_threads < -1 ||
        search.num_threads > MaxNumThreads()) {
      std::fprintf(stderr,
                   "handdb track: --threads %d: must be -1 or 1..%d\n",
                   search.num_threads,
                   MaxNumThreads());
      return false;
    }
    if (!picture.Finish("track")) return false;
    search.hand = hand.Get();
    search.mode = search_mode == "indexed" ? SearchMode::kIndexed : SearchMode::kExact;
    track.smoothing = *ParseSmoothing(smooth);
    track.local_search = !full_search;
    track.keep_pixels = !overlay.empty();
    if (!track.local.Check()) {
      std::fprintf(stderr, "handdb track: invalid local search options (see above)\n");
      return false;
    }
    return true;
  }
};

// The frame's overlay: its picture with the answer's skeleton.
Status WriteOverlay(const fs::path& dir, const TrackFrame& frame) {
  char name[32];
  std::snprintf(name, sizeof(name), "frame-%06lld.png", static_cast<long long>(frame.index));
  const std::span<const Point2f> skeleton = frame.has_pose
                                                ? std::span<const Point2f>(frame.keypoints_image_px)
                                                : std::span<const Point2f>();
  if (!frame.frame_bgr.empty()) {
    const PicturePixels pixels{frame.frame_width, frame.frame_height, 3, frame.frame_bgr.data(), 0};
    return WriteSkeletonOverlay(dir / name, {}, &pixels, skeleton);
  }
  std::error_code ec;
  if (frame.source.empty() || !fs::is_regular_file(frame.source, ec)) return Status::Ok();
  Status s = WriteSkeletonOverlay(dir / name, frame.source, nullptr, skeleton);
  // A frame that does not decode has no overlay; its line says why.
  return s.code() == StatusCode::kBadImage || s.code() == StatusCode::kNotFound ? Status::Ok() : s;
}

}  // namespace

int RunTrack(int argc, char** argv) {
  CLI::App app{
      "Tracks a hand through a video or a folder of frames: per frame the picture's evidence "
      "(as handdb query reads a photo), a search near the previous frame's answer (exact within "
      "that neighbourhood) or of the whole database when the hand was lost, the local answer is "
      "poor or a full search is due, then one pose chosen among the frame's top matches over time "
      "and fitted. One JSON object per frame (schemas/track_frame.schema.json); a missing or "
      "unreadable frame, or one without a hand, is a line with its error and the run goes on "
      "(docs/track.md).",
      "handdb track"};
  TrackFlags flags;
  const auto start = std::chrono::steady_clock::now();
  flags.Add(app);
  if (int rc = ParseArgs(app, argc, argv); rc >= 0) return rc;
  if (!flags.Finish()) return flags.picture.failure_exit_code;

  SearcherOptions open;
  open.num_threads = flags.picture.options.search.num_threads;
  open.use_index = flags.search_mode == "indexed" ? IndexUse::kIndexed : IndexUse::kExact;
  auto searcher = Searcher::Open(flags.db_dir, open);
  if (!searcher.ok()) return Fail("track", searcher.status());
  const Database& db = (*searcher)->database();
  if (db.num_views() == 0) {
    return Fail("track",
                Status(StatusCode::kNotFound, flags.db_dir + ": the database has no views"));
  }
  if (flags.fit != "off") {
    auto rig = LoadDatabaseRig(flags.db_dir);
    if (rig.ok()) {
      flags.picture.options.rig = std::make_shared<const DatabaseRig>(std::move(rig).value());
      flags.picture.options.fit.use_silhouette = flags.fit == "on";
    } else if (flags.fit == "on") {
      return Fail("track", rig.status());
    }
  }
  if (Status s = flags.picture.UseDatabaseConversion(db, flags.db_dir); !s.ok()) {
    return Fail("track", s);
  }
  flags.track.picture = flags.picture.options;
  auto frames = OpenFrames(flags.input, flags.source);
  if (!frames.ok()) return Fail("track", frames.status());
  if (!flags.overlay.empty()) {
    std::error_code ec;
    fs::create_directories(flags.overlay, ec);
    if (ec) {
      return Fail("track",
                  Status(StatusCode::kIoError,
                         flags.overlay + ": cannot create the overlay folder: " + ec.message()));
    }
  }

  std::string buffered;  // --out: written at the end, atomically
  const bool to_file = !flags.out.empty();
  auto on_frame = [&](const TrackFrame& frame) -> Status {
    const json line = TrackFrameToJson(frame);
    // A bug, but never print JSON that breaks the schema.
    HANDDB_RETURN_IF_ERROR(ValidateJson(line, "track_frame.schema.json", "track frame"));
    if (!flags.overlay.empty()) HANDDB_RETURN_IF_ERROR(WriteOverlay(flags.overlay, frame));
    if (frame.found == FoundBy::kNone && !flags.quiet) {
      std::fprintf(stderr,
                   "%shanddb track: frame %lld: %s\n",
                   ::isatty(STDERR_FILENO) ? "\r\033[K" : "",
                   static_cast<long long>(frame.index),
                   frame.error.message().c_str());
    }
    if (to_file) {
      buffered += line.dump() + "\n";
    } else {
      std::fputs((line.dump() + "\n").c_str(), stdout);
      std::fflush(stdout);
    }
    return Status::Ok();
  };
  auto summary = TrackFrames(**searcher, **frames, flags.track, on_frame, !flags.quiet);
  if (!summary.ok()) return Fail("track", summary.status());
  if (to_file) {
    if (Status s = WriteFileAtomic(flags.out, buffered); !s.ok()) return Fail("track", s);
  }
  if (!flags.quiet) {
    const double seconds = SecondsSince(start);
    std::fprintf(stderr,
                 "handdb track: %lld frames in %.2f s (%.1f frames/s): %lld full, %lld local, "
                 "%lld carried, %lld without a pose\n",
                 static_cast<long long>(summary->frames),
                 seconds,
                 seconds > 0 ? summary->frames / seconds : 0.0,
                 static_cast<long long>(summary->found_full),
                 static_cast<long long>(summary->found_local),
                 static_cast<long long>(summary->found_carried),
                 static_cast<long long>(summary->found_none));
  }
  return kExitOk;
}

}  // namespace handdb::cli
