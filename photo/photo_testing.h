// Synthetic pictures for the photo path's tests: a hand drawn from edges/synthetic_hand.h as a
// photo-like image (skin-coloured links, darker lines between them, a noisy background) or as an
// edge image, written to a per-test temporary folder. Tests only.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>

#include "edges/edges.h"
#include "edges/synthetic_hand.h"

namespace handdb {

class SyntheticPictureTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("handdb-image-edges-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  static SyntheticHand Hand(double angle, double bend = 0.2) {
    SyntheticHandParams p;
    p.width = 320;
    p.height = 300;
    p.centre_x = 160;
    p.centre_y = 165;
    p.angle = angle;
    p.bend = {bend, -bend, 0.1, bend / 2, -0.1};
    return RenderSyntheticHand(p);
  }

  // A photo-like rendering: skin-coloured hand with darker lines between links, on a blue-grey
  // background with mild noise.
  std::filesystem::path WritePhoto(const LabelImage& li,
                                   const std::string& name,
                                   uint32_t seed = 1) {
    cv::Mat img(li.height, li.width, CV_8UC3);
    std::mt19937 rng(seed);
    std::uniform_int_distribution<int> noise(-6, 6);
    const EdgeResult e = ExtractEdges(li, DefaultJointPairs(), EdgeOptions{});
    cv::Mat internal = cv::Mat::zeros(li.height, li.width, CV_8U);
    for (const EdgePixel& p : e.edges) internal.at<uint8_t>(p.row, p.col) = 1;
    for (int y = 0; y < li.height; ++y) {
      for (int x = 0; x < li.width; ++x) {
        const bool hand = li.label(x, y) != 0;
        cv::Vec3i c = hand ? cv::Vec3i(120, 150, 210) : cv::Vec3i(140, 110, 90);  // BGR
        if (hand && internal.at<uint8_t>(y, x)) c = cv::Vec3i(70, 95, 150);
        for (int k = 0; k < 3; ++k) {
          img.at<cv::Vec3b>(y, x)[k] = cv::saturate_cast<uint8_t>(c[k] + noise(rng));
        }
      }
    }
    const std::filesystem::path path = dir_ / name;
    EXPECT_TRUE(cv::imwrite(path.string(), img));
    return path;
  }

  std::filesystem::path WriteEdgeImage(const LabelImage& li, const std::string& name) {
    cv::Mat img = cv::Mat::zeros(li.height, li.width, CV_8U);
    for (const EdgePixel& p : ExtractEdges(li, DefaultJointPairs(), EdgeOptions{}).edges) {
      img.at<uint8_t>(p.row, p.col) = 255;
    }
    const std::filesystem::path path = dir_ / name;
    EXPECT_TRUE(cv::imwrite(path.string(), img));
    return path;
  }

  std::filesystem::path dir_;
};

}  // namespace handdb
