// The `handdb` binary against hostile inputs and outputs: stdout on a full disk (/dev/full) is
// exit 1 with one line, never exit 0 over an empty file; 100,000 nested brackets in a config or
// manifest are refused with one line instead of a SIGSEGV; a FIFO or /dev/zero as a manifest or
// shard is refused at once instead of blocking or growing memory forever; a truncated PNG / JPEG,
// a directory or a symlink loop as the query image is one line; validate cross-checks the
// manifest against the shards; labels out of range are refused at open; rolls, image pixels and
// plan sizes are bounded before allocating; `show`'s image finds its own view; a second writer is
// refused and a bad config leaves no directory; bad --skin / --canny / --dt-cell values are one
// line. Every command runs under `timeout`, so a regression fails instead of hanging.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "base/directory_lock.h"
#include "base/json_schema.h"
#include "edges/normalise.h"
#include "format/manifest.h"
#include "format/shard_layout.h"
#include "format/shard_reader.h"
#include "format/shard_testing.h"
#include "format/shard_writer.h"
#include "query/search_testing.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

struct CliRun {
  int code = -1;  // exit code; 124 when `timeout` killed it; -1 when killed by a signal
  std::string err;
};

std::string Slurp(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Runs `handdb ARGS > STDOUT` (from the source directory, so configs/ resolves) with a 20 s
// timeout.
CliRun Handdb(const std::string& args, const std::string& stdout_to = "/dev/null") {
  static int n = 0;
  const fs::path err = fs::temp_directory_path() /
                       ("handdb-hard-err-" + std::to_string(getpid()) + "-" + std::to_string(n++));
  const std::string cmd = std::string("cd ") + HANDDB_SOURCE_DIR + " && timeout 20 " +
                          HANDDB_BINARY + " " + args + " >" + stdout_to + " 2>" + err.string();
  const int status = std::system(cmd.c_str());
  CliRun r;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.err = Slurp(err);
  fs::remove(err);
  return r;
}

int Lines(const std::string& s) {
  int n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

class HardeningCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() / ("handdb-hard-" + std::to_string(getpid())));
    fs::create_directories(*dir_ / "db");
    Manifest manifest;
    manifest.tool_version = "hardening_cli_test";
    manifest.rolls = 12;
    ShardWriter w;
    ASSERT_TRUE(w.Open(*dir_ / "db" / "shard-00000.hdb", ShardWriterOptions{}).ok());
    for (uint32_t v = 0; v < 4; ++v) {
      ASSERT_TRUE(
          w.AddView(testing::SyntheticViewLabel(v, 4), testing::SyntheticEdgeSet(v, 300)).ok());
    }
    auto summary = w.Finish();
    ASSERT_TRUE(summary.ok());
    manifest.AddShard(*summary);
    ASSERT_TRUE(WriteManifest(*dir_ / "db", manifest).ok());
    // A query image: view 1's points as white pixels.
    std::ofstream pgm(*dir_ / "q.pgm", std::ios::binary);
    pgm << "P5\n300 300\n255\n";
    std::string pixels(300 * 300, '\0');
    for (const auto& p : testing::SyntheticEdgeSet(1, 300)) {
      const int x = static_cast<int>(150 + p.x), y = static_cast<int>(150 + p.y);
      if (x >= 0 && x < 300 && y >= 0 && y < 300) pixels[static_cast<size_t>(y) * 300 + x] = '\xff';
    }
    pgm << pixels;
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
  }
  static std::string Db() { return (*dir_ / "db").string(); }
  // A copy of the database whose manifest.json is replaced by `make_manifest(path)`.
  template <typename F>
  static std::string DbWithManifest(const std::string& name, F make_manifest) {
    const fs::path db = *dir_ / name;
    fs::create_directories(db);
    fs::copy_file(*dir_ / "db" / "shard-00000.hdb",
                  db / "shard-00000.hdb",
                  fs::copy_options::overwrite_existing);
    fs::remove(db / "manifest.json");
    make_manifest(db / "manifest.json");
    return db.string();
  }
  static fs::path* dir_;
};
fs::path* HardeningCli::dir_ = nullptr;

// Each --json command writing into a full disk.
TEST_F(HardeningCli, StdoutOnFullDiskIsExitOneWithOneLine) {
  // The same commands succeed with a working stdout, so the failure below is the write's.
  const std::string q = (*dir_ / "q.pgm").string();
  const std::string plan = (*dir_ / "plan.json").string();
  const std::vector<std::pair<std::string, std::string>> runs = {
      {"info", "info " + Db() + " --json"},
      {"validate", "validate " + Db() + " --json -q"},
      {"query", "query " + Db() + " " + q + " --input edges --json"},
      {"plan", "plan configs/demo.json -o " + plan + " --json"},
      {"version", "version"},
  };
  for (const auto& [name, args] : runs) {
    SCOPED_TRACE(args);
    const CliRun ok = Handdb(args);
    ASSERT_EQ(ok.code, 0) << ok.err;
    const CliRun full = Handdb(args, "/dev/full");
    EXPECT_EQ(full.code, 1) << full.err;
    // The reason is errno's text when one is left (ENOSPC: "No space left on device").
    EXPECT_EQ(full.err.rfind("handdb " + name + ": cannot write to stdout: ", 0), 0u) << full.err;
    EXPECT_EQ(Lines(full.err), 1) << full.err;
  }
}

// A command whose output file does not fit on the disk (a full 64 KiB tmpfs) is
// exit 1 with one line naming that file (not its temp file) and the reason, and leaves neither
// the file nor a temp file behind. Needs mount(2) (root); skipped elsewhere.
TEST_F(HardeningCli, OutputFilesOnAFullDiskAreExitOneNamingTheFile) {
  const fs::path full = *dir_ / "full";
  fs::create_directories(full);
  if (std::system(("mount -t tmpfs -o size=64k tmpfs " + full.string() + " 2>/dev/null").c_str()) !=
      0) {
    GTEST_SKIP() << "cannot mount a tmpfs here";
  }
  // Fill it but for a few KB: the outputs below are larger.
  std::system(
      ("dd if=/dev/zero of=" + (full / "fill").string() + " bs=1k count=60 2>/dev/null").c_str());
  const std::string q = (*dir_ / "q.pgm").string();
  const std::vector<std::pair<std::string, fs::path>> runs = {
      {"plan configs/demo.json -o ", full / "plan.json"},
      {"query " + Db() + " " + q + " --input edges --sheet ", full / "sheet.png"},
  };
  for (const auto& [args, file] : runs) {
    SCOPED_TRACE(args);
    const CliRun r = Handdb(args + file.string());
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_NE(r.err.find(": " + file.string() + ": write failed: No space left on device\n"),
              std::string::npos)
        << r.err;
    EXPECT_EQ(Lines(r.err), 1) << r.err;
  }
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(full)) left.push_back(e.path().filename().string());
  EXPECT_EQ(left, std::vector<std::string>{"fill"});
  std::system(("umount " + full.string()).c_str());
}

// 100,000 nested '[' given to plan / validate / info / query: one line each, not a stack overflow.
TEST_F(HardeningCli, DeeplyNestedJsonIsRefusedWithOneLine) {
  const std::string deep = std::string(100000, '[') + std::string(100000, ']');
  const fs::path config = *dir_ / "deep-config.json";
  std::ofstream(config) << deep;
  CliRun r = Handdb("plan " + config.string() + " -o " + (*dir_ / "p.json").string());
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(r.err,
            "handdb plan: " + config.string() + ": JSON nested deeper than 64 levels at byte 64\n");

  const std::string db = DbWithManifest("deep-db", [&](const fs::path& m) {
    std::ofstream(m) << "{\"a\": \"[[[[\", \"b\": " << deep << "}";
  });
  for (const std::string cmd : {"info", "validate", "query"}) {
    SCOPED_TRACE(cmd);
    const std::string extra = cmd == "query" ? " " + (*dir_ / "q.pgm").string() : "";
    r = Handdb(cmd + " " + db + extra + (cmd == "validate" ? " -q" : ""));
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_NE(r.err.find("manifest.json: JSON nested deeper than 64 levels at byte"),
              std::string::npos)
        << r.err;
    EXPECT_EQ(Lines(r.err), 1) << r.err;
  }
}

// A FIFO (nobody writing) or /dev/zero as the manifest, a FIFO as a shard: refused, not opened.
TEST_F(HardeningCli, FifosAndDevicesAreRefusedNotOpened) {
  const std::string fifo_db =
      DbWithManifest("fifo-db", [](const fs::path& m) { ASSERT_EQ(::mkfifo(m.c_str(), 0644), 0); });
  const std::string zero_db =
      DbWithManifest("zero-db", [](const fs::path& m) { fs::create_symlink("/dev/zero", m); });
  const std::string q = (*dir_ / "q.pgm").string();
  for (const std::string& db : {fifo_db, zero_db}) {
    for (const std::string cmd : {"info", "validate", "query"}) {
      SCOPED_TRACE(cmd + " " + db);
      const CliRun r = Handdb(cmd + " " + db + (cmd == "query" ? " " + q : "") +
                              (cmd == "validate" ? " -q" : ""));
      EXPECT_EQ(r.code, 1) << r.err;
      EXPECT_NE(r.err.find(db + "/manifest.json: not a regular file"), std::string::npos) << r.err;
      EXPECT_EQ(Lines(r.err), 1) << r.err;
    }
  }
  const fs::path fifo_shard = *dir_ / "fifo.hdb";
  ASSERT_EQ(::mkfifo(fifo_shard.c_str(), 0644), 0);
  for (const std::string cmd : {"info", "validate"}) {
    SCOPED_TRACE(cmd);
    const CliRun r = Handdb(cmd + " " + fifo_shard.string() + (cmd == "validate" ? " -q" : ""));
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_NE(r.err.find(fifo_shard.string() + ": not a regular file"), std::string::npos) << r.err;
  }
}

// A truncated PNG / JPEG is refused, not searched past the codec's warning; a directory or a
// symlink loop given as the image is named as what it is, not as a missing file.
TEST_F(HardeningCli, TruncatedOrMissingImagesAreRefusedWithOneLine) {
  const cv::Mat img = cv::imread((*dir_ / "q.pgm").string(), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(img.empty());
  for (const std::string ext : {"png", "jpg"}) {
    SCOPED_TRACE(ext);
    const fs::path whole = *dir_ / ("whole." + ext);
    ASSERT_TRUE(cv::imwrite(whole.string(), img));
    EXPECT_EQ(Handdb("query " + Db() + " " + whole.string() + " --input edges").code, 0);
    const fs::path cut = *dir_ / ("cut." + ext);
    fs::copy_file(whole, cut, fs::copy_options::overwrite_existing);
    fs::resize_file(cut, fs::file_size(whole) * 2 / 3);
    const CliRun r = Handdb("query " + Db() + " " + cut.string() + " --input edges");
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_EQ(r.err,
              "handdb query: " + cut.string() + ": truncated " + (ext == "png" ? "PNG" : "JPEG") +
                  (ext == "png" ? " (no IEND chunk)\n" : " (no end-of-image marker)\n"));
  }
  // A directory given as IMAGE is a batch of its pictures (docs/query.md); one listed as a
  // picture is refused with one line.
  const fs::path list = *dir_ / "list.txt";
  {
    std::ofstream f(list);
    f << dir_->string() << "\n";
  }
  CliRun r = Handdb("query " + Db() + " - < " + list.string());
  EXPECT_EQ(r.code, 1);
  EXPECT_EQ(r.err, "handdb query: " + dir_->string() + ": is a directory, expected a file\n");
  const fs::path loop = *dir_ / "loop.png";
  fs::create_symlink(loop, loop);
  r = Handdb("query " + Db() + " " + loop.string());
  EXPECT_EQ(r.code, 1);
  EXPECT_EQ(
      r.err,
      "handdb query: " + loop.string() + ": too many levels of symbolic links (a symlink loop?)\n");
}

// Bad --skin / --canny / --dt-cell values: one line naming the flag, the value and the rule,
// exit 2 (bad usage), no source paths of the option checks.
TEST_F(HardeningCli, BadPhotoAndSearchFlagsAreOneLineNamingTheFlag) {
  const std::string query = "query " + Db() + " " + (*dir_ / "q.pgm").string() + " ";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"--skin 0,300,0,0,0,0",
       "handdb query: --skin 0,300,0,0,0,0: each of Y, Cr, Cb needs 0 <= min <= max <= 255\n"},
      {"--skin 0,255,200,100,0,255",
       "handdb query: --skin 0,255,200,100,0,255: each of Y, Cr, Cb needs 0 <= min <= max <= "
       "255\n"},
      {"--skin 1,2,3",
       "handdb query: --skin needs six integers Ymin,Ymax,Crmin,Crmax,Cbmin,Cbmax\n"},
      {"--canny 200,100", "handdb query: --canny 200,100: needs 0 <= low <= high\n"},
      {"--canny -5,10", "handdb query: --canny -5,10: needs 0 <= low <= high\n"},
      {"--canny 5", "handdb query: --canny needs two integers low,high\n"},
      {"--dt-cell 0.3",
       "handdb query: --dt-cell 0.3: must be 1, 0.5, 0.25, 0.125 or 0.0625 (px)\n"},
      {"--dt-cell 2", "handdb query: --dt-cell 2: must be 1, 0.5, 0.25, 0.125 or 0.0625 (px)\n"},
  };
  for (const auto& [flags, message] : cases) {
    const CliRun r = Handdb(query + flags);
    EXPECT_EQ(r.code, 2) << flags;
    EXPECT_EQ(r.err, message) << flags;
  }
  EXPECT_EQ(Handdb(query + "--dt-cell 0.5 --canny 10,20 --skin 0,255,0,255,0,255").code, 0);
  // A landmark model that is missing, not a model, or not a landmark model: one line naming it.
  const fs::path text = *dir_ / "text.tflite";
  std::ofstream(text) << "not a model\n";
  const fs::path small = fs::path(HANDDB_SOURCE_DIR) / "tests" / "data" / "tflite" / "head.tflite";
  const std::vector<std::pair<fs::path, std::string>> models = {
      {*dir_ / "missing.tflite", "no such model file"},
      {text, "not a TensorFlow Lite model (no TFL3 identifier)"},
      {small,
       "not a hand landmark model (expected one 1xHxWx3 input, and 63 joint coordinates and a "
       "presence score as its first two outputs)"},
  };
  for (const auto& [model, problem] : models) {
    const CliRun r = Handdb(query + "--landmarks " + model.string());
    EXPECT_EQ(r.code, 1) << model;  // a bad file, not bad usage
    EXPECT_EQ(r.err, "handdb query: --landmarks: " + model.string() + ": " + problem + "\n");
  }
}

// A database of one shard whose metadata is `metadata_json`, after `patch` edited the shard's
// bytes (checksums recomputed, the manifest made to match), with `rolls` in the manifest.
template <typename F>
std::string WriteDb(const fs::path& db, const std::string& metadata_json, uint32_t rolls, F patch) {
  fs::create_directories(db);
  const fs::path shard_path = db / "shard-00000.hdb";
  ShardWriter w;
  THROW_CHECK(w.Open(shard_path, ShardWriterOptions{metadata_json, {}}).ok());
  for (uint32_t v = 0; v < 4; ++v) {
    THROW_CHECK(
        w.AddView(testing::SyntheticViewLabel(v, 4), testing::SyntheticEdgeSet(v, 300)).ok());
  }
  auto summary = w.Finish();
  THROW_CHECK(summary.ok());
  std::ifstream in(shard_path, std::ios::binary);
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                             std::istreambuf_iterator<char>());
  in.close();
  patch(&bytes);
  THROW_CHECK(shard::RewriteChecksums(bytes));
  std::ofstream(shard_path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
  summary->checksum = shard::ChecksumHex(shard::Checksum(bytes.data(), bytes.size()));
  Manifest manifest;
  manifest.tool_version = "hardening_cli_test";
  manifest.rolls = rolls;
  manifest.AddShard(*summary);
  // Bypasses WriteManifest's own checks, so a manifest it would refuse can be tested too.
  THROW_CHECK(WriteJsonFileAtomic(db / "manifest.json", ManifestToJson(manifest)).ok());
  return db.string();
}

// A manifest saying 24 rolls over shards made with 48: validate reports it, query refuses it.
TEST_F(HardeningCli, ValidateCrossChecksTheManifestAgainstTheShards) {
  const std::string db =
      WriteDb(*dir_ / "rolls-db", R"({"unit": 0, "rolls": 48})", 24, [](std::vector<uint8_t>*) {});
  const fs::path out = *dir_ / "validate.txt";
  const CliRun r = Handdb("validate " + db, out.string());
  EXPECT_EQ(r.code, 1) << r.err;
  const std::string report = r.err;  // problems go to stderr, the summary to stdout
  EXPECT_NE(report.find(db + "/shard-00000.hdb: rolls is 24 in the manifest but 48 in the "
                             "shard's metadata (rolls)"),
            std::string::npos)
      << report << r.err;
  // query no longer searches the manifest's 24 rolls over 48-roll shards: one line, exit 1.
  const std::string q = (*dir_ / "q.pgm").string();
  const CliRun query = Handdb("query " + db + " " + q + " --input edges");
  EXPECT_EQ(query.code, 1);
  EXPECT_EQ(query.err,
            "handdb query: " + db +
                "/shard-00000.hdb: rolls is 24 in the manifest but 48 in the shard's metadata "
                "(run 'handdb validate' for every problem)\n");
  const std::string good =
      WriteDb(*dir_ / "rolls-ok", R"({"unit": 0, "rolls": 24})", 24, [](std::vector<uint8_t>*) {});
  EXPECT_EQ(Handdb("validate " + good + " -q").code, 0);
  EXPECT_EQ(Handdb("query " + good + " " + q + " --input edges").code, 0);
}

// A NaN joint angle / an infinite keypoint under recomputed checksums: the reader's open checks
// refuse it (one line naming the shard) instead of serving `nan` / JSON null.
TEST_F(HardeningCli, LabelsOutOfRangeAreRefusedAtOpen) {
  const std::string q = (*dir_ / "q.pgm").string();
  for (const auto& [name, value] :
       {std::pair{std::string("nan"), std::nanf("")},
        std::pair{std::string("inf"), std::numeric_limits<float>::infinity()}}) {
    SCOPED_TRACE(name);
    const float v = value;
    const bool is_nan = name == "nan";  // a lambda cannot capture a structured binding in C++20
    uint64_t field_at = 0;
    const std::string db =
        WriteDb(*dir_ / ("label-" + name), "{}", 12, [&](std::vector<uint8_t>* b) {
          auto reader = ShardReader::FromMemory(*b, "s");
          THROW_CHECK(reader.ok());
          for (const auto& sec : reader->sections()) {
            if (sec.name == "views") field_at = sec.offset + 1 * shard::kViewRecordSize;
          }
          field_at += is_nan ? shard::kViewOffJointAngles : shard::kViewOffKeypoints + 12 * 3;
          StoreLittleEndian<float>(b->data() + field_at, v);
        });
    const std::string expected =
        db + "/shard-00000.hdb: offset " + std::to_string(field_at) +
        ": view 1: " + (name == "nan" ? "joint_angles[0] is nan" : "keypoints[3][0] is inf") +
        " (not finite)";
    // query opens the database; info the shard (on a database it reads only the manifest).
    for (const std::string cmd : {"query", "info"}) {
      SCOPED_TRACE(cmd);
      const CliRun r = Handdb(cmd == "query" ? "query " + db + " " + q + " --input edges --json"
                                             : "info " + db + "/shard-00000.hdb");
      EXPECT_EQ(r.code, 1) << r.err;
      EXPECT_NE(r.err.find(expected), std::string::npos) << r.err;
      EXPECT_EQ(Lines(r.err), 1) << r.err;
    }
  }
}

// Counts that size an allocation are bounded before allocating, one line each.
TEST_F(HardeningCli, CountsThatSizeAllocationsAreBounded) {
  const std::string q = (*dir_ / "q.pgm").string();
  // A manifest with rolls = 10^8 and a matching virtual-view count.
  const std::string db =
      WriteDb(*dir_ / "many-rolls", "{}", 100000000, [](std::vector<uint8_t>*) {});
  for (const std::string cmd : {"info", "validate", "query"}) {
    SCOPED_TRACE(cmd);
    const CliRun r = Handdb(cmd + " " + db + (cmd == "query" ? " " + q + " --input edges" : "") +
                            (cmd == "validate" ? " -q" : ""));
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_NE(r.err.find(db + "/manifest.json: rolls is 100000000, more than the 3600 a database "
                              "may have"),
              std::string::npos)
        << r.err;
    EXPECT_EQ(Lines(r.err), 1) << r.err;
  }
  // A 5 MB-class PNG claiming 20000 x 20000 pixels: refused from its header, nothing decoded.
  const fs::path big = *dir_ / "big.png";
  {
    const cv::Mat tiny(8, 8, CV_8UC1, cv::Scalar(0));
    ASSERT_TRUE(cv::imwrite(big.string(), tiny));
    std::fstream f(big, std::ios::in | std::ios::out | std::ios::binary);
    const char size[8] = {0, 0, 0x4e, 0x20, 0, 0, 0x4e, 0x20};  // IHDR width, height = 20000
    f.seekp(16);
    f.write(size, 8);
  }
  CliRun r = Handdb("query " + Db() + " " + big.string());
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(r.err,
            "handdb query: " + big.string() +
                ": 20000 x 20000 pixels (PNG header), more than the 67108864 (64 Mpx) allowed\n");
  // A schema-valid config {"method": "pairs", "k": 1000}: 4 GB in 22 s before; now refused at once.
  const fs::path config = *dir_ / "pairs.json";
  std::ofstream(config) << R"({"seed": 0, "shapes": {"method": "pairs", "k": 1000},
                              "views": {"method": "fibonacci", "count": 86}})";
  const auto start = std::chrono::steady_clock::now();
  r = Handdb("plan " + config.string() + " -o " + (*dir_ / "pairs-plan.json").string());
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_NE(r.err.find("pairs of 26 basic shapes with k = 1000 give 325000 shapes x 86 "
                       "directions, more than the 250000 renders a plan may hold"),
            std::string::npos)
      << r.err;
  EXPECT_EQ(Lines(r.err), 1) << r.err;
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(10));
}

// A synthetic hand's points as the converter stores a rendered view: rasterised into a 256 px
// render (diameter ~134 px), then normalised from those pixels (hull-centroid centre, diameter
// 192).
std::vector<PointQ> AsConverted(const std::vector<PointQ>& points) {
  std::set<std::pair<int32_t, int32_t>> pixels;  // (row, col): raster order
  for (const PointQ& p : points) {
    pixels.insert({static_cast<int32_t>(std::floor(128 + 0.7 * p.y / kPointScale)),
                   static_cast<int32_t>(std::floor(128 + 0.7 * p.x / kPointScale))});
  }
  std::vector<EdgePixel> contour;
  for (const auto& [row, col] : pixels) contour.push_back({col, row});
  auto norm = ComputeNormalisation(contour);
  THROW_CHECK(norm.ok());
  return NormalisePixels(contour, *norm);
}

// `show -o v.png` then `query DB v.png`: the tool's own image (an anti-aliased caption that
// auto-detection must not take for a photo) finds its own view at rank 1, D_c ~ 0.
TEST_F(HardeningCli, ShowOutputQueriedFindsItsOwnView) {
  const fs::path db = *dir_ / "show-db";
  fs::create_directories(db);
  Manifest manifest;
  manifest.tool_version = "hardening_cli_test";
  manifest.rolls = 12;
  ShardWriter w;
  ASSERT_TRUE(w.Open(db / "shard-00000.hdb", ShardWriterOptions{}).ok());
  for (uint32_t v = 0; v < 8; ++v) {
    ASSERT_TRUE(w.AddView(testing::SyntheticViewLabel(v, 4),
                          AsConverted(testing::SyntheticHandEdges(v / 4, v % 4, 4, 600)))
                    .ok());
  }
  auto summary = w.Finish();
  ASSERT_TRUE(summary.ok());
  manifest.AddShard(*summary);
  ASSERT_TRUE(WriteManifest(db, manifest).ok());
  const fs::path png = *dir_ / "v.png";
  CliRun r = Handdb("show " + db.string() + " --view 5 --roll 3 -o " + png.string());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(Slurp(png).find("tEXtDescription"), std::string::npos);  // the caption, as text
  const fs::path out = *dir_ / "v.json";
  r = Handdb("query " + db.string() + " " + png.string() + " --json --top 3", out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(r.err, "");  // no decoder warning about the text chunk either
  const auto result = nlohmann::json::parse(Slurp(out));
  EXPECT_EQ(result["input_kind"], "edges");
  const auto& best = result["matches"][0];
  EXPECT_EQ(best["view_id"], 5) << best.dump();
  EXPECT_EQ(best["roll"], 3) << best.dump();
  EXPECT_LT(best["distance"].get<double>(), 1.0) << best.dump();
  EXPECT_GT(result["matches"][1]["distance"].get<double>(), 2 * best["distance"].get<double>());
  // --caption still draws it for people (and is then not meant as a query input).
  EXPECT_EQ(
      Handdb("show " + db.string() + " --view 5 --caption -o " + (*dir_ / "c.png").string()).code,
      0);
}

// The output directory is flock'ed: a second writer (generate or convert) into one --out is
// refused at once with one line. A bad config leaves no OUT/render/ behind.
TEST_F(HardeningCli, SecondWriterIsRefusedAndABadConfigLeavesNoDirectory) {
  const fs::path out = *dir_ / "locked-out";
  fs::create_directories(out);
  {
    auto held = DirectoryLock::Acquire(out);  // as a running generate holds it
    ASSERT_TRUE(held.ok());
    const std::string busy = out.string() +
                             ": another handdb process is writing here (its lock is held); wait "
                             "for it to finish or use another directory\n";
    CliRun r = Handdb("generate configs/demo.json -q --out " + out.string());
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_EQ(r.err, "handdb generate: " + busy);
    EXPECT_FALSE(fs::exists(out / "render" / "plan.json"));  // nothing written beside the owner
    r = Handdb("convert " + (*dir_ / "no-render").string() + " -q --out " + out.string());
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_EQ(r.err, "handdb convert: " + busy);
  }
  const fs::path config = *dir_ / "bad-pairs.json";
  std::ofstream(config) << R"({"seed": 0, "shapes": {"method": "pairs", "k": 1000},
                              "views": {"method": "fibonacci", "count": 86}})";
  const fs::path fresh = *dir_ / "never-made";
  const CliRun r = Handdb("generate " + config.string() + " -q --out " + fresh.string());
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(Lines(r.err), 1) << r.err;
  EXPECT_FALSE(fs::exists(fresh));
}

// Reads a file whole (binary), for editing a copy.
std::string ReadAll(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// Output paths that are a device or a FIFO were replaced by a regular file (the atomic rename
// went over them; as root, `-o /dev/null` replaced /dev/null). They are written in place now.
TEST_F(HardeningCli, DeviceAndFifoOutputsAreWrittenNotReplaced) {
  const fs::path dev = *dir_ / "null-device";
  if (::mknod(dev.c_str(), S_IFCHR | 0666, makedev(1, 3)) != 0) {
    GTEST_SKIP() << "cannot mknod here: " << std::strerror(errno);
  }
  const std::string q = (*dir_ / "q.pgm").string();
  const std::vector<std::string> runs = {
      "query " + Db() + " " + q + " --input edges -q --sheet " + dev.string(),
      "show " + Db() + " --view 1 -o " + dev.string(),
      "plan configs/demo.json -o " + dev.string(),
  };
  for (const std::string& args : runs) {
    SCOPED_TRACE(args);
    const CliRun r = Handdb(args);
    EXPECT_EQ(r.code, 0) << r.err;
    struct stat st {};
    ASSERT_EQ(::stat(dev.c_str(), &st), 0);
    EXPECT_TRUE(S_ISCHR(st.st_mode)) << "replaced by a regular file";
  }
  // A FIFO with a reader receives the bytes; one without is one line, exit 1.
  const fs::path fifo = *dir_ / "plan-fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  const fs::path got = *dir_ / "plan-from-fifo.json";
  ASSERT_EQ(
      std::system(("(timeout 20 cat " + fifo.string() + " > " + got.string() + ") &").c_str()), 0);
  CliRun r = Handdb("plan configs/demo.json -o " + fifo.string());
  EXPECT_EQ(r.code, 0) << r.err;
  for (int i = 0; i < 100 && Slurp(got).find("\"units\"") == std::string::npos; ++i) {
    ::usleep(50000);
  }
  EXPECT_NE(Slurp(got).find("\"units\""), std::string::npos);
  struct stat st {};
  ASSERT_EQ(::stat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
  r = Handdb("plan configs/demo.json -o " + fifo.string());
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(r.err, "handdb plan: " + fifo.string() + ": a FIFO with no reader\n");
}

// Manifest integers were cut to their field's 32 bits: rolls 2^32 + 12 searched 12 rolls; a
// label count of 2^32 + 1 validated; 2^64 + 12 (a float to the parser) showed as "252 x 0".
TEST_F(HardeningCli, ManifestIntegersBeyondTheirTypeAreRefused) {
  const nlohmann::json original = nlohmann::json::parse(Slurp(*dir_ / "db" / "manifest.json"));
  const std::string q = (*dir_ / "q.pgm").string();
  struct Case {
    std::string name;
    std::string pointer;
    nlohmann::json value;
    std::string message;
  };
  const std::vector<Case> cases = {
      {"rolls32", "/rolls", 4294967308ull, "rolls is 4294967308, not an integer in 0..4294967295"},
      {"rolls64",
       "/rolls",
       nlohmann::json::parse("18446744073709551628"),
       "rolls is 1.8446744073709552e+19, not an integer in 0..4294967295"},
      {"count32",
       "/labels/0/count",
       4294967297ull,
       "labels[0].count is 4294967297, not an integer in 0..4294967295"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    nlohmann::json edited = original;
    edited[nlohmann::json::json_pointer(c.pointer)] = c.value;
    const std::string db = DbWithManifest(
        "int-" + c.name, [&](const fs::path& m) { std::ofstream(m) << edited.dump(); });
    for (const std::string cmd : {"info", "validate", "query"}) {
      SCOPED_TRACE(cmd);
      const CliRun r = Handdb(cmd + " " + db + (cmd == "query" ? " " + q + " --input edges" : "") +
                              (cmd == "validate" ? " -q" : ""));
      EXPECT_EQ(r.code, 1) << r.err;
      EXPECT_NE(r.err.find(db + "/manifest.json: " + c.message), std::string::npos) << r.err;
      EXPECT_EQ(Lines(r.err), 1) << r.err;
    }
  }
}

// A NUL byte ended JSON parsing: whatever followed was ignored (a config, a manifest and shard
// metadata with "\0junk" appended were accepted).
TEST_F(HardeningCli, NulBytesInJsonAreRefusedNamingTheOffset) {
  const std::string demo = ReadAll(fs::path(HANDDB_SOURCE_DIR) / "configs" / "demo.json");
  const fs::path config = *dir_ / "nul-config.json";
  std::ofstream(config, std::ios::binary) << demo << std::string("\0junk", 5);
  CliRun r = Handdb("plan " + config.string() + " -o " + (*dir_ / "nul-plan.json").string());
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(r.err,
            "handdb plan: " + config.string() + ": NUL byte at offset " +
                std::to_string(demo.size()) + " (not allowed in JSON text)\n");
  EXPECT_FALSE(fs::exists(*dir_ / "nul-plan.json"));

  const std::string manifest = ReadAll(*dir_ / "db" / "manifest.json");
  const std::string db = DbWithManifest("nul-db", [&](const fs::path& m) {
    std::ofstream(m, std::ios::binary) << manifest << std::string("\0junk{{", 7);
  });
  r = Handdb("validate " + db + " -q");
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_NE(r.err.find(db + "/manifest.json: NUL byte at offset " +
                       std::to_string(manifest.size()) + " (not allowed in JSON text)"),
            std::string::npos)
      << r.err;

  const std::string metadata_db = WriteDb(*dir_ / "nul-metadata",
                                          std::string("{\"unit\": 0}\0junk", 16),
                                          12,
                                          [](std::vector<uint8_t>*) {});
  r = Handdb("validate " + metadata_db + "/shard-00000.hdb");
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_NE(r.err.find("metadata section: NUL byte at offset 11 (not allowed in JSON text)"),
            std::string::npos)
      << r.err;
}

// A test-set config's seed of 2^64 was recorded as 0; plan-time numbers that overflow (a PCA
// scale of 1e308) are refused naming the field; an icosahedron of 655,362 directions is refused
// from the config before 200 s of sampling.
TEST_F(HardeningCli, ConfigNumbersAreCheckedBeforeTheyAreUsed) {
  nlohmann::json testset =
      nlohmann::json::parse(ReadAll(fs::path(HANDDB_SOURCE_DIR) / "configs" / "testset-demo.json"));
  testset["seed"] = nlohmann::json::parse("18446744073709551616");
  const fs::path testset_config = *dir_ / "testset-seed.json";
  std::ofstream(testset_config) << testset.dump();
  CliRun r = Handdb("testset " + testset_config.string() + " --out " + (*dir_ / "ts").string());
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(r.err,
            "handdb testset: " + testset_config.string() +
                ": seed is 1.8446744073709552e+19, not an integer in 0..18446744073709551615\n");
  EXPECT_FALSE(fs::exists(*dir_ / "ts"));

  const fs::path pca = *dir_ / "pca-scale.json";
  std::ofstream(pca) << R"({"seed": 0, "shapes": {"method": "pca", "count": 4, "scale": 1e308},
                           "views": {"method": "fibonacci", "count": 10}})";
  r = Handdb("plan " + pca.string() + " -o " + (*dir_ / "pca-plan.json").string());
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(r.err.rfind("handdb plan: " + pca.string() +
                            ": shapes: scale 1e+308 gives a coefficient or joint angle that is "
                            "not finite",
                        0),
            0u)
      << r.err;
  EXPECT_EQ(Lines(r.err), 1) << r.err;

  const fs::path ico = *dir_ / "ico8.json";
  std::ofstream(ico) << R"({"seed": 0, "shapes": {"method": "basic", "names": ["fist"]},
                           "views": {"method": "icosahedron", "subdivisions": 8}})";
  const auto start = std::chrono::steady_clock::now();
  r = Handdb("plan " + ico.string() + " -o " + (*dir_ / "ico-plan.json").string());
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(10));
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(r.err,
            "handdb plan: " + ico.string() +
                ": views: icosahedron subdivisions 8 give 655362 directions, more than the 250000 "
                "renders a plan may hold\n");
}

// evaluate followed a test-set label of ../../../../etc/passwd or /dev/zero, and counted a
// missing label a miss (exit 0).
TEST_F(HardeningCli, TestSetLabelsOutsideTheTestSetOrMissingAreRefused) {
  const nlohmann::json two = nlohmann::json::parse(ReadAll(
      fs::path(HANDDB_SOURCE_DIR) / "tests" / "fuzz" / "corpus" / "testset" / "two-views.json"));
  for (const std::string label : {"../../../../etc/passwd", "/dev/zero"}) {
    SCOPED_TRACE(label);
    nlohmann::json edited = two;
    edited["items"][0]["label"] = label;
    const fs::path set = *dir_ / "escape-set";
    fs::create_directories(set);
    std::ofstream(set / "testset.json") << edited.dump();
    const CliRun r = Handdb("evaluate " + Db() + " " + set.string() + " -q");
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_EQ(r.err,
              "handdb evaluate: " + (set / "testset.json").string() + ": items[0].label is \"" +
                  label + "\", not a relative path inside the test set's directory\n");
  }
  const fs::path set = *dir_ / "missing-set";
  fs::create_directories(set);
  std::ofstream(set / "testset.json") << two.dump();
  const CliRun r = Handdb("evaluate " + Db() + " " + set.string() + " -q");
  EXPECT_EQ(r.code, 1) << r.err;
  // After the synthetic database's warning about its edge options: the one error line.
  const std::string error = "handdb evaluate: " + (set / "units/u00000/r000000.exr").string() +
                            ": no such file (clean input of test view 0 in " +
                            (set / "testset.json").string() + ")\n";
  ASSERT_GE(r.err.size(), error.size()) << r.err;
  EXPECT_EQ(r.err.substr(r.err.size() - error.size()), error);
}

// A JPEG with a damaged body was searched with libjpeg's stray "Corrupt JPEG data" line; a
// damaged PNG printed "libpng error: ..." before handdb's line; a TIFF (whose size no header
// check reads) was decoded at any size. Each is one line naming the file now.
TEST_F(HardeningCli, DamagedOrUncheckedPicturesAreOneLine) {
  const cv::Mat img = cv::imread((*dir_ / "q.pgm").string(), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(img.empty());
  const fs::path jpg = *dir_ / "damaged.jpg";
  ASSERT_TRUE(cv::imwrite(jpg.string(), img));
  std::string bytes = ReadAll(jpg);
  const size_t sos = bytes.find("\xFF\xDA");
  ASSERT_NE(sos, std::string::npos);
  for (size_t i = sos + 100; i < sos + 160 && i + 2 < bytes.size(); ++i) bytes[i] ^= 0x5A;
  std::ofstream(jpg, std::ios::binary) << bytes;
  CliRun r = Handdb("query " + Db() + " " + jpg.string() + " --input edges");
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(r.err.rfind("handdb query: " + jpg.string() + ": corrupt JPEG: ", 0), 0u) << r.err;
  EXPECT_EQ(Lines(r.err), 1) << r.err;

  const fs::path png =
      fs::path(HANDDB_SOURCE_DIR) / "tests" / "data" / "images" / "corrupt_crc.png";
  r = Handdb("query " + Db() + " " + png.string());
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(r.err, "handdb query: " + png.string() + ": corrupt PNG: IDAT: CRC error\n");

  const fs::path tiff = *dir_ / "q.tiff";
  ASSERT_TRUE(cv::imwrite(tiff.string(), img));
  r = Handdb("query " + Db() + " " + tiff.string());
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(r.err,
            "handdb query: " + tiff.string() +
                ": not a PNG, JPEG, PNM or BMP image (the formats read)\n");
}

// stdout on a full disk named the wrong reason ("Inappropriate ioctl for device", "No such file
// or directory", "write error"): the failed write's own errno is reported.
TEST_F(HardeningCli, StdoutOnFullDiskNamesNoSpaceLeft) {
  const std::string q = (*dir_ / "q.pgm").string();
  const std::string plan = (*dir_ / "plan-full.json").string();
  const std::vector<std::pair<std::string, std::string>> runs = {
      {"info", "info " + Db() + " --json"},
      {"info", "info " + Db()},
      {"validate", "validate " + Db() + " --json -q"},
      {"query", "query " + Db() + " " + q + " --input edges"},
      {"query", "query " + Db() + " " + q + " --input edges --json"},
      {"plan", "plan configs/demo.json -o " + plan + " --json"},
      {"version", "version"},
      {"version", "--version"},
      {"help", "--help"},
  };
  for (const auto& [name, args] : runs) {
    SCOPED_TRACE(args);
    const CliRun full = Handdb(args, "/dev/full");
    EXPECT_EQ(full.code, 1) << full.err;
    EXPECT_EQ(full.err, "handdb " + name + ": cannot write to stdout: No space left on device\n");
  }
}

// A landmark model that cannot be loaded is a bad file, not bad usage: exit 1 and one line naming
// the file and the problem, whatever is wrong with it; a directory, a FIFO or a device is named
// as what it is, not as a missing file (and a FIFO is not opened, so nothing blocks).
TEST_F(HardeningCli, BadLandmarkModelsAreExitOneNamingTheFile) {
  const std::string query = "query " + Db() + " " + (*dir_ / "q.pgm").string() + " --landmarks ";
  const fs::path real = fs::path(HANDDB_SOURCE_DIR) / "third_party" / "assets" / "mediapipe-hands" /
                        "hand_landmark_full.tflite";
  const fs::path models = *dir_ / "models";
  fs::create_directories(models / "a-directory.tflite");
  const fs::path fifo = models / "fifo.tflite";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0) << std::strerror(errno);
  std::ofstream(models / "empty.tflite");
  std::string random(4096, '\0');
  for (size_t i = 0; i < random.size(); ++i) random[i] = static_cast<char>((i * 2654435761u) >> 13);
  std::ofstream(models / "random.tflite", std::ios::binary) << random;
  // The TFL3 identifier after a root offset that points far outside the file.
  const std::string header = std::string("\xfc\xff\xff\x0fTFL3", 8) + std::string(56, '\xff');
  std::ofstream(models / "header.tflite", std::ios::binary) << header;
  std::vector<std::pair<fs::path, std::string>> cases = {
      {models / "a-directory.tflite", "a directory, not a model file"},
      {fifo, "a FIFO, not a model file"},
      {"/dev/zero", "a device, not a model file"},
      {models / "empty.tflite", ""},
      {models / "random.tflite", ""},
      {models / "header.tflite", ""},
  };
  if (fs::exists(real)) {
    std::ifstream in(real, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    for (const size_t keep : {size_t{16}, size_t{1000}, bytes.size() / 2, bytes.size() - 1}) {
      const fs::path cut = models / ("cut-" + std::to_string(keep) + ".tflite");
      std::ofstream(cut, std::ios::binary) << bytes.substr(0, keep);
      cases.emplace_back(cut, "");
    }
  }
  for (const auto& [model, problem] : cases) {
    const CliRun r = Handdb(query + model.string());
    EXPECT_EQ(r.code, 1) << model << ": " << r.err;
    EXPECT_EQ(Lines(r.err), 1) << r.err;
    const std::string prefix = "handdb query: --landmarks: " + model.string() + ": ";
    EXPECT_EQ(r.err.rfind(prefix, 0), 0u) << r.err;
    if (!problem.empty()) {
      EXPECT_EQ(r.err, prefix + problem + "\n");
    }
  }
  // `handdb evaluate --photos` shares the flag and its exit code.
  const fs::path no_photos = *dir_ / "no-photos";
  fs::create_directories(no_photos);
  const CliRun r = Handdb("evaluate " + Db() + " --photos " + no_photos.string() +
                          " -q --landmarks " + (models / "random.tflite").string());
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(r.err.rfind("handdb evaluate: --landmarks: " + (models / "random.tflite").string(), 0),
            0u)
      << r.err;
  // So does a test set's photo evaluation, whose model is the installed one
  // ($HANDDB_LANDMARK_MODEL).
  ASSERT_EQ(setenv("HANDDB_LANDMARK_MODEL", (models / "random.tflite").c_str(), 1), 0);
  const CliRun t = Handdb("evaluate " + Db() + " " + no_photos.string() + " --input photo -q");
  unsetenv("HANDDB_LANDMARK_MODEL");
  EXPECT_EQ(t.code, 1) << t.err;
  EXPECT_EQ(Lines(t.err), 1) << t.err;
  EXPECT_NE(t.err.find((models / "random.tflite").string()), std::string::npos) << t.err;
}

// A flag CLI11 rejects is bad usage in one line naming the command and the flag (exit 2), like
// every other error, not CLI11's two lines without the command.
TEST_F(HardeningCli, RejectedFlagsAreOneLineNamingTheCommand) {
  const std::string query = "query " + Db() + " " + (*dir_ / "q.pgm").string() + " ";
  for (const std::string flags : {"--top 0", "--top x", "--per-shape -1", "--no-such-flag"}) {
    const CliRun r = Handdb(query + flags);
    EXPECT_EQ(r.code, 2) << flags;
    EXPECT_EQ(Lines(r.err), 1) << r.err;
    EXPECT_EQ(r.err.rfind("handdb query: ", 0), 0u) << r.err;
  }
  EXPECT_EQ(Handdb(query + "--top 0").err.rfind("handdb query: --top: ", 0), 0u);
  EXPECT_EQ(Handdb("query --help").code, 0);
}

// A coded view damaged past what Open checks: `show` says which shard and view in one line (not
// "internal error", not "point code: point code"), exit 1.
TEST_F(HardeningCli, ShowOfADamagedCodedViewNamesTheShardAndView) {
  const fs::path db = *dir_ / "coded-db";
  fs::create_directories(db);
  const fs::path shard_path = db / "shard-00000.hdb";
  ShardWriterOptions options;
  options.coded = true;
  ShardWriter w;
  ASSERT_TRUE(w.Open(shard_path, options).ok());
  for (uint32_t v = 0; v < 4; ++v) {
    ASSERT_TRUE(
        w.AddView(testing::SyntheticViewLabel(v, 4), testing::SyntheticEdgeSet(v, 300)).ok());
  }
  auto summary = w.Finish();
  ASSERT_TRUE(summary.ok());
  Manifest manifest;
  manifest.tool_version = "hardening_cli_test";
  manifest.rolls = 12;
  manifest.AddShard(*summary);
  ASSERT_TRUE(WriteManifest(db, manifest).ok());
  ASSERT_EQ(Handdb("show " + db.string() + " --view 0 -o " + (*dir_ / "coded.png").string()).code,
            0);

  std::ifstream in(shard_path, std::ios::binary);
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                             std::istreambuf_iterator<char>());
  in.close();
  testing::DamageFirstPointCode(&bytes);
  std::ofstream(shard_path, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
  summary->checksum = shard::ChecksumHex(shard::Checksum(bytes.data(), bytes.size()));
  Manifest damaged;
  damaged.tool_version = "hardening_cli_test";
  damaged.rolls = 12;
  damaged.AddShard(*summary);
  ASSERT_TRUE(WriteManifest(db, damaged).ok());

  const CliRun r = Handdb("show " + db.string() + " --view 0 -o " + (*dir_ / "bad.png").string());
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(Lines(r.err), 1) << r.err;
  EXPECT_EQ(r.err.rfind("handdb show: " + shard_path.string() + ": offset ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find(": view 0: point code: "), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("point code: point code"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("internal error"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(*dir_ / "bad.png"));
}

// An edge image whose edges are a filled area, and a picture too thin to hold a hand: one line
// naming the picture and the limit, exit 1, before any search (and quickly: the 2000 x 2000 white
// edge image took 2.6 GB and many seconds).
TEST_F(HardeningCli, EdgeImagesPastTheLimitsAndThinPicturesAreOneLine) {
  const std::string query = "query " + Db() + " ";
  const fs::path white = *dir_ / "white-2000.png";
  ASSERT_TRUE(cv::imwrite(white.string(), cv::Mat(2000, 2000, CV_8U, cv::Scalar(255))));
  CliRun r = Handdb(query + white.string() + " --input edges");
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(r.err,
            "handdb query: " + white.string() +
                ": 4000000 edge pixels, more than the 1048576 an edge image may have (edges are "
                "lines, not filled areas)\n");
  const fs::path square = *dir_ / "white-600.png";
  ASSERT_TRUE(cv::imwrite(square.string(), cv::Mat(600, 600, CV_8U, cv::Scalar(255))));
  r = Handdb(query + square.string() + " --input edges");
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(Lines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("handdb query: " + square.string() +
                       ": 360000 edge points, more than the "
                       "65536 a query may have"),
            std::string::npos)
      << r.err;
  const fs::path strip = *dir_ / "strip-2000x1.png";
  ASSERT_TRUE(cv::imwrite(strip.string(), cv::Mat(1, 2000, CV_8UC3, cv::Scalar(120, 150, 210))));
  r = Handdb(query + strip.string());
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_EQ(r.err,
            "handdb query: " + strip.string() +
                ": a 2000x1 picture is too thin to hold a hand (16 px each way at least)\n");
}

}  // namespace
}  // namespace handdb
