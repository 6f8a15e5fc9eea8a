// The two backends of the TFLite runtime on the real landmark model (scripts/deps.sh --asset):
// random inputs, a grey one and real photos of hands (tests/data/photos, scaled to the input)
// give the same joints and presence up to float rounding, and a runtime is never shared by two
// threads at once. Skipped where XNNPACK is not built in or does not run on the CPU.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "base/image_decode.h"
#include "nn/tflite.h"

namespace handdb {
namespace {

namespace fs = std::filesystem;

fs::path SourceDir() {
  const char* env = std::getenv("HANDDB_SOURCE_DIR");
  return env != nullptr ? fs::path(env) : fs::path(".");
}

fs::path LandmarkModel() {
  const fs::path model =
      SourceDir() / "third_party" / "assets" / "mediapipe-hands" / "hand_landmark_full.tflite";
  THROW_CHECK_MSG(fs::exists(model), model.string() << " is missing: run scripts/deps.sh --asset");
  return model;
}

// A photo as the network's input: RGB in [0, 1], scaled bilinearly to w x h.
std::vector<float> PhotoInput(const fs::path& path, int w, int h) {
  DecodeOptions options;
  options.mode = DecodeOptions::Mode::kColor;
  auto image = DecodeImageFile(path, options);
  THROW_CHECK_MSG(image.ok(), image.status().ToString());
  std::vector<float> out(static_cast<size_t>(w) * h * 3);
  const auto at = [&](int x, int y, int c) {
    x = std::clamp(x, 0, image->width - 1);
    y = std::clamp(y, 0, image->height - 1);
    return image->pixels[(static_cast<size_t>(y) * image->width + x) * 3 + (2 - c)] / 255.0f;
  };
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const float sx = (x + 0.5f) * image->width / w - 0.5f;
      const float sy = (y + 0.5f) * image->height / h - 0.5f;
      const int x0 = static_cast<int>(std::floor(sx)), y0 = static_cast<int>(std::floor(sy));
      const float fx = sx - x0, fy = sy - y0;
      for (int c = 0; c < 3; ++c) {
        out[(static_cast<size_t>(y) * w + x) * 3 + c] =
            (1 - fy) * ((1 - fx) * at(x0, y0, c) + fx * at(x0 + 1, y0, c)) +
            fy * ((1 - fx) * at(x0, y0 + 1, c) + fx * at(x0 + 1, y0 + 1, c));
      }
    }
  }
  return out;
}

class TfliteBackendsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto portable = TfliteModel::Load(LandmarkModel(), TfliteBackend::kPortable);
    ASSERT_TRUE(portable.ok()) << portable.status().ToString();
    EXPECT_EQ(portable->backend(), TfliteBackend::kPortable);
    auto xnnpack = TfliteModel::Load(LandmarkModel(), TfliteBackend::kXnnpack);
    ASSERT_TRUE(xnnpack.ok()) << xnnpack.status().ToString();
    if (xnnpack->backend() != TfliteBackend::kXnnpack) {
      GTEST_SKIP() << "XNNPACK is not built in, or does not run on this CPU";
    }
    portable_ = std::make_unique<TfliteModel>(std::move(portable).value());
    xnnpack_ = std::make_unique<TfliteModel>(std::move(xnnpack).value());
  }

  std::vector<float> Random(uint32_t seed) const {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    std::vector<float> x(static_cast<size_t>(portable_->input_shape()[1]) *
                         portable_->input_shape()[2] * 3);
    for (float& v : x) v = u(rng);
    return x;
  }

  std::unique_ptr<TfliteModel> portable_, xnnpack_;
};

// XNNPACK sums the products in another order (and with FMAs): the joints, in the crop's 224
// px, agree to 2e-3 px (measured: at most 3e-4), the presence to 1e-6 (measured: at most
// 5e-8).
constexpr double kJointTolerancePx = 2e-3;
constexpr double kPresenceTolerance = 1e-6;

TEST_F(TfliteBackendsTest, AgreeOnRandomGreyAndRealInputs) {
  std::vector<std::pair<std::string, std::vector<float>>> inputs;
  for (uint32_t seed : {1u, 2u, 3u})
    inputs.emplace_back("random " + std::to_string(seed), Random(seed));
  inputs.emplace_back("grey", std::vector<float>(Random(0).size(), 0.5f));
  const int w = portable_->input_shape()[2], h = portable_->input_shape()[1];
  for (const auto& [shape, file] : std::vector<std::pair<std::string, std::string>>{
           {"asl-1", "IMG_1170.JPG"}, {"asl-5", "IMG_1174.JPG"}, {"asl-3", ""}}) {
    fs::path path = SourceDir() / "tests" / "data" / "photos" / "asl-digits" / shape / file;
    if (file.empty()) {
      for (const auto& e : fs::directory_iterator(path)) path = e.path();
    }
    inputs.emplace_back(shape + "/" + path.filename().string(), PhotoInput(path, w, h));
  }
  double max_joint = 0, max_presence = 0;
  for (const auto& [name, x] : inputs) {
    SCOPED_TRACE(name);
    const auto a = portable_->Run(x);
    const auto b = xnnpack_->Run(x);
    ASSERT_EQ(a.size(), b.size());
    for (size_t o = 0; o < a.size(); ++o) ASSERT_EQ(a[o].size(), b[o].size()) << "output " << o;
    double joint = 0;
    for (size_t i = 0; i < a[0].size(); ++i) {
      ASSERT_TRUE(std::isfinite(b[0][i]));
      joint = std::max(joint, std::abs(double{a[0][i]} - b[0][i]));
    }
    const double presence = std::abs(double{a[1][0]} - b[1][0]);
    EXPECT_LT(joint, kJointTolerancePx);
    EXPECT_LT(presence, kPresenceTolerance);
    std::printf("%-22s presence %.4f  max |joint difference| %.2e px  |presence difference| %.2e\n",
                name.c_str(),
                a[1][0],
                joint,
                presence);
    max_joint = std::max(max_joint, joint);
    max_presence = std::max(max_presence, presence);
  }
  std::printf("over all inputs: joints %.2e px, presence %.2e\n", max_joint, max_presence);
}

// Runs on several threads at once, each through the model's pool of runtimes: every result is
// the one a lone run gives, bit for bit (one runtime's arithmetic does not depend on the thread).
TEST_F(TfliteBackendsTest, ConcurrentRunsGiveTheLoneResults) {
  std::vector<std::vector<float>> inputs;
  std::vector<std::vector<std::vector<float>>> want;
  for (uint32_t seed = 10; seed < 14; ++seed) {
    inputs.push_back(Random(seed));
    want.push_back(xnnpack_->Run(inputs.back()));
  }
  std::vector<int> wrong(4, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      auto ws = xnnpack_->NewWorkspace();
      for (int r = 0; r < 3; ++r) {
        const size_t k = static_cast<size_t>(t + r) % inputs.size();
        if (xnnpack_->Run(inputs[k], ws.get()) != want[k]) ++wrong[t];
      }
    });
  }
  for (std::thread& t : threads) t.join();
  for (int t = 0; t < 4; ++t) EXPECT_EQ(wrong[t], 0) << "thread " << t;
}

// The environment chooses the default backend; a value it does not know is an error.
TEST(TfliteBackendTest, TheEnvironmentChoosesTheDefault) {
  const char* old = std::getenv("HANDDB_NN_BACKEND");
  const std::string saved = old != nullptr ? old : "";
  ::setenv("HANDDB_NN_BACKEND", "portable", 1);
  auto portable = TfliteModel::Load(LandmarkModel());
  ::setenv("HANDDB_NN_BACKEND", "gpu", 1);
  auto bad = TfliteModel::Load(LandmarkModel());
  if (old != nullptr) {
    ::setenv("HANDDB_NN_BACKEND", saved.c_str(), 1);
  } else {
    ::unsetenv("HANDDB_NN_BACKEND");
  }
  ASSERT_TRUE(portable.ok()) << portable.status().ToString();
  EXPECT_EQ(portable->backend(), TfliteBackend::kPortable);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("HANDDB_NN_BACKEND=gpu"), std::string::npos)
      << bad.status().ToString();
}

}  // namespace
}  // namespace handdb
