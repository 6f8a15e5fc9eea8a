#include "edges/exr_io.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "base/atomic_file.h"
#include "base/testing.h"
#include "edges/synthetic_hand.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

class ExrIo : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = handdb::testing::TempDir(
        std::string("exr_io_") + ::testing::UnitTest::GetInstance()->current_test_info()->name());
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Writes arbitrary float channels (for malformed inputs).
  void WriteRaw(const fs::path& path,
                int w,
                int h,
                const std::vector<std::string>& names,
                const std::vector<float>& pixels) {
    // pixels are interleaved, names.size() floats per pixel.
    const size_t nch = names.size();
    Imf::Header header(w, h);
    Imf::FrameBuffer frame;
    for (size_t c = 0; c < nch; ++c) {
      header.channels().insert(names[c], Imf::Channel(Imf::FLOAT));
      frame.insert(names[c],
                   Imf::Slice(Imf::FLOAT,
                              reinterpret_cast<char*>(const_cast<float*>(pixels.data() + c)),
                              sizeof(float) * nch,
                              sizeof(float) * nch * static_cast<size_t>(w)));
    }
    Imf::OutputFile out(path.c_str(), header);
    out.setFrameBuffer(frame);
    out.writePixels(h);
  }

  fs::path dir_;
};

TEST_F(ExrIo, RoundTripsABlenderStyleLabelImage) {
  SyntheticHandParams params;
  params.folded[2] = true;
  const SyntheticHand hand = RenderSyntheticHand(params);
  const fs::path path = dir_ / "r000000.exr";
  ASSERT_TRUE(WriteLabelExr(path, hand.image).ok());
  ExrReadOptions opt;
  opt.expected_width = 256;
  opt.expected_height = 256;
  auto img = ReadLabelExr(path, opt);
  ASSERT_TRUE(img.ok()) << img.status().ToString();
  EXPECT_EQ(img->width, 256);
  EXPECT_EQ(img->labels, hand.image.labels);
  EXPECT_EQ(img->depth, hand.image.depth);
}

TEST_F(ExrIo, RoundTripsHalfFloatAndBlenderCombinedPass) {
  const SyntheticHand hand = RenderSyntheticHand(SyntheticHandParams{});
  ExrWriteOptions options;
  options.half = true;
  options.combined_pass = true;
  options.layer = "View Layer";
  const fs::path path = dir_ / "half.exr";
  const Status written = WriteLabelExr(path, hand.image, options);
  ASSERT_TRUE(written.ok()) << written.ToString();
  auto img = ReadLabelExr(path, ExrReadOptions{});
  ASSERT_TRUE(img.ok()) << img.status().ToString();
  EXPECT_EQ(img->labels, hand.image.labels);  // small integers are exact in half floats
  for (size_t i = 0; i < img->labels.size(); ++i) {
    if (img->labels[i] != 0) {
      EXPECT_NEAR(img->depth[i], hand.image.depth[i], 1e-3);
    }
  }
}

TEST_F(ExrIo, FindsChannelsByDottedSuffixAmongOthers) {
  const int w = 4, h = 3;
  std::vector<float> px;
  for (int i = 0; i < w * h; ++i) {
    px.insert(px.end(), {0.5f, 0.25f, 0.1f, 1.0f, 2.0f + i, static_cast<float>(i % 17)});
  }
  const fs::path path = dir_ / "multi.exr";
  WriteRaw(path,
           w,
           h,
           {"View Layer.Combined.R",
            "View Layer.Combined.G",
            "View Layer.Combined.B",
            "View Layer.Combined.A",
            "View Layer.Depth.Z",
            "View Layer.IndexMA.X"},
           px);
  auto img = ReadLabelExr(path, ExrReadOptions{});
  ASSERT_TRUE(img.ok()) << img.status().ToString();
  for (int i = 0; i < w * h; ++i) {
    EXPECT_EQ(img->labels[i], i % 17);
    EXPECT_EQ(img->depth[i], 2.0f + i);
  }
}

TEST_F(ExrIo, MissingLabelChannel) {
  const fs::path path = dir_ / "nolabel.exr";
  WriteRaw(path, 2, 2, {"ViewLayer.Depth.Z"}, {1, 1, 1, 1});
  auto img = ReadLabelExr(path, ExrReadOptions{});
  ASSERT_FALSE(img.ok());
  EXPECT_EQ(img.status().code(), StatusCode::kBadImage);
  EXPECT_NE(img.status().message().find("nolabel.exr"), std::string::npos);
  EXPECT_NE(img.status().message().find("IndexMA.X"), std::string::npos);
  EXPECT_NE(img.status().message().find("ViewLayer.Depth.Z"), std::string::npos);
}

TEST_F(ExrIo, MissingDepthChannel) {
  const fs::path path = dir_ / "nodepth.exr";
  WriteRaw(path, 2, 2, {"ViewLayer.IndexMA.X"}, {0, 1, 2, 3});
  EXPECT_EQ(ReadLabelExr(path, ExrReadOptions{}).status().code(), StatusCode::kBadImage);
  ExrReadOptions lenient;
  lenient.require_depth = false;
  auto img = ReadLabelExr(path, lenient);
  ASSERT_TRUE(img.ok());
  EXPECT_FALSE(img->has_depth());
}

TEST_F(ExrIo, LabelOutOfRangeOrFractional) {
  for (float bad : {17.0f, -1.0f, 2.5f, std::nanf("")}) {
    const fs::path path = dir_ / "bad.exr";
    WriteRaw(path,
             3,
             2,
             {"ViewLayer.Depth.Z", "ViewLayer.IndexMA.X"},
             {1, 0, 1, 1, 1, 2, 1, 3, 1, bad, 1, 0});
    auto img = ReadLabelExr(path, ExrReadOptions{});
    ASSERT_FALSE(img.ok()) << bad;
    EXPECT_EQ(img.status().code(), StatusCode::kOutOfRange);
    EXPECT_NE(img.status().message().find("pixel (1, 1)"), std::string::npos)
        << img.status().message();
  }
}

TEST_F(ExrIo, WrongSize) {
  LabelImage img;
  img.width = 8;
  img.height = 6;
  img.labels.assign(48, 0);
  img.depth.assign(48, 1.0f);
  const fs::path path = dir_ / "small.exr";
  ASSERT_TRUE(WriteLabelExr(path, img).ok());
  ExrReadOptions opt;
  opt.expected_width = 256;
  opt.expected_height = 256;
  auto r = ReadLabelExr(path, opt);
  EXPECT_EQ(r.status().code(), StatusCode::kSizeMismatch);
  EXPECT_NE(r.status().message().find("8x6, expected 256x256"), std::string::npos)
      << r.status().message();
}

TEST_F(ExrIo, TruncatedFile) {
  const SyntheticHand hand = RenderSyntheticHand(SyntheticHandParams{});
  const fs::path path = dir_ / "trunc.exr";
  ASSERT_TRUE(WriteLabelExr(path, hand.image).ok());
  const auto size = fs::file_size(path);
  for (double keep : {0.9, 0.5, 0.02}) {
    const fs::path cut = dir_ / ("cut" + std::to_string(static_cast<int>(keep * 100)) + ".exr");
    fs::copy_file(path, cut, fs::copy_options::overwrite_existing);
    fs::resize_file(cut, static_cast<uintmax_t>(static_cast<double>(size) * keep));
    auto r = ReadLabelExr(cut, ExrReadOptions{});
    ASSERT_FALSE(r.ok()) << keep;
    EXPECT_TRUE(r.status().code() == StatusCode::kTruncated ||
                r.status().code() == StatusCode::kBadImage)
        << r.status().ToString();
    EXPECT_NE(r.status().message().find(cut.filename().string()), std::string::npos);
  }
}

TEST_F(ExrIo, NotAnExrOrMissing) {
  EXPECT_EQ(ReadLabelExr(dir_ / "absent.exr", ExrReadOptions{}).status().code(),
            StatusCode::kNotFound);
  ASSERT_TRUE(WriteFileAtomic(dir_ / "text.exr", "hello, not an image").ok());
  EXPECT_EQ(ReadLabelExr(dir_ / "text.exr", ExrReadOptions{}).status().code(),
            StatusCode::kBadImage);
}

}  // namespace
}  // namespace handdb
