// The C interface of PCL's kd-tree backend (libhanddb_pcl_kdtree.so, query/kdtree_pcl_plugin.cc):
// PCL's KdTreeFLANN brings pcl_common, pcl_kdtree and lz4 (~5,400 symbol relocations, a third of
// every command's) into a process that links it, and only `--kdtree pcl` uses it, so
// query/kdtree.cc opens the plugin (dlopen) on the first such tree. Plain C types only.
#pragma once

#include <stddef.h>
#include <stdint.h>

// The plugin is built with hidden symbols; these four are its exports.
#define HANDDB_PCL_KDTREE_EXPORT __attribute__((visibility("default")))

extern "C" {

// Bumped when a function's meaning or signature changes; the loader refuses another version.
#define HANDDB_PCL_KDTREE_ABI 1

struct handdb_pcl_kdtree;

// The ABI version the plugin was built with.
HANDDB_PCL_KDTREE_EXPORT int handdb_pcl_kdtree_abi(void);

// A tree over n points, x and y interleaved (n >= 1); null when it cannot be built.
HANDDB_PCL_KDTREE_EXPORT struct handdb_pcl_kdtree* handdb_pcl_kdtree_new(const float* xy, size_t n);

// The index of one nearest point to (x, y) (the backend's choice among ties). Thread-safe.
HANDDB_PCL_KDTREE_EXPORT uint32_t handdb_pcl_kdtree_nearest(const struct handdb_pcl_kdtree* tree,
                                                            float x,
                                                            float y);

HANDDB_PCL_KDTREE_EXPORT void handdb_pcl_kdtree_delete(struct handdb_pcl_kdtree* tree);
}
