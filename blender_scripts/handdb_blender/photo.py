"""Photo-like renders of the posed hand (needs bpy; imported only inside Blender).

Turns a HandScene (scene.py, set up for label renders) into a simple photo studio: every link
material becomes one skin-toned Principled BSDF, a key and a fill light follow the camera, a dim
grey world gives ambient light, and a background card parented to the camera fills the view
behind the hand: a plain colour, or (clutter) a seeded procedural texture of Voronoi cells, noise
and stripes. Cycles renders the colour image with a few samples to an 8-bit sRGB PNG.

A plan's items may each choose their background (`clutter`, default the plan's photo.clutter) and
shift the hand in the picture (`photo_offset_px`, x right and y down: the camera's lens shift, with
the background card moved along so it still fills the view); test sequences use both
(generator/testset/sequence.h). Label renders are made before the studio and are never shifted.

With `forearm` the studio adds a skin-coloured forearm (forearm.py) to the photos; with
`forearm_fraction` it adds it once and shows it on the items whose plan entry says `forearm`. The
label renders made before the studio exists never see it.
"""

from __future__ import annotations

import math
from typing import Dict, Sequence

import bpy
import numpy as np

from . import forearm, testset
from .scene import CAMERA_DISTANCE

BACKGROUND_DEPTH = 0.45  # hand-frame units behind the look-at point (the hand spans ~0.25)

def _emission_material(name: str):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    emit = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    return mat, nt, emit


class PhotoStudio:
    def __init__(self, hand_scene, photo: dict, ortho_scale: float, items=()):
        self.hs = hand_scene
        scene = hand_scene.scene
        self.clutter = bool(photo["clutter"])
        self.any_clutter = self.clutter or any(bool(it.get("clutter", False)) for it in items)
        self.ortho_scale = ortho_scale
        self.resolution = None
        skin = [testset.srgb_to_linear(c) for c in testset.check_rgb(photo["skin_rgb"], "photo.skin_rgb")]
        plain = [testset.srgb_to_linear(c)
                 for c in testset.check_rgb(photo["background_rgb"], "photo.background_rgb")]

        # Skin on every link slot.
        mat = bpy.data.materials.new("handdb_skin")
        mat.use_nodes = True
        bsdf = mat.node_tree.nodes.get("Principled BSDF")
        bsdf.inputs["Base Color"].default_value = (*skin, 1.0)
        bsdf.inputs["Roughness"].default_value = 0.55
        bsdf.inputs["Specular"].default_value = 0.25
        me = hand_scene.mesh.data
        for i in range(len(me.materials)):
            me.materials[i] = mat
        self.forearm_default = bool(photo.get("forearm", False))
        self.forearm_obj = None
        if testset.uses_forearm(photo):
            self.forearm_obj = self._add_forearm(mat)

        # Ambient world.
        world = bpy.data.worlds.new("handdb_world")
        world.use_nodes = True
        self.world_bg = world.node_tree.nodes.get("Background")
        self.world_bg.inputs["Color"].default_value = (0.5, 0.5, 0.5, 1.0)
        scene.world = world

        # Lights parented to the camera (a sun's light travels along its local -Z, like the view).
        self.key = self._sun("handdb_key")
        self.fill = self._sun("handdb_fill")

        # Background card: a plane facing the camera, behind the hand, a bit larger than the view.
        mesh = bpy.data.meshes.new("handdb_background")
        mesh.from_pydata([(-0.5, -0.5, 0.0), (0.5, -0.5, 0.0), (0.5, 0.5, 0.0), (-0.5, 0.5, 0.0)], [],
                         [(0, 1, 2, 3)])
        mesh.update()
        card = bpy.data.objects.new("handdb_background", mesh)
        scene.collection.objects.link(card)
        card.parent = hand_scene.camera
        card.matrix_parent_inverse.identity()
        card.location = (0.0, 0.0, -(CAMERA_DISTANCE + BACKGROUND_DEPTH))
        card.rotation_euler = (0.0, 0.0, 0.0)
        card.scale = (ortho_scale * 1.5, ortho_scale * 1.5, 1.0)
        self.card = card
        self.card_depth = -(CAMERA_DISTANCE + BACKGROUND_DEPTH)
        card.visible_shadow = False
        card.visible_diffuse = False
        card.visible_glossy = False
        card.visible_transmission = False
        bmat, nt, emit = _emission_material("handdb_background")
        self.emit = emit
        self.plain = plain
        self.background_tree = nt
        self.clutter_link = None
        emit.inputs["Color"].default_value = (*plain, 1.0)
        if self.any_clutter:
            self._build_clutter(nt, emit)
        card.data.materials.append(bmat)

        self._setup_render(scene, int(photo["samples"]))

    def _add_forearm(self, material) -> None:
        hs = self.hs
        model = hs.model
        arm = hs.arm
        # Rest mesh vertices in the hand frame (the armature's object space).
        me = hs.mesh.data
        co = np.empty(len(me.vertices) * 3)
        me.vertices.foreach_get("co", co)
        co = co.reshape(-1, 3)
        to_hand = np.array(arm.matrix_world.inverted() @ hs.mesh.matrix_world)
        co = co @ to_hand[:3, :3].T + to_hand[:3, 3]
        wrist = np.array(arm.data.bones["wrist"].head_local)
        centre, a, b = forearm.wrist_section(co, wrist, model["forward_axis"], model["palm_normal"])
        verts, faces = forearm.forearm_vertices(centre, a, b, model["forward_axis"], model["palm_normal"])
        mesh = bpy.data.meshes.new("handdb_forearm")
        mesh.from_pydata(verts, [], faces)
        for poly in mesh.polygons:
            poly.use_smooth = True
        mesh.update()
        obj = bpy.data.objects.new("handdb_forearm", mesh)
        hs.scene.collection.objects.link(obj)
        obj.parent = arm
        obj.matrix_parent_inverse.identity()
        mesh.materials.append(material)
        return obj

    def _sun(self, name: str):
        data = bpy.data.lights.new(name, type="SUN")
        data.angle = math.radians(8.0)
        obj = bpy.data.objects.new(name, data)
        self.hs.scene.collection.objects.link(obj)
        obj.parent = self.hs.camera
        obj.matrix_parent_inverse.identity()
        obj.location = (0.0, 0.0, 0.0)
        return obj

    def _build_clutter(self, nt, emit) -> None:
        n = nt.nodes
        coord = n.new("ShaderNodeTexCoord")
        self.mapping = n.new("ShaderNodeMapping")
        nt.links.new(coord.outputs["Generated"], self.mapping.inputs["Vector"])
        self.voronoi = n.new("ShaderNodeTexVoronoi")
        self.noise = n.new("ShaderNodeTexNoise")
        self.wave = n.new("ShaderNodeTexWave")
        for tex in (self.voronoi, self.noise, self.wave):
            nt.links.new(self.mapping.outputs["Vector"], tex.inputs["Vector"])
        self.ramp_cells = n.new("ShaderNodeValToRGB")
        self.ramp_noise = n.new("ShaderNodeValToRGB")
        nt.links.new(self.voronoi.outputs["Distance"], self.ramp_cells.inputs["Fac"])
        nt.links.new(self.noise.outputs["Fac"], self.ramp_noise.inputs["Fac"])
        self.mix_noise = n.new("ShaderNodeMixRGB")
        self.mix_noise.blend_type = "MIX"
        nt.links.new(self.ramp_cells.outputs["Color"], self.mix_noise.inputs["Color1"])
        nt.links.new(self.ramp_noise.outputs["Color"], self.mix_noise.inputs["Color2"])
        self.mix_wave = n.new("ShaderNodeMixRGB")
        self.mix_wave.blend_type = "MULTIPLY"
        nt.links.new(self.mix_noise.outputs["Color"], self.mix_wave.inputs["Color1"])
        nt.links.new(self.wave.outputs["Color"], self.mix_wave.inputs["Color2"])
        self.clutter_link = nt.links.new(self.mix_wave.outputs["Color"], emit.inputs["Color"])

    def _setup_render(self, scene, samples: int) -> None:
        cy = scene.cycles
        cy.samples = samples
        cy.preview_samples = samples
        cy.use_denoising = False
        cy.pixel_filter_type = "BLACKMAN_HARRIS"
        cy.filter_width = 1.5
        cy.max_bounces = 2
        cy.diffuse_bounces = 2
        cy.glossy_bounces = 1
        cy.transparent_max_bounces = 2
        scene.render.film_transparent = False
        scene.view_settings.view_transform = "Standard"
        scene.view_settings.look = "None"
        scene.view_settings.exposure = 0.0
        scene.view_settings.gamma = 1.0
        self.hs.use_label_output(False)  # save the render result (PNG), not the label EXR
        vl = scene.view_layers[0]
        vl.use_pass_combined = True
        vl.use_pass_z = False
        vl.use_pass_material_index = False
        settings = scene.render.image_settings
        settings.file_format = "PNG"
        settings.color_mode = "RGB"
        settings.color_depth = "8"
        settings.compression = 15

    def set_item(self, item: dict) -> None:
        lights: Dict[str, float] = testset.light_params(int(item["seed"]))
        self.key.rotation_euler = (math.radians(lights["key_pitch_deg"]),
                                   math.radians(lights["key_yaw_deg"]), 0.0)
        self.key.data.energy = lights["key_strength"]
        self.fill.rotation_euler = (math.radians(-15.0), math.radians(-lights["key_yaw_deg"] * 1.5), 0.0)
        self.fill.data.energy = lights["fill_strength"]
        self.world_bg.inputs["Strength"].default_value = lights["ambient"]
        clutter = testset.item_clutter(item, self.clutter)
        self._use_clutter(clutter)
        if clutter:
            self._set_clutter(testset.clutter_params(int(item["seed"])))
        self._set_offset(testset.item_offset_px(item))
        if self.forearm_obj is not None:
            self.forearm_obj.hide_render = not testset.item_forearm(item, self.forearm_default)

    def _use_clutter(self, on: bool) -> None:
        """Links the clutter texture to the background, or unlinks it for the plain colour."""
        if self.clutter_link is None:
            return
        nt = self.background_tree
        if on and not self._clutter_linked():
            self.clutter_link = nt.links.new(self.mix_wave.outputs["Color"], self.emit.inputs["Color"])
        elif not on and self._clutter_linked():
            nt.links.remove(self.clutter_link)

    def _clutter_linked(self) -> bool:
        return any(l.from_node == self.mix_wave and l.to_node == self.emit
                   for l in self.background_tree.links)

    def _set_offset(self, offset_px) -> None:
        """Shifts the view so the hand appears offset_px away (x right, y down); the background
        card follows the view."""
        res = self.hs.scene.render.resolution_x
        shift_x = -float(offset_px[0]) / res
        shift_y = float(offset_px[1]) / res
        cam = self.hs.camera.data
        cam.shift_x = shift_x
        cam.shift_y = shift_y
        self.card.location = (shift_x * self.ortho_scale, shift_y * self.ortho_scale, self.card_depth)

    def _set_clutter(self, p: dict) -> None:
        self.mapping.inputs["Location"].default_value = p["offset"]
        self.mapping.inputs["Rotation"].default_value = (0.0, 0.0, p["rotation"])
        self.voronoi.inputs["Scale"].default_value = p["cell_scale"]
        self.noise.inputs["Scale"].default_value = p["noise_scale"]
        self.noise.inputs["Detail"].default_value = p["noise_detail"]
        self.wave.inputs["Scale"].default_value = p["wave_scale"]
        c = p["colours"]
        b = p["brightness"]

        def set_ramp(ramp, c0: Sequence[float], c1: Sequence[float]) -> None:
            els = ramp.color_ramp.elements
            els[0].color = (c0[0] * b, c0[1] * b, c0[2] * b, 1.0)
            els[1].color = (c1[0] * b, c1[1] * b, c1[2] * b, 1.0)

        set_ramp(self.ramp_cells, c[0], c[1])
        set_ramp(self.ramp_noise, c[2], c[3])
        self.mix_noise.inputs["Fac"].default_value = p["mix_noise"]
        self.mix_wave.inputs["Fac"].default_value = p["mix_wave"]
