"""Imports a .glb with Blender's own glTF importer and prints, as one JSON line after
"IMPORTED ", every pose bone's head (armature space: the hand frame) and each camera's world
matrix and orthographic scale: what a user opening handdb's posed hand in Blender gets.

blender -b --factory-startup -P tests/blender/import_posed_glb.py -- FILE.glb
"""
import json
import sys

import bpy
import numpy

# Blender 3.4.1's glTF importer still uses numpy.bool, which numpy 1.24 removed.
if not hasattr(numpy, "bool"):
    numpy.bool = bool


def main():
    path = sys.argv[sys.argv.index("--") + 1]
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    bpy.ops.import_scene.gltf(filepath=path)
    out = {"bones": {}, "cameras": []}
    for obj in bpy.context.scene.objects:
        if obj.type == "ARMATURE":
            out["armature_world"] = [list(row) for row in obj.matrix_world]
            for bone in obj.pose.bones:
                out["bones"][bone.name] = list(bone.head)
        elif obj.type == "CAMERA":
            out["cameras"].append({"world": [list(row) for row in obj.matrix_world],
                                   "type": obj.data.type,
                                   "ortho_scale": obj.data.ortho_scale})
    print("IMPORTED " + json.dumps(out))


if __name__ == "__main__":
    try:
        main()
    except Exception as error:  # one line and a failing exit code, not Blender's prompt
        print(f"import_posed_glb: {error}", file=sys.stderr)
        sys.exit(1)
