// Pictures as cv::Mat, read as cv::imread reads them but decoded by base/image_decode.h for PNG
// and JPEG (a damaged file is one error naming it, never a decoder's line on stderr). PNM and
// BMP, whose headers base/image_file.h checks too, still go through OpenCV's imgcodecs, loaded
// (dlopen) on the first such picture rather than linked: it would load ~120 shared libraries into
// every process start. Any other format is refused before a decoder sees it (a 20000 x 20000 TIFF
// of 2 MB would otherwise be decoded).
#pragma once

#include <filesystem>
#include <opencv2/core/mat.hpp>

#include "base/status.h"

namespace handdb {

// `imread_flags`: cv::IMREAD_UNCHANGED, IMREAD_GRAYSCALE, IMREAD_COLOR or
// IMREAD_REDUCED_COLOR_{2,4,8}, with cv::imread's meaning (the same pixels). Errors are kBadImage
// or the file's kNotFound / kIoError, each naming the file.
Result<cv::Mat> ReadImage(const std::filesystem::path& path, int imread_flags);

}  // namespace handdb
