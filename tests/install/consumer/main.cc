// consumer DB IMAGE: the README's "From C++" example, built against an installed handdb.
// Prints the top match as "top match: view V roll R D_c D shape NAME".
#include <cstdio>

#include "query/input/image_edges.h"
#include "query/searcher.h"

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: consumer DB IMAGE\n");
    return 2;
  }
  auto searcher = handdb::Searcher::Open(argv[1]);  // mmaps every shard; open checks run
  if (!searcher.ok()) {
    std::fprintf(stderr, "consumer: %s\n", searcher.status().message().c_str());
    return 1;
  }
  auto edges = handdb::LoadQueryEdges(argv[2], handdb::ImageEdgeOptions{});
  if (!edges.ok()) {
    std::fprintf(stderr, "consumer: %s\n", edges.status().message().c_str());
    return 1;
  }
  handdb::SearchOptions options;
  options.top_k = 3;
  const auto points = edges->points_px();  // normalised frame, px
  auto matches = (*searcher)->Search(points, options);
  if (!matches.ok() || matches->empty()) {
    std::fprintf(stderr, "consumer: %s\n", matches.status().message().c_str());
    return 1;
  }
  const handdb::Match& m = matches->front();
  std::printf("top match: view %u roll %u D_c %.3f shape %s\n",
              m.view_id,
              m.roll,
              m.distance,
              m.shape_name.c_str());
  return 0;
}
