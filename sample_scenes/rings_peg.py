"""Rings over pegs: eight rings drop onto two pegs and a ring toss's worth of them slide down
and stack around them. Each ring is a closed torus with nothing set but its Rigid Body box:
Automatic makes a closed concave mesh a Mesh body, so the peg passes through its hole (as its
convex hull, a disc, it would lie on top). The pegs are cylinders ticked as colliders (Automatic:
Mesh colliders). Self-check: every ring ends around a peg (the peg's axis through its hole), at
rest; no ring's vertex lies inside another ring, a peg or the ground.
"""
from __future__ import annotations

import math

import bpy
import numpy as np

from sample_scenes import _common

NAME = "rings_peg"
MAJOR, MINOR = 0.42, 0.08  # [m] ring radius and tube radius
SEGMENTS, SIDES = 36, 12  # the torus mesh: around the ring, around the tube
PEG_RADIUS, PEG_HEIGHT = 0.12, 1.4  # [m]
PEGS = ((-0.75, 0.0), (0.75, 0.0))  # (x, y) of each peg on the ground
DEPTH_TOLERANCE = 8e-3  # [m] a facetted surface lies inside the true torus by up to ~3 mm
COLORS = ((0.85, 0.2, 0.15), (0.95, 0.6, 0.1), (0.2, 0.55, 0.85), (0.3, 0.7, 0.3))

# rings in the air over the pegs (8), the first ones sliding down while the last fall (14), all
# stacked (60)
SHOWCASE = (8, 14, 60)
README_FRAME = 14


def _torus(bm) -> None:
    """A closed torus about local Z, quads wound outward."""
    u = np.linspace(0.0, 2.0 * np.pi, SEGMENTS, endpoint=False)
    v = np.linspace(0.0, 2.0 * np.pi, SIDES, endpoint=False)
    verts = [[bm.verts.new(((MAJOR + MINOR * math.cos(b)) * math.cos(a),
                            (MAJOR + MINOR * math.cos(b)) * math.sin(a), MINOR * math.sin(b)))
              for b in v] for a in u]
    for i in range(SEGMENTS):
        for j in range(SIDES):
            i1, j1 = (i + 1) % SEGMENTS, (j + 1) % SIDES
            bm.faces.new((verts[i][j], verts[i1][j], verts[i1][j1], verts[i][j1]))


def _peg(scene, k: int, x: float, y: float, material):
    import bmesh

    ob = _common.add_mesh(scene, f"Peg{k}", lambda bm: bmesh.ops.create_cone(
        bm, cap_ends=True, segments=24, radius1=PEG_RADIUS, radius2=PEG_RADIUS,
        depth=PEG_HEIGHT))
    ob.location = (x, y, PEG_HEIGHT / 2)
    ob.data.materials.append(material)
    ob.physanim.collider.enabled = True
    return ob


def _drops() -> list[tuple[int, tuple, tuple]]:
    """(peg, location, rotation) of each ring: over a peg, a little off its axis and tilted,
    one above the other so that they land in turn."""
    rng = np.random.default_rng(3)
    out = []
    for k in range(8):
        peg = k % 2
        x, y = PEGS[peg]
        off = rng.uniform(-0.12, 0.12, 2)
        tilt = rng.uniform(-0.35, 0.35, 2)
        out.append((peg, (x + off[0], y + off[1], PEG_HEIGHT + 0.4 + 0.45 * (k // 2)),
                    (tilt[0], tilt[1], rng.uniform(0.0, math.pi))))
    return out


def build(scene) -> None:
    _common.stage(scene, (0.0, -6.6, 3.1), (0.0, 0.0, 0.95), frame_end=120)
    _common.ground(scene)
    wood = _common.material("PegWood", (0.55, 0.38, 0.22))
    for k, (x, y) in enumerate(PEGS):
        _peg(scene, k, x, y, wood)
    colors = [_common.material(f"Ring{k}", c) for k, c in enumerate(COLORS)]
    for k, (_, location, rotation) in enumerate(_drops()):
        ob = _common.add_mesh(scene, f"Ring{k}", _torus)
        ob.location, ob.rotation_euler = location, rotation
        ob.data.materials.append(colors[k % len(colors)])
        ob.physanim.rigid_body.enabled = True


def _inside_torus(points: np.ndarray, m: np.ndarray) -> np.ndarray:
    """How deep [m] (> 0 inside) each world point lies inside the true torus posed by ``m``."""
    local = (points - m[:3, 3]) @ m[:3, :3]
    ring = np.hypot(local[:, 0], local[:, 1]) - MAJOR
    return MINOR - np.hypot(ring, local[:, 2])


def check(scene) -> list[str]:
    problems = []
    end = scene.physanim.frame_end
    rings = [bpy.data.objects[f"Ring{k}"] for k in range(len(_drops()))]
    scene.frame_set(end - 1)
    before = [np.array(o.matrix_world) for o in rings]
    scene.frame_set(end)
    poses = [np.array(o.matrix_world) for o in rings]
    verts = [_common.evaluated_vertices(o) for o in rings]
    for k, (ob, m) in enumerate(zip(rings, poses)):
        around = []
        for x, y in PEGS:  # the peg's axis at the ring's height, in the ring's frame
            local = (np.array([x, y, m[2, 3]]) - m[:3, 3]) @ m[:3, :3]
            around.append(np.hypot(local[0], local[1]) < MAJOR - MINOR)
        if not any(around):
            problems.append(f'"{ob.name}" is not around a peg (it ended at '
                            f'{np.round(m[:3, 3], 2).tolist()})')
        speed = np.linalg.norm(m[:3, 3] - before[k][:3, 3]) * scene.render.fps
        if speed > 0.01:
            problems.append(f'"{ob.name}" still moves at {speed:.3f} m/s at frame {end}')
        if verts[k][:, 2].min() < -DEPTH_TOLERANCE:
            problems.append(f'"{ob.name}" sank {-verts[k][:, 2].min() * 1000:.0f} mm into the '
                            "ground")
        for x, y in PEGS:
            low = verts[k][:, 2] < PEG_HEIGHT
            radial = np.hypot(verts[k][low, 0] - x, verts[k][low, 1] - y)
            if len(radial) and radial.min() < PEG_RADIUS - DEPTH_TOLERANCE:
                problems.append(f'"{ob.name}" went {(PEG_RADIUS - radial.min()) * 1000:.0f} mm '
                                "into a peg")
        for j, other in enumerate(poses):
            depth = _inside_torus(verts[k], other).max() if j != k else 0.0
            if depth > DEPTH_TOLERANCE:
                problems.append(f'"{ob.name}" went {depth * 1000:.0f} mm into "{rings[j].name}"')
    return problems
