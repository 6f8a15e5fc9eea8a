// tinygltf's one implementation in handdb. Debian's libtinygltf-dev also ships a shared library,
// but it links libstb for image codecs the export never uses, and every handdb command would load
// both at start-up (docs/architecture.md: start-up cost is part of the design).
#define TINYGLTF_IMPLEMENTATION
#include "pose/tiny_gltf_config.h"
