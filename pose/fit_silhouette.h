// The hand's silhouette and edges as the pose fit reads them (pose/fit.h, the silhouette term):
// a capsule model of the rig's 16 links, and the picture's hand region and edge points turned
// into distance fields in the query's normalised frame. With them a fit needs no landmarks: the
// projected capsules are pulled inside the hand's region, over the whole of it, and their
// outlines onto the picture's edges (docs/photo.md "Fitted pose",
// docs/decisions/0016-silhouette-term-and-fit-choice.md).
#pragma once

#include <array>
#include <span>
#include <vector>

#include "base/status.h"
#include "format/roll.h"
#include "format/view.h"
#include "generator/hand/kinematics.h"

namespace handdb {

// A link's solid: the points within `radius` of the segment between two rig keypoints (a
// sphere-swept segment, whose orthographic projection is the 2D segment swept by a disc of the
// same radius).
struct HandCapsule {
  int from = 0;  // keypoint indices (docs/conventions.md order)
  int to = 0;
  double radius = 0;    // hand-frame units
  bool outline = true;  // its sides are the hand's outline (false: the palm's inner struts)
};

// 15 finger and thumb capsules, one per phalanx or metacarpal link, and 6 struts that fill the
// palm (wrist to each knuckle, across the knuckles, wrist to the thumb's base). The radii are
// the medians, per link, of the distance of the asset's skinned-mesh vertices (each given to the
// bone with its largest skin weight) from the link's segments at the rest pose, measured on the
// WebXR generic hand of the paper database (docs/decisions/0016): the hand model records bones,
// not flesh, and the mesh is the flesh the renders show. In units of the hand model; a rig of
// another size scales them by its wrist-to-middle-knuckle length over the asset's 0.0917.
std::vector<HandCapsule> HandCapsules(const HandRig& rig);

// The fit's distance fields on one square grid, normalised px: node (ix, iy) is at
// (origin_px + ix * cell_px, origin_px + iy * cell_px), row-major (y rows).
struct SilhouetteFields {
  double origin_px = 0;
  double cell_px = 1;
  int size = 0;  // nodes per side
  // Distance (px) from each node to the hand's region (0 inside it).
  std::vector<float> outside_hand;
  // Distance (px) from each node to the nearest edge point (the query's points: the silhouette's
  // outline and the edges inside it).
  std::vector<float> edges;
  // The silhouette's outline thinned to about one point per `outline_spacing_px`.
  std::vector<Point2f> outline;
};

struct SilhouetteFieldOptions {
  // The hand's region is the part of a grid of this step (px) that the outline encloses: coarse
  // enough that a small picture's outline pixels (up to ~2 normalised px apart) close it.
  double region_cell_px = 2.0;
  double outline_spacing_px = 6.0;
  bool Check() const;
};

// From the silhouette's outline pixels and the edge points, both in the normalised frame. The
// region is what the outline encloses (holes in it, as between a thumb and finger touching at
// their tips, count as hand). kInvalidArgument: no outline, no edge points, or an outline that
// encloses nothing (a few scattered pixels).
Result<SilhouetteFields> MakeSilhouetteFields(std::span<const Point2f> outline,
                                              std::span<const PointQ> edges,
                                              const SilhouetteFieldOptions& options = {});

// A capsule projected with a fit's camera: its segment's ends and its radius, normalised px.
struct ProjectedCapsule {
  Point2f from{};
  Point2f to{};
  double radius = 0;
};

// The capsules of `keypoints_in_hand` (FitKinematics or HandRig::Keypoints3d) through the fit's
// orthographic camera: scale * (cam_from_hand * (p - look_at)).xy + shift.
std::vector<ProjectedCapsule> ProjectCapsules(const std::vector<HandCapsule>& capsules,
                                              const HandKeypoints3d& keypoints_in_hand,
                                              const Mat3d& cam_from_hand,
                                              const Vec3d& look_at,
                                              double scale,
                                              const std::array<double, 2>& shift);

}  // namespace handdb
