// tinygltf as handdb builds it, for every file that includes it (pose/tiny_gltf.cc holds its one
// implementation): no image codecs and no external image files. The export copies the asset's
// images, if any, as the bytes they are; decoding them would only add stb to the build.
#pragma once

#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>
