"""Cloth pile: a soft square cloth let go hanging corner-down drops onto the floor, buckles and
folds over onto itself into a pile — its folds lie on each other, never through (Self
Collision)."""
from __future__ import annotations

import math

import bpy
import numpy as np

from sample_scenes import _common

NAME = "cloth_pile"
SIDE = 1.0  # [m] the cloth's side
CUTS = 30  # vertices along a side: 32
DROP = 0.8  # [m] from the lowest corner to the floor

# Frames that show the point (landing on its corner and buckling; folding over; lying at rest
# with both ends folded over onto the rest); README_FRAME is the README's picture.
END = 96
SHOWCASE = (14, 22, END)
README_FRAME = END
# Settled at the end: no vertex faster than SETTLED [m/s], at most a quarter faster than MOVING
# (measured: 0.013 m/s and none since the last parting pass of a sub-step, about 0.04 m/s
# and 50 of 961 since self-collision's forces reach the solve, 0.10
# m/s and 111 before; when the floor let go of vertices the solve pulled on, though the layers
# above pressed them down, 0.24 m/s and 856: the whole pile sliding)
SETTLED, MOVING = 0.15, 0.03


def build(scene) -> None:
    _common.stage(scene, (1.3, -1.7, 1.5), (0.05, 0.0, 0.15), frame_end=END)
    _common.ground(scene, color=(0.3, 0.27, 0.24))
    cloth = _common.grid(scene, "Cloth", CUTS, CUTS, SIDE)
    # a diamond standing corner-down in the XZ plane, leaning a little
    cloth.rotation_mode = 'ZXY'
    cloth.rotation_euler = (math.radians(90.0), math.radians(2.0), math.radians(45.0))
    cloth.location = (0.0, 0.0, DROP + SIDE / math.sqrt(2.0))
    for poly in cloth.data.polygons:
        poly.use_smooth = True
    cloth.data.materials.append(_common.material("Cloth", (0.75, 0.2, 0.35)))
    p = cloth.physanim.spring_mesh
    p.enabled = True
    p.mass = 0.3  # a towel
    p.bend_stiffness = 1e-4  # soft: it folds in many places
    p.self_collision = True  # its folds lie on each other instead of passing through


def check(scene) -> list[str]:
    problems = []
    cloth = bpy.data.objects["Cloth"]
    cloth.data.calc_loop_triangles()
    tris = [t.vertices[:] for t in cloth.data.loop_triangles]
    crossed_frames, lowest, last = [], 0.0, None
    for frame in range(1, scene.physanim.frame_end + 1):
        scene.frame_set(frame)
        x = _common.evaluated_vertices(cloth)
        if not np.all(np.isfinite(x)):
            return [f"frame {frame}: non-finite vertices"]
        lowest = min(lowest, float(x[:, 2].min()))
        crossed = _common.crossings(x, tris)
        if crossed:
            crossed_frames.append(f"{frame} ({crossed})")
        previous, last = last, x
    if crossed_frames:
        problems.append("the cloth passes through itself at frames (crossing triangle pairs): "
                        + ", ".join(crossed_frames[:10]))
    if lowest < -0.005:
        problems.append(f"the cloth goes {-lowest:.3f} m into the ground")
    top = float(last[:, 2].max())
    if top > 0.3 * SIDE:
        problems.append(f"the cloth has not fallen: its top is {top:.2f} m up at the end")
    covered = _covered_area(last, np.array(tris))
    if covered > 0.75 * SIDE * SIDE:
        problems.append(f"the cloth lies almost flat: it covers {covered:.2f} m^2 of floor of "
                        f"its {SIDE * SIDE:.2f} m^2 (not folded over onto itself)")
    speed = np.linalg.norm(last - previous, axis=1) * scene.render.fps
    moving = int((speed > MOVING).sum())
    if speed.max() > SETTLED or moving > len(speed) // 4:
        problems.append(f"the pile has not settled: at the end a vertex moves at "
                        f"{speed.max():.2f} m/s, {moving} of {len(speed)} faster than "
                        f"{MOVING} m/s")
    return problems


def _covered_area(x: np.ndarray, tris: np.ndarray, cell: float = 0.01) -> float:
    """The floor area under the cloth [m^2]: cells of ``cell`` metres that points spread
    over each triangle fall in (a cloth folded over onto itself covers less than its own
    area)."""
    steps = 8
    u, v = np.meshgrid(np.arange(steps + 1), np.arange(steps + 1))
    keep = u + v <= steps
    u, v = u[keep] / steps, v[keep] / steps
    a, b, c = x[tris[:, 0], :2], x[tris[:, 1], :2], x[tris[:, 2], :2]
    points = (a[:, None] + u[None, :, None] * (b - a)[:, None]
              + v[None, :, None] * (c - a)[:, None]).reshape(-1, 2)
    cells = np.unique(np.floor(points / cell).astype(np.int64), axis=0)
    return len(cells) * cell * cell
