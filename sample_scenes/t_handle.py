"""The Dzhanibekov effect in zero gravity: three identical T-handles float side by side, each spun
about one of its principal axes with the same small wobble. The one spun about its intermediate
axis (the stem) turns over again and again; the ones spun about the largest axis (normal to the
T) and the smallest (along the crossbar) keep spinning steadily. Self-check: the intermediate
one's stem reverses direction at least twice, the other two spin axes stay within 20 degrees of
where they started, and every body's centre stays put.

The T is one closed mesh (no internal faces): its outline in the XZ plane, made of four quads,
given thickness along Y. Every rigid-body setting is the default but the spin (and no angular
damping: nothing slows a spin in space): the mass properties come from the mesh (a T is
concave; its convex hull would put the centre of mass half a stem width too low).
"""
from __future__ import annotations

import math

import bpy
import numpy as np

from sample_scenes import _common

NAME = "t_handle"
THICK = 0.16  # [m] the square cross-section of the crossbar and the stem
CROSSBAR = 9 * THICK  # [m] the crossbar's length (along local X)
STEM = 3 * THICK  # [m] the stem's length below the crossbar (along local -Z)
MASS = 1.0  # [kg] the rigid body's default
SPIN = 5.0  # [rad/s] about the chosen axis
WOBBLE = 0.05  # [rad/s] about each of the other two axes: the small perturbation
SPACING = 2.0  # [m] between the handles' centres
# local axis of each handle's spin: largest moment (normal to the T), intermediate (the stem),
# smallest (the crossbar)
SPUN = {"Largest": 1, "Intermediate": 2, "Smallest": 0}
FLIP_DOT = 0.5  # the stem counts as reversed when its direction's cosine to the start crosses
STEADY_DEG = 20.0  # [deg] how far a stable spin axis may wander

# all three upright (20), the middle one turning over (39), upside down (80), turning back (131)
SHOWCASE = (20, 39, 80, 131)
README_FRAME = 39


def _boxes() -> list[tuple[np.ndarray, np.ndarray]]:
    """(size, centre) of the crossbar and the stem, in the T's local axes [m]."""
    t = THICK
    return [(np.array([CROSSBAR, t, t]), np.array([0.0, 0.0, t / 2])),
            (np.array([t, t, STEM]), np.array([0.0, 0.0, -STEM / 2]))]


def mass_properties(mass: float) -> tuple[np.ndarray, np.ndarray]:
    """The T's centre of mass (3,) [m] (from the junction of crossbar and stem) and principal
    moments (3,) [kg m^2] about it along the local axes, for ``mass`` [kg] spread uniformly."""
    boxes = _boxes()
    volumes = np.array([np.prod(size) for size, _ in boxes])
    masses = mass * volumes / volumes.sum()
    com = sum(m * c for m, (_, c) in zip(masses, boxes)) / mass
    moments = np.zeros(3)
    for m, (size, centre) in zip(masses, boxes):
        s2, d2 = size ** 2, (centre - com) ** 2
        moments += m * (s2.sum() - s2) / 12.0 + m * (d2.sum() - d2)  # box + parallel axis
    return com, moments


def _make_t(bm, com: np.ndarray) -> None:
    """The T as one closed quad mesh: the outline in the XZ plane given thickness along Y;
    crossbar faces use material 0, stem faces material 1. ``com`` goes to the origin."""
    h, a, s = THICK / 2, CROSSBAR / 2, STEM
    outline = [(-a, 0), (-h, 0), (-h, -s), (h, -s), (h, 0), (a, 0), (a, 2 * h), (h, 2 * h),
               (-h, 2 * h), (-a, 2 * h)]  # (x, z), counter-clockwise seen from -Y
    caps = [(0, 1, 8, 9), (1, 2, 3, 4), (1, 4, 7, 8), (4, 5, 6, 7)]  # left, stem, middle, right
    n = len(outline)
    front = [bm.verts.new((x - com[0], -h - com[1], z - com[2])) for x, z in outline]
    back = [bm.verts.new((x - com[0], h - com[1], z - com[2])) for x, z in outline]
    faces = [bm.faces.new([front[i] for i in q]) for q in caps]
    faces += [bm.faces.new([back[i] for i in reversed(q)]) for q in caps]
    faces += [bm.faces.new((front[i], back[i], back[(i + 1) % n], front[(i + 1) % n]))
              for i in range(n)]
    for f in faces:
        f.material_index = 1 if f.calc_center_median().z < -com[2] - 1e-6 else 0


def _handle(scene, name: str, x: float, axis: int, materials) -> bpy.types.Object:
    com, _ = mass_properties(MASS)
    ob = _common.add_mesh(scene, f"THandle{name}", lambda bm: _make_t(bm, com))
    ob.location = (x, 0.0, 0.0)
    for mat in materials:
        ob.data.materials.append(mat)
    p = ob.physanim.rigid_body
    p.enabled = True
    p.angular_damping = 0.0  # in space nothing slows the spin down
    w = np.full(3, WOBBLE)
    w[axis] = SPIN
    p.initial_angular_velocity = tuple(w)  # the object is not turned: local axes are world's
    return ob


def build(scene) -> None:
    _common.stage(scene, (0.0, -8.0, 2.6), (0.0, 0.0, 0.0), frame_end=240)
    scene.use_gravity = False
    steel = _common.material("Steel", (0.62, 0.63, 0.66))
    red = _common.material("Stem", (0.8, 0.2, 0.12))
    for k, (name, axis) in enumerate(SPUN.items()):
        _handle(scene, name, (k - 1) * SPACING, axis, (steel, red))


def _axes(scene, ob, frames) -> tuple[np.ndarray, np.ndarray]:
    """World positions (f, 3) and rotation matrices (f, 3, 3) of ``ob`` over ``frames``."""
    x, r = [], []
    for f in frames:
        scene.frame_set(f)
        m = np.array(ob.matrix_world)
        x.append(m[:3, 3])
        r.append(m[:3, :3])
    return np.array(x), np.array(r)


def reversals(cosines: np.ndarray, band: float = FLIP_DOT) -> int:
    """How often a direction turned over: its cosine to the start went from above ``band`` to
    below ``-band`` or back (the band keeps a wobble near 90 degrees from counting)."""
    side, count = 1, 0
    for c in cosines:
        if side > 0 and c < -band or side < 0 and c > band:
            side, count = -side, count + 1
    return count


def check(scene) -> list[str]:
    problems = []
    moments = mass_properties(MASS)[1]
    if list(np.argsort(moments)) != [SPUN["Smallest"], SPUN["Intermediate"], SPUN["Largest"]]:
        problems.append(f"the T's principal moments {moments.round(4).tolist()} [kg m^2] are not "
                        f"in the order the handles are spun about")
    frames = range(scene.physanim.frame_start, scene.physanim.frame_end + 1)
    for name, axis in SPUN.items():
        ob = bpy.data.objects[f"THandle{name}"]
        x, r = _axes(scene, ob, frames)
        drift = float(np.linalg.norm(x - x[0], axis=1).max())
        if drift > 1e-3:
            problems.append(f'"{ob.name}" drifted {drift * 1000:.1f} mm from where it started')
        cosines = r[:, :, axis] @ r[0, :, axis]
        if name == "Intermediate":
            flips = reversals(cosines)
            if flips < 2:
                problems.append(f'"{ob.name}" spun about its intermediate axis turned over '
                                f'{flips} times (expected at least 2)')
        else:
            worst = math.degrees(math.acos(float(np.clip(cosines.min(), -1.0, 1.0))))
            if worst > STEADY_DEG:
                problems.append(f'"{ob.name}" spun about its {name.lower()} axis wandered '
                                f'{worst:.0f} degrees (at most {STEADY_DEG:.0f})')
    return problems
