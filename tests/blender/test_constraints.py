"""Constraints seen from Blender: an object with the Constraint role joins a rigid body to the
world, another rigid body or an animated object at its origin and axes; the bake keys the
bodies as they hang, swing and turn, records where a breakable one broke, and marks the bake
outdated when a constraint changes."""
from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest
from mathutils import Vector

FRAME_START, FRAME_END = 1, 48


def _addon(ext, name: str):
    return sys.modules[f"{ext.__name__}.addon.{name}"]


def _scene(tmp_path: Path, end: int = FRAME_END):
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = FRAME_START, end
    scene.physanim.frame_start, scene.physanim.frame_end = FRAME_START, end
    scene.render.fps, scene.render.fps_base = 24, 1.0
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "constraints.blend"))
    return scene


def _cube(location=(0.0, 0.0, 3.0), **props):
    bpy.ops.mesh.primitive_cube_add(location=location)
    ob = bpy.context.object
    ob.physanim.rigid_body.enabled = True
    for key, value in props.items():
        setattr(ob.physanim.rigid_body, key, value)
    return ob


def _empty(name: str, location, rotation=(0.0, 0.0, 0.0)):
    ob = bpy.data.objects.new(name, None)
    bpy.context.scene.collection.objects.link(ob)
    ob.location, ob.rotation_euler = location, rotation
    return ob


def _constraint(name, location, first, second=None, kind=None, **props):
    ob = _empty(name, location)
    c = ob.physanim.constraint
    c.enabled = True
    c.object1 = first
    if second is not None:
        c.object2 = second
    if kind is not None:
        c.type = kind
    for key, value in props.items():
        setattr(c, key, value)
    return ob


def _pivot_track(scene, body, local, frames) -> np.ndarray:
    """World positions of the body's point ``local`` (its own axes) at ``frames``."""
    out = []
    for f in frames:
        scene.frame_set(f)
        out.append(np.array(body.matrix_world @ Vector(local)))
    return np.array(out)


def test_a_cube_hangs_and_swings_from_a_default_constraint(physanim_ext, tmp_path):
    """Enable the role and choose the body (its First object), nothing else: a ball joint to
    the world at the Empty. The cube, its corner at the Empty, swings down and its corner stays
    on the Empty."""
    scene = _scene(tmp_path)
    cube = _cube(location=(0.0, 0.0, 3.0))
    _constraint("Hook", (1.0, 1.0, 4.0), cube)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    frames = range(FRAME_START, FRAME_END + 1)
    corner = _pivot_track(scene, cube, (1.0, 1.0, 1.0), frames)
    assert np.abs(corner - (1.0, 1.0, 4.0)).max() < 1e-3
    centre = _pivot_track(scene, cube, (0.0, 0.0, 0.0), frames)
    assert centre[:, 2].min() < 4.0 - 0.95 * math.sqrt(3.0)  # it swung down under its corner
    assert "1 constraint(s)" in scene.physanim.bake_info


def test_a_constraint_without_its_body_names_itself_and_keeps_the_previous_bake(physanim_ext,
                                                                               tmp_path):
    scene = _scene(tmp_path)
    cube = _cube()
    hook = _constraint("Hook", (1.0, 1.0, 4.0), cube)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    scene.frame_set(24)
    before = np.array(cube.matrix_world)
    hook.physanim.constraint.object1 = None
    with pytest.raises(RuntimeError, match='constraint "Hook".*First object must be a rigid body'):
        bpy.ops.physanim.bake()
    scene.frame_set(24)
    np.testing.assert_allclose(np.array(cube.matrix_world), before, atol=1e-7)


def test_a_hinge_motor_turns_a_door_and_a_limit_stops_it(physanim_ext, tmp_path):
    """A 2 m door hinged at its edge about the vertical (the Empty's Z), its motor at 1 rad/s
    and limits of +-45 degrees: it turns at the motor's speed and stops at 45 degrees."""
    scene = _scene(tmp_path)
    door = _cube(location=(1.0, 0.0, 1.0), angular_damping=0.0)
    door.scale = (1.0, 0.05, 1.0)
    _constraint("Hinge", (0.0, 0.0, 1.0), door, kind='HINGE', use_motor=True,
                motor_velocity=1.0, motor_max=200.0, use_limits=True,
                angle_lower=-math.pi / 4, angle_upper=math.pi / 4)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    angles = []
    for f in range(FRAME_START, FRAME_END + 1):
        scene.frame_set(f)
        x = door.matrix_world.to_3x3().col[0]
        angles.append(math.atan2(x.y, x.x))
    angles = np.array(angles)
    speed = (angles[13] - angles[11]) * 12.0  # frames 12 -> 14, 24 fps
    assert speed == pytest.approx(1.0, rel=0.03)
    assert angles.max() < math.pi / 4 + 2e-3 and angles[-1] == pytest.approx(math.pi / 4,
                                                                              abs=1e-2)
    scene.frame_set(FRAME_END)
    assert door.matrix_world.to_3x3().col[2].z > 1 - 1e-5  # upright


def test_a_breakable_constraint_breaks_and_says_when(physanim_ext, tmp_path):
    """A 1 kg cube hangs from a ball joint that breaks above 5 N (it carries 9.81 N): it
    breaks at once, the frame is recorded on the constraint and in the bake's report, and the
    cube falls."""
    scene = _scene(tmp_path, end=24)
    cube = _cube(location=(0.0, 0.0, 3.0))
    hook = _constraint("Hook", (0.0, 0.0, 4.0), cube, use_breaking=True, break_force=5.0)
    held = _constraint("Held", (5.0, 0.0, 4.0), _cube(location=(5.0, 0.0, 3.0)))
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert hook.physanim.constraint.broken_frame == FRAME_START + 1
    assert held.physanim.constraint.broken_frame == -1
    assert 'constraint "Hook" broke at frame 2' in scene.physanim.bake_info
    scene.frame_set(24)
    assert cube.matrix_world.translation.z < 3.0 - 0.5 * 9.81 * (23 / 24) ** 2 * 0.95
    assert bpy.ops.physanim.free_bake() == {'FINISHED'}  # the record goes with the bake
    assert hook.physanim.constraint.broken_frame == -1


def _key_constant(ext, ob, path: str, frames_values) -> None:
    """Key ``ob.physanim.constraint.<path>`` at each (frame, value), held between keys."""
    c = ob.physanim.constraint
    for frame, value in frames_values:
        setattr(c, path, value)
        c.keyframe_insert(path, frame=frame)
    for fcurve in _addon(ext, "compat").action_fcurves(ob.animation_data):
        for point in fcurve.keyframe_points:
            point.interpolation = 'CONSTANT'


def test_keyed_breaking_force_and_motor_steer_the_constraints(physanim_ext, tmp_path):
    """Constraint values are keyframable and read every frame: a hook whose breaking force is
    keyed from 100 N down to 5 N at frame 12 (it carries 9.81 N) lets go there (recorded as
    frame 13, when the break shows); a hinge motor keyed from +2 to -2 rad/s at frame 24
    turns the door one way, then back."""
    scene = _scene(tmp_path)
    cube = _cube(location=(0.0, 0.0, 3.0))
    hook = _constraint("Hook", (0.0, 0.0, 4.0), cube, use_breaking=True)
    _key_constant(physanim_ext, hook, "break_force", [(1, 100.0), (12, 5.0)])
    door = _cube(location=(6.5, 0.0, 1.0))
    door.scale = (0.5, 0.025, 1.0)
    hinge = _constraint("DoorHinge", (6.0, 0.0, 1.0), door, kind='HINGE', use_motor=True,
                        motor_max=50.0)
    _key_constant(physanim_ext, hinge, "motor_velocity", [(1, 2.0), (24, -2.0)])
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert hook.physanim.constraint.broken_frame == 13
    scene.frame_set(12)
    assert cube.matrix_world.translation.z == pytest.approx(3.0, abs=1e-3)
    angles = []
    for f in range(FRAME_START, FRAME_END + 1):
        scene.frame_set(f)
        x = door.matrix_world.to_3x3().col[0]
        angles.append(math.atan2(x.y, x.x))
    turn = int(np.argmax(angles)) + FRAME_START
    assert 24 <= turn <= 27 and angles[-1] < angles[turn - FRAME_START] - 0.5


def test_two_bodies_on_a_hinge_swing_together(physanim_ext, tmp_path):
    """Two cubes joined by a hinge at their shared edge, the first hung from the world: the
    shared edge's points stay together on both."""
    scene = _scene(tmp_path)
    a = _cube(location=(0.0, 0.0, 3.0))
    b = _cube(location=(2.0, 0.0, 3.0))
    _constraint("Top", (-1.0, 0.0, 4.0), a)
    _constraint("Edge", (1.0, 0.0, 4.0), a, b, kind='HINGE')
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    frames = range(FRAME_START, FRAME_END + 1)
    on_a = _pivot_track(scene, a, (1.0, 0.0, 1.0), frames)
    on_b = _pivot_track(scene, b, (-1.0, 0.0, 1.0), frames)
    assert np.abs(on_a - on_b).max() < 1e-3
    assert np.abs(on_a[-1] - on_a[0]).max() > 0.5  # they swung


def test_an_animated_empty_carries_the_body_it_holds(physanim_ext, tmp_path):
    """A crane hook: the cube hangs from an animated Empty (the constraint's Second object)
    that moves 3 m along X; the cube's top stays on the hook."""
    scene = _scene(tmp_path)
    cube = _cube(location=(0.0, 0.0, 3.0))
    crane = _empty("Crane", (0.0, 0.0, 4.0))
    crane.keyframe_insert("location", frame=1)
    crane.location.x = 3.0
    crane.keyframe_insert("location", frame=FRAME_END)
    _constraint("Hook", (0.0, 0.0, 4.0), cube, crane)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    top = _pivot_track(scene, cube, (0.0, 0.0, 1.0), range(FRAME_START, FRAME_END + 1))
    hook = []
    for f in range(FRAME_START, FRAME_END + 1):
        scene.frame_set(f)
        hook.append(np.array(crane.matrix_world.translation))
    assert np.abs(top - np.array(hook)).max() < 1e-3
    assert top[-1, 0] == pytest.approx(3.0, abs=1e-3)


def test_editing_a_constraint_makes_the_bake_outdated(physanim_ext, tmp_path):
    scene = _scene(tmp_path, end=12)
    cube = _cube()
    hook = _constraint("Hook", (1.0, 1.0, 4.0), cube)
    panels = _addon(physanim_ext, "panels")
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert panels.bake_status(scene)[1] == 'CHECKMARK'
    hook.physanim.constraint.type = 'HINGE'
    assert "outdated" in panels.bake_status(scene)[0]
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert panels.bake_status(scene)[1] == 'CHECKMARK'
    hook.location.x = 0.5
    assert "outdated" in panels.bake_status(scene)[0]


@pytest.mark.parametrize("pattern, expected", [("CHAIN", 3), ("ACTIVE", 3), ("NEIGHBOURS", 3)])
def test_connect_selected_builds_chains_stars_and_walls(physanim_ext, tmp_path, pattern, expected):
    """Four cubes in a row, 2 m apart (touching): a chain joins each to the next from the
    active one, a star each to the active one, neighbours each touching pair; the pivots of
    touching cubes lie on their shared faces. The result bakes."""
    scene = _scene(tmp_path, end=6)
    cubes = [_cube(location=(2.0 * i, 0.0, 1.0)) for i in range(4)]
    for ob in bpy.context.view_layer.objects:
        ob.select_set(ob in cubes)
    bpy.context.view_layer.objects.active = cubes[0]
    assert bpy.ops.physanim.connect(type='HINGE', pattern=pattern) == {'FINISHED'}
    made = [ob for ob in scene.objects if ob.physanim.constraint.enabled]
    assert len(made) == expected
    joined = {frozenset((ob.physanim.constraint.object1.name, ob.physanim.constraint.object2.name))
              for ob in made}
    names = [c.name for c in cubes]
    if pattern == "ACTIVE":
        assert joined == {frozenset((names[0], n)) for n in names[1:]}
    else:
        assert joined == {frozenset(p) for p in zip(names[:-1], names[1:])}
        for ob in made:
            c = ob.physanim.constraint
            mid = 0.5 * (np.array(c.object1.location) + np.array(c.object2.location))
            np.testing.assert_allclose(np.array(ob.location), mid, atol=1e-6)
    assert all(ob.physanim.constraint.type == 'HINGE' for ob in made)
    assert bpy.ops.physanim.bake() == {'FINISHED'}


def test_connect_needs_two_rigid_bodies(physanim_ext, tmp_path):
    _scene(tmp_path, end=6)
    cube = _cube()
    for ob in bpy.context.view_layer.objects:
        ob.select_set(ob == cube)
    with pytest.raises(RuntimeError, match="at least two rigid bodies"):
        bpy.ops.physanim.connect()


# -- spring meshes held on objects (attachments) -----------------------------------------------

def _pc2_world(ext, ob) -> np.ndarray:
    """(frames, n, 3) world positions of a baked spring mesh."""
    path = bpy.path.abspath(ob.modifiers["physanim"].filepath)
    samples = sys.modules[f"{ext.__name__}.core.pc2"].read_pc2(path)[0]
    m = np.array(ob.matrix_world)
    return samples @ m[:3, :3].T + m[:3, 3]


def _cloth(location=(0.0, 0.0, 2.0), pin_top=True):
    """A 9 x 9 grid of 1 m standing in the xz plane as a spring mesh, its top row pinned (vertex
    group "Top"), its bottom row in the vertex group "Hook"."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=8, y_subdivisions=8, size=1.0,
                                    location=location, rotation=(math.pi / 2, 0.0, 0.0))
    ob = bpy.context.object
    bpy.ops.object.transform_apply(location=False, rotation=True, scale=False)
    z = np.array([v.co.z for v in ob.data.vertices])
    for name, rows in (("Top", z > z.max() - 1e-6), ("Hook", z < z.min() + 1e-6)):
        group = ob.vertex_groups.new(name=name)
        group.add([int(i) for i in np.nonzero(rows)[0]], 1.0, 'REPLACE')
    ob.physanim.spring_mesh.enabled = True
    if pin_top:
        ob.physanim.spring_mesh.pin_group = "Top"
    return ob


def test_a_constraint_holding_a_spring_mesh_at_its_defaults_holds_it_where_it_is(physanim_ext,
                                                                             tmp_path):
    """Enable the role and choose a spring mesh as First, nothing else: all its vertices are
    held where they are (on the world) — the whole bake keeps the first frame's shape."""
    scene = _scene(tmp_path)
    cloth = _cloth(pin_top=False)
    _constraint("Glue", (0.0, 0.0, 2.0), cloth)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    x = _pc2_world(physanim_ext, cloth)
    assert len(x) == scene.physanim.frame_end - scene.physanim.frame_start + 1
    np.testing.assert_allclose(x, np.broadcast_to(x[0], x.shape), atol=1e-6)


def test_a_rigid_box_hangs_from_a_cloth_which_it_pulls(physanim_ext, tmp_path):
    """A 5 kg cube hung by its top face on the cloth's bottom row (an attachment to a rigid
    body): the cloth holds it — it stays within 15 cm of where it started, where without the
    constraint it falls over 2 m in the same 2 s — and it pulls the cloth: the hook row stays
    on the cube's top face, lower than the cloth hanging alone."""
    _scene(tmp_path)
    cloth = _cloth()
    cube = _cube(location=(0.0, 0.0, 1.4), mass=5.0)
    cube.scale = (0.5, 0.1, 0.1)
    _constraint("Sign", (0.0, 0.0, 1.5), cloth, cube, group1="Hook")
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    frames = range(FRAME_START, FRAME_END + 1)
    top = _pivot_track(bpy.context.scene, cube, (0.0, 0.0, 1.0), frames)
    assert np.max(np.abs(top[:, 2] - 1.5)) < 0.15
    x = _pc2_world(physanim_ext, cloth)
    group = cloth.vertex_groups["Hook"].index
    hook = [v.index for v in cloth.data.vertices if any(g.group == group for g in v.groups)]
    np.testing.assert_allclose(x[-1][hook, 2], top[-1, 2], atol=2e-3)

    c = bpy.data.objects["Sign"].physanim.constraint
    c.enabled = False
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    fallen = _pivot_track(bpy.context.scene, cube, (0.0, 0.0, 1.0), frames)
    assert fallen[-1, 2] < 1.5 - 2.0
    alone = _pc2_world(physanim_ext, cloth)  # the cloth hanging under its own weight only
    assert x[-1][hook, 2].mean() < alone[-1][hook, 2].mean() - 0.005


@pytest.mark.parametrize("change, message", [
    ({"type": 'HINGE'}, "can only be held (Fixed or Ball), not by Hinge"),
    ({"type": 'ON_CIRCLE'}, "can only be held (Fixed or Ball), not by On Wire"),
    ({"group1": "Nope"}, '"Nope" is not a vertex group of "Grid"'),
    ({"use_breaking": True}, "cannot break"),
])
def test_an_attachment_that_cannot_hold_says_why(physanim_ext, tmp_path, change, message):
    _scene(tmp_path)
    cloth = _cloth()
    cube = _cube(location=(0.0, 0.0, 1.4))
    ob = _constraint("Sign", (0.0, 0.0, 1.5), cloth, cube, group1="Hook")
    for key, value in change.items():
        setattr(ob.physanim.constraint, key, value)
    with pytest.raises(RuntimeError, match=re.escape(message)):
        bpy.ops.physanim.bake()


# -- an emitter's particles held on planes, spheres and wires ---------------------------------

def _particle_frames(ext, emitter) -> list:
    """Every cached frame of an emitter's result: dicts of arrays."""
    res = emitter.physanim.emitter.result
    folder = bpy.path.abspath(res.physanim.result.cache)
    read = sys.modules[f"{ext.__name__}.core.cache"].read_frame
    scene = bpy.context.scene
    return [read(folder, f) for f in range(scene.physanim.frame_start,
                                            scene.physanim.frame_end + 1)]


@pytest.mark.parametrize("kind", ['ON_PLANE', 'ON_CIRCLE'])
def test_an_emitters_particles_stay_on_a_plane_or_a_wire(physanim_ext, tmp_path, kind):
    """A default plane emitter and a constraint holding its particles, with only its type (and
    its placement) set: On Plane — a vertical plane through the origin (the Empty turned 90
    degrees about X): every particle has y = 0 in every frame while they fly up and fall; On
    Wire — the vertical circle of the default radius (1 m) about (0, 0, 1): every particle is
    on it."""
    _scene(tmp_path)
    bpy.ops.mesh.primitive_plane_add()
    emitter = bpy.context.object
    emitter.physanim.emitter.enabled = True
    centre = (0.0, 0.0, 0.0) if kind == 'ON_PLANE' else (0.0, 0.0, 1.0)
    rail = _constraint("Rail", centre, emitter, kind=kind)
    rail.rotation_euler = (math.pi / 2, 0.0, 0.0)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    frames = [a for a in _particle_frames(physanim_ext, emitter) if len(a["id"])]
    assert len(frames) > 40
    x = np.concatenate([a["position"] for a in frames])
    np.testing.assert_allclose(x[:, 1], 0.0, atol=1e-5)
    if kind == 'ON_CIRCLE':
        np.testing.assert_allclose(np.linalg.norm(x - centre, axis=1), 1.0, atol=1e-5)
    assert np.ptp(x[:, 2]) > 1.0 and np.ptp(x[:, 0]) > 0.5  # they move, on it


def test_an_emitter_held_by_a_joint_type_says_why(physanim_ext, tmp_path):
    _scene(tmp_path)
    bpy.ops.mesh.primitive_plane_add()
    emitter = bpy.context.object
    emitter.physanim.emitter.enabled = True
    _constraint("Rail", (0.0, 0.0, 0.0), emitter, kind='HINGE')
    with pytest.raises(RuntimeError, match="held On Plane, On Sphere, On Wire or by a Tie, "
                                           "not by a Hinge joint"):
        bpy.ops.physanim.bake()


def _still_after(frames: list, reach_of, centre) -> tuple[int, int]:
    """(particles within ``reach_of`` of ``centre`` at some frame, those of them that never
    moved after it by more than 1e-9 m)."""
    first, moved = {}, set()
    for a in frames:
        for pid, x in zip(a["id"].tolist(), a["position"]):
            if pid in first:
                if np.linalg.norm(x - first[pid]) > 1e-9:
                    moved.add(pid)
            elif np.linalg.norm(x - centre) <= reach_of:
                first[pid] = x
    return len(first), len(set(first) - moved)


def test_a_tie_at_its_defaults_holds_the_particles_born_at_it(physanim_ext, tmp_path):
    """An emitter giving its particles from its origin (at the default 5 m/s) and a
    constraint on it with only its type set to Tie: every particle within the Tie's Reach
    (5 cm) of its origin at a frame stays exactly there from then on (tied to the world), and
    there are many of them; the others fly off."""
    _scene(tmp_path)
    bpy.ops.mesh.primitive_plane_add(location=(0.0, 0.0, 1.0))
    emitter = bpy.context.object
    emitter.physanim.emitter.enabled = True
    emitter.physanim.emitter.source = 'ORIGIN'
    _constraint("Hook", (0.0, 0.0, 1.0), emitter, kind='TIE')
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    frames = _particle_frames(physanim_ext, emitter)
    near, still = _still_after(frames, 0.05, np.array([0.0, 0.0, 1.0]))
    assert near > 100 and still == near
    assert np.ptp(frames[-1]["position"][:, 2]) > 1.0  # the others flew


def _rope(top=3.0, bottom=2.0):
    """A rope emitter: 20 particles of 0.1 kg born for the first frame (in the interval
    before it) while it moves from ``top`` down to ``bottom``, each joined to the one before
    by a rigid link."""
    bpy.ops.mesh.primitive_plane_add(size=0.05, location=(0.0, 0.0, top))
    ob = bpy.context.object
    e = ob.physanim.emitter
    e.enabled = True
    e.source = 'ORIGIN'
    e.frame_start, e.frame_end = 1, 1
    e.speed, e.spread, e.lifetime = 0.0, 0.0, 1000.0
    e.link, e.link_hard = True, True
    ob.keyframe_insert("location", frame=0)
    ob.location.z = bottom
    ob.keyframe_insert("location", frame=1)
    return ob


def test_a_rigid_body_tied_to_a_particle_rope_hangs_from_it_and_pulls_it(physanim_ext,
                                                                          tmp_path):
    """A particle rope tied to the world at its top and to a 1 kg cube at its bottom (Tie with
    the cube as Second): the rope holds the cube — within 25 cm of where it started after 2 s,
    where without the tie it falls over 2 m — its tied particle stays on the cube (its
    distance from the cube's centre changes by under 1e-4 m), and the cube pulls the rope
    taut: the rope's particles end up spanning more than 0.9 m."""
    scene = _scene(tmp_path)
    rope = _rope()
    cube = _cube(location=(0.0, 0.0, 1.9))
    cube.scale = (0.1, 0.1, 0.1)
    _constraint("Hook", (0.0, 0.0, 3.0), rope, kind='TIE')
    tie = _constraint("Crate", (0.0, 0.0, 2.0), rope, cube, kind='TIE')
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    frames = _particle_frames(physanim_ext, rope)
    centres = _pivot_track(scene, cube, (0.0, 0.0, 0.0), range(FRAME_START, FRAME_END + 1))
    assert np.max(np.abs(centres[:, 2] - 1.9)) < 0.25
    ids = frames[-1]["id"]
    tied = int(ids[np.argmin(frames[-1]["position"][:, 2])])  # the lowest: on the cube
    gaps = [np.linalg.norm(a["position"][list(a["id"]).index(tied)] - c)
            for a, c in zip(frames, centres)]
    assert np.ptp(gaps) < 1e-4
    assert np.ptp(frames[-1]["position"][:, 2]) > 0.9

    tie.physanim.constraint.enabled = False
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    fallen = _pivot_track(scene, cube, (0.0, 0.0, 0.0), [FRAME_END])
    assert fallen[0, 2] < 1.9 - 2.0


def test_a_spring_constraint_at_its_defaults_bounces_a_cube_on_it(physanim_ext, tmp_path):
    """Type Spring, nothing else set: the 1 kg cube hangs from the Empty at its centre on a
    damped spring of 10 N/m — it drops, bounces about the static sag m g / k = 0.98 m below
    (with the period 2 pi sqrt(m / k) = 2 s) and does not turn (the pull is at its centre)."""
    scene = _scene(tmp_path, end=120)
    cube = _cube(location=(0.0, 0.0, 3.0))
    _constraint("Bungee", (0.0, 0.0, 3.0), cube, kind='SPRING')
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    z = []
    for f in range(FRAME_START, 121):
        scene.frame_set(f)
        z.append(cube.matrix_world.translation.z)
    z = np.array(z) - (3.0 - 9.81 / 10.0)
    assert z.min() < -0.7 * 0.98  # it overshoots the sag
    down = np.nonzero((z[:-1] > 0.0) & (z[1:] <= 0.0))[0]
    assert np.mean(np.diff(down)) / 24 == pytest.approx(2 * math.pi * math.sqrt(0.1), rel=0.05)
    assert cube.matrix_world.to_3x3().col[2].z > 1 - 1e-6


def test_a_constraint_on_an_object_in_two_roles_holds_what_its_type_says(physanim_ext,
                                                                         tmp_path):
    """A mesh that is both a spring mesh and an emitter: On Plane holds its particles (they
    stay in the plane) and leaves its vertices free (it falls); Ball holds its vertices (it
    stays) and is no error for its particles."""
    scene = _scene(tmp_path, end=24)
    cloth = _cloth(pin_top=False)
    cloth.physanim.emitter.enabled = True
    rail = _constraint("Rail", (0.0, 0.0, 0.0), cloth, kind='ON_PLANE')
    rail.rotation_euler = (math.pi / 2, 0.0, 0.0)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    x = np.concatenate([a["position"] for a in _particle_frames(physanim_ext, cloth)
                        if len(a["id"])])
    np.testing.assert_allclose(x[:, 1], 0.0, atol=1e-5)
    assert _pc2_world(physanim_ext, cloth)[-1][:, 2].max() < 1.5  # its vertices fell
    rail.physanim.constraint.type = 'BALL'
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    mesh = _pc2_world(physanim_ext, cloth)
    np.testing.assert_allclose(mesh[-1], mesh[0], atol=1e-6)
    assert scene.physanim.frame_end == 24


def _curve_wire(name, kind='CIRCLE', **placement):
    add = {'CIRCLE': bpy.ops.curve.primitive_bezier_circle_add,
           'BEZIER': bpy.ops.curve.primitive_bezier_curve_add}[kind]
    add(**placement)
    ob = bpy.context.object
    ob.name = name
    return ob


def _evaluated_polyline(ob):
    """The curve's evaluated points in world space, in order, and whether it is closed (read
    here through Blender's own API, independently of the add-on)."""
    me = ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    co = np.array([ob.matrix_world @ v.co for v in me.vertices])
    closed = len(me.edges) == len(me.vertices)
    ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh_clear()
    return co, closed


def _off_polyline(x, pts, closed):
    a, b = (pts, np.roll(pts, -1, axis=0)) if closed else (pts[:-1], pts[1:])
    d = b - a
    u = np.clip(np.einsum("rsk,sk->rs", x[:, None] - a[None], d) / np.einsum("sk,sk->s", d, d),
                0.0, 1.0)
    return np.min(np.linalg.norm(x[:, None] - (a[None] + u[..., None] * d[None]), axis=2),
                  axis=1)


@pytest.mark.parametrize("bevel", [0.0, 0.05])
def test_an_emitters_particles_run_along_a_curve_object_at_the_defaults(physanim_ext, tmp_path,
                                                                        bevel):
    """On Wire on a Curve object, nothing else set: a default plane emitter under Blender's
    default Bezier circle (radius 1) stood up vertical about (0, 0, 1). Every particle is on the
    curve as Blender evaluates it (its 48-point polyline at the default resolution), in every
    frame, and they run round it (they are not pinned where they were born). A bevel (the wire
    shown as a tube) changes nothing: the wire is the curve's centre line, and the bevel is
    back as it was after the bake."""
    _scene(tmp_path)
    bpy.ops.mesh.primitive_plane_add()
    emitter = bpy.context.object
    emitter.physanim.emitter.enabled = True
    wire = _curve_wire("Loop", location=(0.0, 0.0, 1.0), rotation=(math.pi / 2, 0.0, 0.0))
    wire.data.bevel_depth = bevel
    c = wire.physanim.constraint
    c.enabled, c.object1, c.type = True, emitter, 'ON_CIRCLE'
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert wire.data.bevel_depth == pytest.approx(bevel)
    frames = [a for a in _particle_frames(physanim_ext, emitter) if len(a["id"])]
    assert len(frames) > 40
    x = np.concatenate([a["position"] for a in frames])
    wire.data.bevel_depth = 0.0  # the centre line, read through Blender's API
    pts, closed = _evaluated_polyline(wire)
    assert closed and len(pts) >= 16
    assert _off_polyline(x, pts, closed).max() < 1e-5
    assert np.ptp(x[:, 2]) > 1.0 and np.ptp(x[:, 0]) > 1.0  # along the loop, not pinned


def test_a_curve_wire_that_is_not_one_spline_says_why(physanim_ext, tmp_path):
    _scene(tmp_path)
    bpy.ops.mesh.primitive_plane_add()
    emitter = bpy.context.object
    emitter.physanim.emitter.enabled = True
    wire = _curve_wire("Rails", 'BEZIER', location=(0.0, 0.0, 1.0))
    second = wire.data.splines.new('POLY')
    second.points.add(1)
    second.points[1].co = (0.0, 1.0, 0.0, 1.0)
    c = wire.physanim.constraint
    c.enabled, c.object1, c.type = True, emitter, 'ON_CIRCLE'
    with pytest.raises(RuntimeError, match=r'"Rails".*one spline: this curve has 2 splines'):
        bpy.ops.physanim.bake()


def test_particles_ride_a_curve_wire_that_moves_and_bends(physanim_ext, tmp_path):
    """The curve wire keyed to slide 1 m along x over the bake and one of its control points
    keyed to move (the wire bends): at every frame every particle is on the curve as Blender
    evaluates it at that frame."""
    scene = _scene(tmp_path)
    bpy.ops.mesh.primitive_plane_add()
    emitter = bpy.context.object
    emitter.physanim.emitter.enabled = True
    wire = _curve_wire("Loop", location=(0.0, 0.0, 1.0), rotation=(math.pi / 2, 0.0, 0.0))
    c = wire.physanim.constraint
    c.enabled, c.object1, c.type = True, emitter, 'ON_CIRCLE'
    point = wire.data.splines[0].bezier_points[0]
    for frame, dx in ((FRAME_START, 0.0), (FRAME_END, 1.0)):
        wire.location.x = dx
        wire.keyframe_insert("location", index=0, frame=frame)
        point.co.x = -1.0 - 0.5 * dx  # pulled out: the loop bends
        point.keyframe_insert("co", frame=frame)
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "constraints.blend"))
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    frames = _particle_frames(physanim_ext, emitter)
    worst, seen = 0.0, 0
    for frame, data in zip(range(FRAME_START, FRAME_END + 1), frames):
        if not len(data["id"]):
            continue
        scene.frame_set(frame)
        pts, closed = _evaluated_polyline(wire)
        worst = max(worst, float(_off_polyline(data["position"], pts, closed).max()))
        seen += 1
    assert seen > 40 and worst < 1e-4
