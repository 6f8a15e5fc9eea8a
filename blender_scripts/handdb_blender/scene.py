"""Blender scene for label renders (needs bpy; imported only inside Blender).

Builds once per process: imports the rigged glTF hand, rebuilds its bone hierarchy from the hand
model (reparenting in edit mode keeps every rest transform), gives every face the material of the
link of its dominant bone (pass_index = link id), and sets Cycles up for exact integer labels.
Per render only the pose bones and the camera change (persistent data keeps the BVH setup).
"""

from __future__ import annotations

import os
import struct
import warnings
from typing import Sequence

import bpy
import mathutils
import numpy as np

from . import exr, kinematics
from .errors import RenderError

CAMERA_DISTANCE = 1.0  # hand-frame units from the look-at point; the hand spans ~0.25


def _import_gltf(path: str):
    # The Blender 3.4 glTF importer still uses numpy.bool, removed in numpy 1.24.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        np.bool = bool  # type: ignore[attr-defined]
    before = set(bpy.data.objects)
    result = bpy.ops.import_scene.gltf(filepath=path)
    if "FINISHED" not in result:
        raise RenderError(f"{path}: glTF import failed")
    new = [o for o in bpy.data.objects if o not in before]
    arms = [o for o in new if o.type == "ARMATURE"]
    meshes = [o for o in new if o.type == "MESH"]
    if len(arms) != 1 or len(meshes) != 1:
        raise RenderError(f"{path}: expected one armature and one mesh, found {len(arms)} and {len(meshes)}")
    return arms[0], meshes[0]


def _check_rest(arm, model: dict, path: str, tol: float = 1e-4) -> None:
    for b in model["bones"]:
        bone = arm.data.bones.get(b["name"])
        if bone is None:
            raise RenderError(f"{path}: asset has no bone '{b['name']}' named by the hand model")
        head = np.array(bone.head_local)
        rot = np.array(bone.matrix_local.to_3x3())
        if np.abs(head - np.array(b["head"])).max() > tol or np.abs(rot - np.array(b["rest_matrix"])).max() > tol:
            raise RenderError(f"{path}: bone '{b['name']}' rest transform differs from the hand model")


def _rebuild_hierarchy(arm, model: dict) -> None:
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    ebones = arm.data.edit_bones
    for b in model["bones"]:
        eb = ebones[b["name"]]
        eb.use_connect = False
        eb.parent = ebones[b["parent"]] if b["parent"] is not None else None
    bpy.ops.object.mode_set(mode="OBJECT")


def _link_materials(mesh, model: dict) -> None:
    link_of_bone = {b["name"]: b["link"] for b in model["bones"]}
    group_link = {}
    for g in mesh.vertex_groups:
        if g.name in link_of_bone:
            group_link[g.index] = link_of_bone[g.name]
    me = mesh.data
    me.materials.clear()
    for link in range(1, 17):
        mat = bpy.data.materials.new(f"handdb_link_{link:02d}")
        mat.pass_index = link
        mat.use_nodes = False
        me.materials.append(mat)
    nverts = len(me.vertices)
    weights = np.zeros((nverts, 17))
    for v in me.vertices:
        for ge in v.groups:
            link = group_link.get(ge.group)
            if link is not None:
                weights[v.index, link] += ge.weight
    for poly in me.polygons:
        w = weights[list(poly.vertices)].sum(axis=0)
        link = int(np.argmax(w[1:])) + 1
        poly.material_index = link - 1


def _setup_render(scene, resolution: int) -> None:
    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device = "CPU"
    cy.samples = 1
    cy.preview_samples = 1
    cy.use_adaptive_sampling = False
    cy.use_denoising = False
    cy.pixel_filter_type = "BOX"
    cy.filter_width = 0.01
    cy.max_bounces = 0
    cy.diffuse_bounces = 0
    cy.glossy_bounces = 0
    cy.transmission_bounces = 0
    cy.volume_bounces = 0
    cy.transparent_max_bounces = 0
    cy.caustics_reflective = False
    cy.caustics_refractive = False
    cy.seed = 0
    scene.render.use_persistent_data = True
    scene.render.film_transparent = True
    scene.render.resolution_x = resolution
    scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    scene.render.use_file_extension = False
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    scene.render.dither_intensity = 0.0
    # No render date/time in the EXR header: the same plan gives the same bytes.
    for stamp in ("date", "time", "render_time", "frame", "filename", "memory", "hostname"):
        setattr(scene.render, "use_stamp_" + stamp, False)
    vl = scene.view_layers[0]
    vl.use_pass_combined = False
    vl.use_pass_z = True
    vl.use_pass_material_index = True


# The label renders are written by a compositor File Output node, not by saving the render result:
# Blender's render-result EXR always carries the RGBA Combined pass and writes Depth/IndexMA as
# float32 whatever color_depth says, and decoding those 6 channels was ~90% of the converter's
# time (docs/conversion.md). The node writes exactly two HALF channels: half floats hold the link
# ids 0..16 exactly and depth to ~1 mm near the camera distance (far below the 5 mm occlusion
# jump); the background depth 1e10 becomes +inf, which the converter accepts off the hand. The
# node names a float input's channel "<slot>.V"; render_to renames it in the header to the
# ".X"/".Z" names Blender's own passes carry (same length, so no offset moves).
_LABEL_SLOT, _DEPTH_SLOT = "ViewLayer.IndexMA", "ViewLayer.Depth"
_CHANNEL_RENAMES = ((_DEPTH_SLOT + ".V", _DEPTH_SLOT + ".Z"), (_LABEL_SLOT + ".V", _LABEL_SLOT + ".X"))


def _setup_label_output(scene):
    scene.use_nodes = True
    nt = scene.node_tree
    for node in list(nt.nodes):
        nt.nodes.remove(node)
    layers = nt.nodes.new("CompositorNodeRLayers")
    layers.scene = scene
    out = nt.nodes.new("CompositorNodeOutputFile")
    fmt = out.format
    fmt.file_format = "OPEN_EXR_MULTILAYER"
    fmt.color_depth = "16"
    fmt.exr_codec = "ZIP"
    out.layer_slots.clear()
    out.layer_slots.new(_LABEL_SLOT)
    out.layer_slots.new(_DEPTH_SLOT)
    nt.links.new(layers.outputs["IndexMA"], out.inputs[_LABEL_SLOT])
    nt.links.new(layers.outputs["Depth"], out.inputs[_DEPTH_SLOT])
    scene.render.use_compositing = True
    return out


def _rename_channels(path: str) -> None:
    with open(path, "r+b") as f:
        data = f.read(1 << 16)
        try:
            header, end = exr._read_header(data, path)
        except (exr.ExrError, ValueError, IndexError, struct.error) as e:
            raise RenderError(f"{path}: Blender wrote an unreadable EXR header ({e})") from e
        names = sorted(c[0] for c in header.get("channels", []))
        if names != sorted(old for old, _ in _CHANNEL_RENAMES) or any(c[1] != 1 for c in header["channels"]):
            raise RenderError(f"{path}: expected half channels {[o for o, _ in _CHANNEL_RENAMES]}, got {names}")
        head = data[:end]
        for old, new in _CHANNEL_RENAMES:
            needle = old.encode() + b"\0"
            if head.count(needle) != 1:
                raise RenderError(f"{path}: channel name '{old}' not found once in the header")
            head = head.replace(needle, new.encode() + b"\0")
        f.seek(0)
        f.write(head)


class HandScene:
    """The posed hand + orthographic camera; one per Blender process."""

    def __init__(self, model: dict, asset_path: str, resolution: int, ortho_scale: float):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        self.model = model
        self.scene = bpy.context.scene
        self.arm, self.mesh = _import_gltf(asset_path)
        _check_rest(self.arm, model, asset_path)
        _rebuild_hierarchy(self.arm, model)
        _check_rest(self.arm, model, asset_path)
        _link_materials(self.mesh, model)
        for pb in self.arm.pose.bones:
            pb.rotation_mode = "QUATERNION"
            pb.location = (0.0, 0.0, 0.0)
            pb.scale = (1.0, 1.0, 1.0)
        cam_data = bpy.data.cameras.new("handdb_camera")
        cam_data.type = "ORTHO"
        cam_data.ortho_scale = ortho_scale
        cam_data.clip_start = 0.01
        cam_data.clip_end = 2.0 * CAMERA_DISTANCE + 1.0
        cam_data.sensor_fit = "HORIZONTAL"
        self.camera = bpy.data.objects.new("handdb_camera", cam_data)
        self.scene.collection.objects.link(self.camera)
        self.scene.camera = self.camera
        _setup_render(self.scene, resolution)
        self._label_output = _setup_label_output(self.scene)
        self._labels = True

    def use_label_output(self, enabled: bool) -> None:
        """True (the default): render_to writes the label EXR; False: it saves the render result
        in the scene's image format (photo.py's studio renders)."""
        self._labels = enabled
        self.scene.render.use_compositing = enabled

    def set_pose(self, joints: Sequence[float]) -> None:
        rots = kinematics.local_rotations(self.model, joints)
        for pb in self.arm.pose.bones:
            r = rots.get(pb.name)
            m = mathutils.Matrix(r.tolist()) if r is not None else mathutils.Matrix.Identity(3)
            pb.rotation_quaternion = m.to_quaternion()
        bpy.context.view_layer.update()

    def set_camera(self, matrix_world: np.ndarray) -> None:
        self.camera.matrix_world = mathutils.Matrix(matrix_world.tolist())
        bpy.context.view_layer.update()

    def keypoints_hand(self) -> np.ndarray:
        """(21, 3) keypoints of the current pose, read from Blender's posed bones."""
        out = np.zeros((len(self.model["keypoints"]), 3))
        mw = self.arm.matrix_world
        for kp in self.model["keypoints"]:
            pb = self.arm.pose.bones[kp["bone"]]
            if kp["at"] == "head":
                p = mw @ pb.head
            else:
                m = mw @ pb.matrix
                p = m.translation + m.to_3x3().col[1] * float(kp["length"])
            out[kp["index"]] = tuple(p)
        return out

    def mesh_vertices_hand(self) -> np.ndarray:
        """Posed (evaluated) mesh vertices in the hand frame."""
        dg = bpy.context.evaluated_depsgraph_get()
        ev = self.mesh.evaluated_get(dg)
        me = ev.to_mesh()
        co = np.empty(len(me.vertices) * 3)
        me.vertices.foreach_get("co", co)
        ev.to_mesh_clear()
        co = co.reshape(-1, 3)
        mw = np.array(self.mesh.matrix_world)
        return co @ mw[:3, :3].T + mw[:3, 3]

    def render_to(self, path: str) -> None:
        if not self._labels:
            self.scene.render.filepath = path
            result = bpy.ops.render.render(write_still=True)
            if "FINISHED" not in result or not os.path.exists(path):
                raise RenderError(f"{path}: Blender did not write the render")
            return
        path = os.path.abspath(path)
        if "#" in path:
            raise RenderError(f"{path}: '#' in a render path (Blender reads it as a frame number)")
        # The node appends the frame number in place of '#': write PATH.<frame>, then rename.
        self._label_output.base_path = path + ".#"
        written = f"{path}.{self.scene.frame_current}"
        if os.path.exists(written):
            os.remove(written)
        result = bpy.ops.render.render(write_still=False)
        if "FINISHED" not in result or not os.path.exists(written):
            raise RenderError(f"{path}: Blender did not write the render")
        _rename_channels(written)
        os.replace(written, path)
