// The Searcher's threads: one pool sized at open, and nothing else. Its own binary, so the
// threads counted are this test's alone (gtest starts none).
#include <gtest/gtest.h>
#include <xxhash.h>

#include <filesystem>
#include <string>
#include <vector>

#include "base/atomic_file.h"
#include "base/hex.h"
#include "base/testing.h"
#include "base/thread_pool.h"
#include "format/manifest.h"
#include "format/shard_testing.h"
#include "format/shard_writer.h"
#include "query/index/view_index.h"
#include "query/search_testing.h"
#include "query/searcher.h"

namespace handdb {
namespace {

constexpr uint32_t kViews = 48;
constexpr uint32_t kRolls = 8;

// The process's threads, as the kernel lists them.
size_t CountThreads() {
  size_t n = 0;
  for ([[maybe_unused]] const auto& entry :
       std::filesystem::directory_iterator("/proc/self/task")) {
    ++n;
  }
  return n;
}

// Coded shards (their views summarised when the database opens) with an index listed in the
// manifest, as `handdb index` writes it; built on one thread.
std::filesystem::path WriteIndexedDatabase(const std::string& name) {
  const std::filesystem::path dir = ::handdb::testing::TempDir(name);
  Manifest m;
  m.tool_version = "test";
  m.rolls = kRolls;
  ShardWriterOptions shard_options;
  shard_options.coded = true;
  ShardWriter writer;
  THROW_CHECK(writer.Open(dir / "shard-00000.hdb", shard_options).ok());
  for (uint32_t v = 0; v < kViews; ++v) {
    const ViewLabel label = testing::SyntheticViewLabel(v, 12);
    THROW_CHECK(writer.AddView(label, ::handdb::testing::LatticePoints(label, v)).ok());
  }
  auto summary = writer.Finish();
  THROW_CHECK(summary.ok());
  m.AddShard(*summary);
  THROW_CHECK(WriteManifest(dir, m).ok());

  auto db = Database::Open(dir, false, 1);
  THROW_CHECK(db.ok());
  IndexBuildOptions options;
  options.grid.cell_units = 256;
  options.grid.side = 15;
  options.dims = 16;
  options.nlist = 4;
  options.num_threads = 1;
  auto index = ViewIndex::Build(*db, options);
  THROW_CHECK(index.ok());
  const std::string bytes = index->Serialize();
  const std::string sum = Hex64(XXH3_64bits(bytes.data(), bytes.size()));
  const std::string file = "index-" + sum + ".hdbi";
  THROW_CHECK(WriteFileAtomic(dir / file, bytes).ok());
  m.index = ManifestIndex{file, kIndexKind, bytes.size(), sum, nlohmann::json::object()};
  const Status written = WriteManifest(dir, m);
  THROW_CHECK_MSG(written.ok(), written.ToString());
  return dir;
}

// num_threads = 1: opening, preparing and every kind of search run on the calling thread.
TEST(SearcherThreads, OneThreadStartsNoOtherThreadInAnyPhase) {
  const std::filesystem::path dir = WriteIndexedDatabase("searcher_threads_one");
  ASSERT_EQ(CountThreads(), 1u);
  SearcherOptions open;
  open.num_threads = 1;
  auto searcher = Searcher::Open(dir, open);
  ASSERT_TRUE(searcher.ok()) << searcher.status().ToString();
  EXPECT_EQ(CountThreads(), 1u) << "after open";
  ASSERT_NE((*searcher)->index(), nullptr);  // the manifest lists one: attached
  (*searcher)->PrepareExactSearch();
  EXPECT_EQ(CountThreads(), 1u) << "after PrepareExactSearch";

  const std::vector<Point2f> query = testing::RolledView((*searcher)->database(), 7, 3);
  for (SearchMode mode : {SearchMode::kExact, SearchMode::kAuto}) {
    for (int per_shape : {0, 1}) {
      SearchOptions options;
      options.top_k = 5;
      options.hand = Hand::kEither;
      options.mode = mode;
      options.max_per_shape = per_shape;
      options.index.candidates = 60;
      SearchStats stats;
      auto matches = (*searcher)->Search(query, options, &stats);
      ASSERT_TRUE(matches.ok()) << matches.status().ToString();
      ASSERT_FALSE(matches->empty());
      const bool indexed = mode == SearchMode::kAuto;
      EXPECT_EQ(stats.mode, indexed ? SearchMode::kIndexed : SearchMode::kExact);
      EXPECT_EQ(stats.candidates > 0, indexed);
      EXPECT_EQ(CountThreads(), 1u) << SearchModeName(mode) << " per_shape " << per_shape;
    }
  }
  SearchOptions brute;
  brute.brute_force = true;
  ASSERT_TRUE((*searcher)->Search(query, brute).ok());
  EXPECT_EQ(CountThreads(), 1u) << "brute force";
}

// The pool is started once, at open, and every search reuses it: the thread count does not grow
// with searches, and a search capped below the pool gets the same matches.
TEST(SearcherThreads, OnePoolPerSearcherReusedByEverySearch) {
  const std::filesystem::path dir = WriteIndexedDatabase("searcher_threads_pool");
  SearcherOptions open;
  open.num_threads = 3;
  open.use_index = IndexUse::kExact;
  auto searcher = Searcher::Open(dir, open);
  ASSERT_TRUE(searcher.ok()) << searcher.status().ToString();
  EXPECT_EQ((*searcher)->index(), nullptr);  // opted out
  EXPECT_EQ((*searcher)->num_threads(), 3);
  const size_t after_open = CountThreads();
  EXPECT_EQ(after_open, 3u);  // the caller and the pool's two
  const std::vector<Point2f> query = testing::RolledView((*searcher)->database(), 11, 5);
  std::vector<Match> first;
  for (int threads : {-1, 1, 2, 3, 8}) {
    SearchOptions options;
    options.top_k = 8;
    options.num_threads = threads;
    auto matches = (*searcher)->Search(query, options);
    ASSERT_TRUE(matches.ok());
    EXPECT_EQ(CountThreads(), after_open) << threads << " threads";
    if (first.empty()) first = *matches;
    ASSERT_EQ(matches->size(), first.size());
    for (size_t i = 0; i < first.size(); ++i) {
      EXPECT_EQ((*matches)[i].view_id, first[i].view_id);
      EXPECT_EQ((*matches)[i].roll, first[i].roll);
      EXPECT_EQ((*matches)[i].distance, first[i].distance);
    }
  }
}

TEST(SearcherThreads, ThreadsThatCannotStartAreAnErrorOfOpen) {
  const std::filesystem::path dir = WriteIndexedDatabase("searcher_threads_fail");
  SetThreadStartLimitForTesting(1);
  SearcherOptions open;
  open.num_threads = 4;
  auto searcher = Searcher::Open(dir, open);
  auto db = std::make_shared<const Database>(testing::SyntheticDatabase(8, 40, 4));
  auto created = Searcher::Create(db, open);
  SetThreadStartLimitForTesting(-1);
  ASSERT_FALSE(searcher.ok());
  EXPECT_EQ(searcher.status().code(), StatusCode::kIoError);
  EXPECT_NE(searcher.status().message().find("cannot start 3 worker threads"), std::string::npos)
      << searcher.status().message();
  ASSERT_FALSE(created.ok());
  EXPECT_EQ(CountThreads(), 1u);  // what started was joined
}

TEST(SearcherOptions, CheckBoundsTheThreads) {
  SearcherOptions o;
  EXPECT_TRUE(o.Check());
  o.num_threads = MaxNumThreads();
  EXPECT_TRUE(o.Check());
  o.num_threads = MaxNumThreads() + 1;
  EXPECT_FALSE(o.Check());
  o.num_threads = 0;
  EXPECT_FALSE(o.Check());
  SearchOptions s;
  s.num_threads = MaxNumThreads() + 1;
  EXPECT_FALSE(s.Check());
  s.num_threads = 2;
  EXPECT_TRUE(s.Check());
  auto db = std::make_shared<const Database>(testing::SyntheticDatabase(8, 40, 4));
  SearcherOptions too_many;
  too_many.num_threads = 100000;
  auto created = Searcher::Create(db, too_many);
  ASSERT_FALSE(created.ok());
  EXPECT_EQ(created.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(created.status().message().find("at most 256"), std::string::npos);
}

TEST(SearcherOptions, IndexedWithoutAnIndexIsAnErrorOfOpen) {
  auto db = std::make_shared<const Database>(testing::SyntheticDatabase(8, 40, 4));
  SearcherOptions o;
  o.num_threads = 1;
  o.use_index = IndexUse::kIndexed;
  auto created = Searcher::Create(db, o);
  ASSERT_FALSE(created.ok());
  EXPECT_EQ(created.status().code(), StatusCode::kNotFound);
  o.use_index = IndexUse::kAuto;  // no index listed: exact
  created = Searcher::Create(db, o);
  ASSERT_TRUE(created.ok());
  EXPECT_EQ((*created)->ModeFor(SearchOptions{}), SearchMode::kExact);
  EXPECT_EQ(ParseIndexUse("indexed").value(), IndexUse::kIndexed);
  EXPECT_FALSE(ParseIndexUse("fast").ok());
}

}  // namespace
}  // namespace handdb
