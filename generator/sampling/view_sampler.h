// Near-uniform view directions on the unit sphere (docs/generator.md) and their covering radius:
// the largest angle from any direction on the sphere to its nearest sample, i.e. the worst-case
// viewpoint error of a database built on the set before roll and shape are considered.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace handdb {

// Fibonacci (golden-angle spiral) lattice: z_i = 1 - (2i + 1)/n, phi_i = i * golden angle. Any n
// >= 1.
std::vector<Eigen::Vector3d> FibonacciDirections(int n);

// Vertices of the icosahedron subdivided `subdivisions` times (each triangle into 4, new vertices
// projected onto the sphere): 10 * 4^k + 2 directions, the 12 original vertices first.
std::vector<Eigen::Vector3d> IcosahedronDirections(int subdivisions);

// k with 10 * 4^k + 2 == count, or -1.
int IcosahedronSubdivisionsForCount(int count);

struct CoveringRadius {
  double radians = 0;  // exact: the largest empty-circle radius at a spherical Voronoi vertex found
  Eigen::Vector3d farthest = Eigen::Vector3d::UnitZ();  // the direction at that distance
  double dense_radians = 0;  // the plain dense-probe estimate (a lower bound), for comparison
};

// Probes `probes` Fibonacci directions; at each probe the circumcentre of its three nearest samples
// is a candidate Voronoi vertex, kept when no sample is closer than those three. Every Voronoi
// vertex whose region a probe falls into is found, so with enough probes (the default is plenty for
// a few thousand samples) the result is the exact covering radius.
CoveringRadius ComputeCoveringRadius(const std::vector<Eigen::Vector3d>& directions,
                                     int probes = 100000);

// Camera roll angles 2*pi*r/R, r = 0..R-1 (virtual: applied to point sets, never rendered).
std::vector<double> RollAngles(int num_rolls);

}  // namespace handdb
