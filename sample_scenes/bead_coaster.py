"""Bead coaster: beads on a wire shaped like a roller coaster. The wire is a Curve object (one
poly spline: a slope, a vertical loop, a valley and a ramp climbing higher than the start)
with the Constraint role, type On Wire and the emitter as First; nothing else is set on it. A
small emitter on the slope lets a bead go every frame: each slides down, runs round the loop,
climbs the ramp short of its end, slides back through the loop, and so on — no friction, so
each keeps its energy. Everything else is the default (2 sub-steps, symplectic Euler).

Self-check: in every frame every bead is on the wire as Blender evaluates it (within 0.1 mm),
each bead keeps its energy per unit mass (1/2 v^2 + g z) within 5 % of g times the drop to the
valley (symplectic Euler's first-order bound at the default step: measured 3.8 %; 2.3 % at 4
sub-steps, 0.9 % at 8), beads run over the top of the loop and
up the far ramp, and none reaches the ramp's end.
"""
from __future__ import annotations


import bpy
import numpy as np

from sample_scenes import _common

NAME = "bead_coaster"
FRAMES = 120
G = 9.81
RADIUS = 0.7  # [m] the loop's
VALLEY = 0.3  # [m] the valley's height
START, RAMP = 3.0, 3.6  # [m] the heights of the wire's ends (the ramp higher: never reached)
EMIT = (-3.4, 0.0)  # [m] the emitter's x and y, on the slope
ENERGY = 0.05  # of g (height of the emitter above the valley)
OFF = 1e-4  # [m]

# beads on the slope (20), the first through the loop (40), many at once (90)
SHOWCASE = (20, 40, 90)
README_FRAME = 40


def track(count: int = 240) -> np.ndarray:
    """(P, 3) points of the wire: slope, valley, loop (shifted sideways by 0.3 m as it turns,
    so it does not cross itself), valley, ramp."""
    def ease(u):
        return 0.5 * (1.0 - np.cos(np.pi * u))

    n = count // 4
    u = np.linspace(0.0, 1.0, n, endpoint=False)
    slope = np.column_stack([-4.5 + 3.5 * u, np.zeros(n), START - (START - VALLEY) * ease(u)])
    phi = np.linspace(0.0, 2.0 * np.pi, 2 * n, endpoint=False)
    loop = np.column_stack([RADIUS * np.sin(phi), 0.3 * phi / (2.0 * np.pi),
                            VALLEY + RADIUS * (1.0 - np.cos(phi))])
    u = np.linspace(0.0, 1.0, n)
    ramp = np.column_stack([1.0 + 3.5 * u, np.full(n, 0.3), VALLEY + (RAMP - VALLEY) * ease(u)])
    return np.vstack([slope, [[-1.0, 0.0, VALLEY], [-0.5, 0.0, VALLEY]], loop,
                      [[0.5, 0.3, VALLEY]], ramp])


def build(scene) -> None:
    import bmesh

    _common.stage(scene, (0.0, -12.5, 2.6), (0.0, 0.0, 1.6), frame_end=FRAMES)
    _common.ground(scene)
    curve = bpy.data.curves.new("Coaster", 'CURVE')
    curve.dimensions = '3D'
    curve.bevel_depth = 0.015  # seen as a thin rail
    pts = track()
    spline = curve.splines.new('POLY')
    spline.points.add(len(pts) - 1)
    spline.points.foreach_set("co", np.hstack([pts, np.ones((len(pts), 1))]).ravel())
    wire = bpy.data.objects.new("Coaster", curve)
    scene.collection.objects.link(wire)
    curve.materials.append(_common.material("Rail", (0.6, 0.6, 0.65)))
    c = wire.physanim.constraint
    c.enabled, c.type = True, 'ON_CIRCLE'  # On Wire: on a Curve object, along its spline
    at = np.interp(EMIT[0], pts[:40, 0], pts[:40, 2])
    emitter = _common.add_mesh(scene, "Beads", lambda bm: bmesh.ops.create_cube(bm, size=0.1))
    emitter.location = (EMIT[0], EMIT[1], at)
    emitter.hide_render = True
    p = emitter.physanim.emitter
    p.enabled = True
    p.source = 'ORIGIN'
    p.rate, p.frame_start, p.frame_end = 1.0, 1, 60
    p.speed = 0.0
    p.lifetime = 10.0 * FRAMES
    p.size = 0.06
    p.color_stops[0].color = (0.9, 0.35, 0.1, 1.0)
    p.color_stops[1].color = (0.95, 0.75, 0.15, 1.0)
    c.object1 = emitter


def _wire(scene) -> np.ndarray:
    """The wire's world points, read from its poly spline (its evaluated line)."""
    ob = bpy.data.objects["Coaster"]
    co = np.empty(len(ob.data.splines[0].points) * 4)
    ob.data.splines[0].points.foreach_get("co", co)
    m = np.array(ob.matrix_world)
    return co.reshape(-1, 4)[:, :3] @ m[:3, :3].T + m[:3, 3]


def _off(x: np.ndarray, pts: np.ndarray) -> np.ndarray:
    a, d = pts[:-1], np.diff(pts, axis=0)
    u = np.clip(np.einsum("rsk,sk->rs", x[:, None] - a[None], d) / np.einsum("sk,sk->s", d, d),
                0.0, 1.0)
    return np.min(np.linalg.norm(x[:, None] - (a[None] + u[..., None] * d[None]), axis=2),
                  axis=1)


def check(scene) -> list[str]:
    problems = []
    pts = _wire(scene)
    energy0: dict[int, float] = {}
    worst_off = worst_energy = 0.0
    looped = climbed = False
    for frame in range(1, FRAMES + 1):
        p = _common.points(scene, "Beads", frame)
        x, v = p["position"].astype(float), p["velocity"].astype(float)
        if not len(x):
            continue
        worst_off = max(worst_off, float(_off(x, pts).max()))
        e = 0.5 * np.einsum("ij,ij->i", v, v) + G * x[:, 2]
        for i, value in zip(p["id"].tolist(), e.tolist()):
            worst_energy = max(worst_energy, abs(value - energy0.setdefault(i, value)))
        looped |= bool(np.any((x[:, 2] > VALLEY + 1.9 * RADIUS) & (np.abs(x[:, 0]) < 0.2)))
        climbed |= bool(np.any(x[:, 0] > 2.0))
        if np.any(x[:, 0] > 4.45):
            problems.append(f"a bead reached the ramp's end at frame {frame}")
    drop = G * (float(np.interp(EMIT[0], pts[:40, 0], pts[:40, 2])) - VALLEY)
    if worst_off > OFF:
        problems.append(f"a bead left the wire by {worst_off * 1000:.3f} mm")
    if worst_energy > ENERGY * drop:
        problems.append(f"a bead's energy changed by {100 * worst_energy / drop:.1f} % of g times "
                        f"its drop (at most {100 * ENERGY:.0f} %)")
    if len(energy0) < 50:
        problems.append(f"only {len(energy0)} beads were born")
    if not looped:
        problems.append("no bead ran over the top of the loop")
    if not climbed:
        problems.append("no bead climbed the far ramp")
    return problems
