"""Rope swing: a 5 kg crate hangs from a beam on a rope of particles, pulled back 50 degrees;
let go, it swings down into a stack of boxes and knocks it over. The rope is an emitter that
runs from the beam to the crate in the frame before the first (Even Timing: its 30 particles
of 0.2 kg 10 cm apart, each joined to the one before by a rigid link); two constraints of type
Tie hold it — its first particle on the world at the beam, its last on the crate (the crate as
Second: the crate swings on the rope and pulls it taut, two-way). Everything else is the
default (2 sub-steps). A rope of 60 links of 0.1 kg on a 10 kg crate passed this
self-check at 2 sub-steps too, measured on an earlier machine (where such a rope's limit lies
depends on rounding: see the README's limitations; a 100 kg end needs more sub-steps).

Self-check: in every frame no link of the rope is longer or shorter than at birth by more than
1 mm, the particle tied at the beam stays where it was tied and the one tied to the crate
stays on the crate (within 1 mm of its place on it), the crate swings through the bottom, and it knocks at
least two boxes off their places.
"""
from __future__ import annotations

import math

import bpy
import numpy as np
from mathutils import Matrix, Vector

from sample_scenes import _common

NAME = "rope_swing"
FRAMES = 72
BEAM = np.array([0.0, 0.0, 4.2])  # [m] where the rope is tied
LENGTH = 3.0  # [m] the rope's
COUNT = 30  # the rope's particles
LINK_MASS = 0.2  # [kg] each
CRATE = 0.4  # [m] the crate's side
CRATE_MASS = 5.0  # [kg]
PULL = math.radians(50.0)  # how far the rope is pulled back from hanging straight down
BOX = 0.4  # [m] the stacked boxes' side
STACK = (2, 3)  # boxes across, rows
STACK_X = 0.55  # [m] the stack's near side
HOLD = 1e-3  # [m]
KNOCKED = 0.2  # [m] a box counts as knocked off once moved this far

# pulled back (1), striking the stack (25), swinging on over the fallen stack (40)
SHOWCASE = (1, 25, 40)
README_FRAME = 25


def _direction() -> np.ndarray:
    """Down the rope from the beam, pulled back (towards -x) by PULL."""
    return np.array([-math.sin(PULL), 0.0, -math.cos(PULL)])


def _ends() -> tuple[np.ndarray, np.ndarray]:
    """The rope's first and last particles (births at the middle of their 1/60 of the run)."""
    d = _direction()
    step = LENGTH / COUNT
    return BEAM + d * 0.5 * step, BEAM + d * (LENGTH - 0.5 * step)


def _boxes() -> list[str]:
    return [f"Box{r}{c}" for r in range(STACK[1]) for c in range(STACK[0])]


def _tie(scene, name: str, at, rope, second=None) -> None:
    empty = bpy.data.objects.new(name, None)
    empty.empty_display_size = 0.1
    empty.location = Vector(at)
    scene.collection.objects.link(empty)
    c = empty.physanim.constraint
    c.enabled, c.type, c.object1 = True, 'TIE', rope
    c.reach = 0.04  # one particle: they are 10 cm apart
    if second is not None:
        c.object2 = second


def build(scene) -> None:
    import bmesh

    _common.stage(scene, (1.0, -12.5, 2.8), (-0.4, 0.0, 2.15), frame_end=FRAMES)
    _common.ground(scene)
    d = _direction()
    beam = _common.add_mesh(scene, "Beam", lambda bm: bmesh.ops.create_cube(
        bm, size=1.0, matrix=Matrix.Diagonal((0.2, 2.0, 0.2, 1.0))))
    beam.location = Vector(BEAM + np.array([0.0, 0.0, 0.12]))
    beam.data.materials.append(_common.material("Wood", (0.45, 0.3, 0.18)))

    rope = _common.add_mesh(scene, "Rope", lambda bm: bmesh.ops.create_cube(bm, size=0.05))
    rope.hide_render = True
    p = rope.physanim.emitter
    p.enabled, p.source = True, 'ORIGIN'
    p.rate, p.even_timing, p.frame_start, p.frame_end = COUNT, True, 1, 1
    p.speed, p.spread, p.lifetime, p.size, p.mass = 0.0, 0.0, 100.0 * FRAMES, 0.05, LINK_MASS
    p.link, p.link_hard = True, True
    p.color_stops[0].color = (0.8, 0.7, 0.45, 1.0)
    p.color_stops[1].color = (0.8, 0.7, 0.45, 1.0)
    rope.location = Vector(BEAM)  # it runs down the rope in the frame before the first
    rope.keyframe_insert("location", frame=0)
    rope.location = Vector(BEAM + d * LENGTH)
    rope.keyframe_insert("location", frame=1)

    first, last = _ends()
    crate = _common.add_mesh(scene, "Crate", lambda bm: bmesh.ops.create_cube(bm, size=CRATE))
    crate.matrix_world = Matrix.Translation(Vector(last + d * (CRATE / 2 + 0.01))) @ \
        Matrix.Rotation(-PULL, 4, 'Y')
    crate.data.materials.append(_common.material("Crate", (0.6, 0.42, 0.22)))
    r = crate.physanim.rigid_body
    r.enabled, r.mass = True, CRATE_MASS
    _tie(scene, "BeamTie", first, rope)
    _tie(scene, "CrateTie", last, rope, crate)

    paint = [_common.material(f"Box{k}", (0.25 + 0.15 * k, 0.45, 0.7 - 0.15 * k))
             for k in range(2)]
    for row in range(STACK[1]):
        for col in range(STACK[0]):
            ob = _common.add_mesh(scene, f"Box{row}{col}", lambda bm: bmesh.ops.create_cube(
                bm, size=BOX))
            ob.location = (STACK_X + BOX / 2 + col * BOX * 1.01, 0.0, BOX / 2 + row * BOX)
            ob.data.materials.append(paint[(row + col) % 2])
            ob.physanim.rigid_body.enabled = True


def check(scene) -> list[str]:
    problems = []
    m = _common.track(scene, ["Crate"] + _boxes(), range(1, FRAMES + 1))
    crate, boxes = m[:, 0], m[:, 1:]
    lengths0, worst, beam_off, crate_off, tied = None, 0.0, 0.0, [], None
    for frame in range(1, FRAMES + 1):
        p = _common.points(scene, "Rope", frame)
        x = p["position"][np.argsort(p["id"])].astype(float)
        if len(x) != COUNT:
            problems.append(f"{len(x)} rope particles at frame {frame} (not {COUNT})")
            return problems
        lengths = np.linalg.norm(np.diff(x, axis=0), axis=1)
        lengths0 = lengths if lengths0 is None else lengths0
        worst = max(worst, float(np.abs(lengths - lengths0).max()))
        tied = x[0] if frame == 1 else tied  # where it was tied (it fell a little first)
        beam_off = max(beam_off, float(np.linalg.norm(x[0] - tied)))
        inv = np.linalg.inv(crate[frame - 1])
        crate_off.append(inv[:3, :3] @ x[-1] + inv[:3, 3])  # the tied particle on the crate
    if worst > HOLD:
        problems.append(f"a rope link changed its length by {worst * 1000:.2f} mm")
    if beam_off > HOLD:
        problems.append(f"the rope's end left the beam by {beam_off * 1000:.2f} mm")
    crate_off = np.array(crate_off)
    drift = float(np.linalg.norm(crate_off - crate_off[0], axis=1).max())
    if drift > HOLD:
        problems.append(f"the rope's end moved {drift * 1000:.2f} mm on the crate")
    if crate[:, 0, 3].max() < 0.0:
        problems.append("the crate never swung through the bottom")
    moved = np.linalg.norm(boxes[-1, :, :3, 3] - boxes[0, :, :3, 3], axis=1)
    if (moved > KNOCKED).sum() < 2:
        problems.append(f"only {int((moved > KNOCKED).sum())} boxes knocked off")
    return problems
