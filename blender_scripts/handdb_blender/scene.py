"""Blender scene for label renders (needs bpy; imported only inside Blender).

Builds once per process: imports the rigged glTF hand, rebuilds its bone hierarchy from the hand
model (reparenting in edit mode keeps every rest transform), gives every face the material of the
link of its dominant bone (pass_index = link id), and sets Cycles up for exact integer labels.
Per render only the pose bones and the camera change (persistent data keeps the BVH setup).
"""

from __future__ import annotations

import os
import warnings
from typing import Sequence

import bpy
import mathutils
import numpy as np

from . import kinematics
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
    vl = scene.view_layers[0]
    vl.use_pass_combined = True
    vl.use_pass_z = True
    vl.use_pass_material_index = True
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.color_depth = "32"
    settings.exr_codec = "ZIP"


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
        self.scene.render.filepath = path
        result = bpy.ops.render.render(write_still=True)
        if "FINISHED" not in result or not os.path.exists(path):
            raise RenderError(f"{path}: Blender did not write the render")
