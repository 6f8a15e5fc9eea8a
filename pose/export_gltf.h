// A pose as a file other tools open: the hand model's rigged asset (a glTF binary, .glb) posed
// with a joint vector, for Blender, web viewers and anything else that reads glTF skins.
//
// The asset's joints are flat siblings (docs/hand_model.md), so setting a rotation on one would
// not move its children. The export therefore parents the joint nodes as the rig does (wrist ->
// metacarpals -> phalanges -> tips) and gives each the local transform that makes its world
// transform the rig's posed bone (HandRig::PoseBones) in the asset's frame. The mesh, the skin's
// inverse bind matrices and every buffer are written unchanged (but for a left hand, below), so a
// viewer's skinning (joint world matrix times inverse bind matrix) deforms the mesh exactly as the
// renders' Blender did.
#pragma once

#include <filesystem>
#include <optional>

#include "base/status.h"
#include "format/view.h"
#include "generator/hand/kinematics.h"

namespace handdb {

struct PosedHandGlbOptions {
  // The rigged asset to pose; empty: the one the rig's hand model names (its asset path resolved
  // as a plan's paths are, generator/plan/plan.h ResolvePlanPath).
  std::filesystem::path asset;
  // When set, the file also holds an orthographic camera placed as the render camera of
  // generator/hand/camera.h: looking at the model's look_at point with this rotation (PoseFit's
  // cam_from_hand, or CamFromHand of a view direction and roll), so the hand seen through it is
  // the hand of the picture (image x right, y down; glTF's camera looks along its -z, +y up).
  std::optional<Mat3d> cam_from_hand;
  // That camera's width across its square image, in hand-frame units; 0: the hand model's
  // ortho_scale.
  double ortho_scale = 0;
  // The right hand's mirror image, a left hand (a match of query/searcher.h's Hand::kLeft, which
  // searched the mirrored picture). With a camera the mirror plane passes through look_at normal
  // to the camera's image x axis, so the camera sees the picture's hand as it is (the search
  // mirrored x of the query's frame); without, it is normal to the hand's thumb side
  // (forward_axis x palm_normal). The skin's vertices, normals, winding and inverse bind matrices
  // are mirrored with it, so every transform in the file stays a rotation (no negative scale for
  // a viewer to get wrong) and the faces keep their outside out. cam_from_hand stays the
  // right hand's camera, whose image mirrored left to right is the picture: for a left Match,
  // that of MirrorLabel(match.label), not of the label in the left hand's frame.
  bool left_hand = false;
  // ortho_scale finite and >= 0; cam_from_hand, if set, a rotation (orthonormal within 1e-6,
  // determinant +1).
  bool Check() const;
};

// Writes `out` atomically (base/atomic_file.h): a crash or an error leaves the old file or none.
// Errors are one line naming the file: kInvalidArgument (options failing Check(), non-finite
// joints, a camera asked for without any ortho_scale), the asset's read errors (kNotFound,
// kIoError), kBadMagic (not a glTF binary), kSchemaViolation (a glTF that does not load, or whose
// skin lacks a bone of the rig or holds it at another rest transform than the hand model's,
// beyond 1e-4), and the write's kIoError. Joints outside the limits are posed as given.
Status WritePosedHandGlb(const std::filesystem::path& out,
                         const HandRig& rig,
                         const JointVector& joints,
                         const PosedHandGlbOptions& options = {});

}  // namespace handdb
