"""Forward kinematics of a hand model JSON (configs/hands/*.json), without bpy.

The model lists every bone with its rest head and rest rotation in the hand frame (armature
space) and its parent. A pose is the 20-vector of joint angles (radians, DOF order of
docs/conventions.md). Each DOF rotates its bone about an axis given in the bone's rest frame;
a bone with two DOFs (MCP / thumb CMC) applies abduction then flexion: R = R(abd) @ R(flex), so
flexion turns about the abducted bone's own axis. This is exactly what Blender computes for a
pose bone whose rotation is R (pose = parent_pose @ parent_rest^-1 @ rest @ R).
"""

from __future__ import annotations

import math
from typing import Dict, List, Sequence

import numpy as np

NUM_DOFS = 20
NUM_KEYPOINTS = 21


def axis_angle_matrix(axis: Sequence[float], angle: float) -> np.ndarray:
    """3x3 rotation by `angle` (radians, right-handed) about unit `axis`."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    x, y, z = a
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    return np.array([
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ])


def rest_matrix(bone: dict) -> np.ndarray:
    """4x4 rest transform of a bone (bone frame -> hand frame)."""
    m = np.eye(4)
    m[:3, :3] = np.asarray(bone["rest_matrix"], dtype=np.float64)
    m[:3, 3] = np.asarray(bone["head"], dtype=np.float64)
    return m


def bone_order(model: dict) -> List[str]:
    """Bone names with every parent before its children."""
    parents = {b["name"]: b["parent"] for b in model["bones"]}
    order: List[str] = []
    placed = set()

    def place(name: str, depth: int = 0) -> None:
        if name in placed:
            return
        if depth > len(parents):
            raise ValueError(f"bone hierarchy has a cycle at '{name}'")
        parent = parents[name]
        if parent is not None:
            if parent not in parents:
                raise ValueError(f"bone '{name}' has unknown parent '{parent}'")
            place(parent, depth + 1)
        order.append(name)
        placed.add(name)

    for b in model["bones"]:
        place(b["name"])
    return order


def local_rotations(model: dict, joints: Sequence[float]) -> Dict[str, np.ndarray]:
    """Per-bone 3x3 pose rotation (in the bone's rest frame) for a joint vector."""
    if len(joints) != NUM_DOFS:
        raise ValueError(f"joint vector has {len(joints)} values, expected {NUM_DOFS}")
    flex: Dict[str, np.ndarray] = {}
    abd: Dict[str, np.ndarray] = {}
    for dof in model["dofs"]:
        r = axis_angle_matrix(dof["axis"], float(joints[dof["index"]]))
        target = abd if dof["kind"] == "abduction" else flex
        bone = dof["bone"]
        target[bone] = target[bone] @ r if bone in target else r
    out = {}
    for bone in set(flex) | set(abd):
        out[bone] = abd.get(bone, np.eye(3)) @ flex.get(bone, np.eye(3))
    return out


def pose_bones(model: dict, joints: Sequence[float]) -> Dict[str, np.ndarray]:
    """4x4 posed transform (bone frame -> hand frame) of every bone."""
    rots = local_rotations(model, joints)
    bones = {b["name"]: b for b in model["bones"]}
    posed: Dict[str, np.ndarray] = {}
    for name in bone_order(model):
        b = bones[name]
        rest = rest_matrix(b)
        basis = np.eye(4)
        if name in rots:
            basis[:3, :3] = rots[name]
        if b["parent"] is None:
            posed[name] = rest @ basis
        else:
            parent_rest = rest_matrix(bones[b["parent"]])
            posed[name] = posed[b["parent"]] @ np.linalg.inv(parent_rest) @ rest @ basis
    return posed


def keypoints(model: dict, joints: Sequence[float]) -> np.ndarray:
    """(21, 3) keypoints in the hand frame for a joint vector."""
    posed = pose_bones(model, joints)
    out = np.zeros((len(model["keypoints"]), 3))
    for kp in model["keypoints"]:
        m = posed[kp["bone"]]
        if kp["at"] == "head":
            out[kp["index"]] = m[:3, 3]
        else:  # "tail": a point `length` along the bone's y axis
            out[kp["index"]] = m[:3, 3] + m[:3, 1] * float(kp["length"])
    return out


def within_limits(model: dict, joints: Sequence[float], tol: float = 1e-9) -> List[str]:
    """Names of the DOFs whose value lies outside [min, max]."""
    bad = []
    for dof in model["dofs"]:
        v = float(joints[dof["index"]])
        if v < dof["min"] - tol or v > dof["max"] + tol:
            bad.append(dof["name"])
    return bad
