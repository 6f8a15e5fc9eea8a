// libhanddb_pcl_kdtree.so: PCL's KdTreeFLANN behind the C interface of query/kdtree_pcl_plugin.h.
#include "query/kdtree_pcl_plugin.h"

#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <new>
#include <vector>

struct handdb_pcl_kdtree {
  pcl::PointCloud<pcl::PointXY>::Ptr cloud{new pcl::PointCloud<pcl::PointXY>};
  pcl::KdTreeFLANN<pcl::PointXY> tree;
};

extern "C" {

int handdb_pcl_kdtree_abi(void) { return HANDDB_PCL_KDTREE_ABI; }

handdb_pcl_kdtree* handdb_pcl_kdtree_new(const float* xy, size_t n) {
  try {
    auto* t = new handdb_pcl_kdtree;
    t->cloud->resize(n);
    for (size_t i = 0; i < n; ++i) {
      (*t->cloud)[i].x = xy[2 * i];
      (*t->cloud)[i].y = xy[2 * i + 1];
    }
    t->tree.setSortedResults(false);
    t->tree.setInputCloud(t->cloud);
    return t;
  } catch (...) {
    return nullptr;
  }
}

uint32_t handdb_pcl_kdtree_nearest(const handdb_pcl_kdtree* tree, float x, float y) {
  pcl::PointXY p;
  p.x = x;
  p.y = y;
  // KdTreeFLANN::nearestKSearch is const and thread-safe; the output vectors are ours.
  std::vector<int> indices(1);
  std::vector<float> sq(1);
  tree->tree.nearestKSearch(p, 1, indices, sq);
  return static_cast<uint32_t>(indices[0]);
}

void handdb_pcl_kdtree_delete(handdb_pcl_kdtree* tree) { delete tree; }
}
