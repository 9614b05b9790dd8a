"""Rigid-body results: one key per frame on ``location`` and ``rotation_quaternion``, in bulk.

The bake's keys go into an action of their own; the object's previous animation (action, slot,
rotation mode) is set aside on the object and given back by Free Bake. Keys are the object's
local transform (its parent's motion and parent inverse removed), so the evaluated world
transform equals the simulated one; the scale channel is left as it was. The result needs no
extension to play or render.
"""
from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix

from ..core.cache import read_frame
from ..core.controls import ImpactTracker, SquashSettings, log_deformation
from ..core.controls.hang import FlightSettings, shape_flights
from ..core.controls.timing import TimeMap
from ..core.errors import PhysanimError
from ..core.rigid import quaternion as quat
from . import compat, convert, timing


def _tracks(folder: str, frame_start: int, frame_end: int):
    """(frames (f,), positions (f, n, 3), rotations (f, n, 4)) of the cached frames."""
    frames, pos, rot = [], [], []
    for f in range(frame_start, frame_end + 1):
        a = read_frame(folder, f)
        if a is not None:
            frames.append(f)
            pos.append(a["position"])
            rot.append(a["rotation"])
    return np.array(frames, np.float64), np.array(pos), np.array(rot)


def _continuous(q: np.ndarray) -> np.ndarray:
    """(f, 4) quaternions with signs chosen so that consecutive keys interpolate the short way:
    a key turns over when it points away from the key before as keyed (q_k . q'_k-1 < 0). With
    d_k = q_k . q_k-1 of the keys as given, the sign of key k is the product of the signs of
    the d since the last key with d = 0 (which keeps its own sign): a parity of counts, for
    every key at once."""
    q = q.copy()
    if len(q) < 2:
        return q
    d = np.einsum("ij,ij->i", q[1:], q[:-1])
    against = np.concatenate([[0], np.cumsum(d < 0.0)])  # keys pointing away up to each key
    start = np.maximum.accumulate(np.concatenate([[0], np.where(d == 0.0,
                                                                np.arange(1, len(q)), 0)]))
    q[(against - against[start]) % 2 == 1] *= -1.0
    return q


def _parent_spaces(scene, objects: list, frames: np.ndarray) -> dict:
    """Per parented object, (f, 4, 4) its parent's world matrix times its parent inverse at
    each frame: one pass over the frames for all of them."""
    parented = [ob for ob in objects if ob.parent is not None]
    if not parented:
        return {}
    keep = scene.frame_current
    spaces = {ob.name: np.empty((len(frames), 4, 4)) for ob in parented}
    for k, f in enumerate(frames):
        scene.frame_set(int(f))
        for ob in parented:
            spaces[ob.name][k] = (convert.matrix(ob.parent.matrix_world)
                                  @ convert.matrix(ob.matrix_parent_inverse))
    scene.frame_set(keep)
    return spaces


def _local(ob, space, position, rotation):
    """The object's local location and rotation per frame from its world pose (``space``: its
    parent space per frame, or None without a parent)."""
    if space is None:
        return position, rotation
    world = np.zeros((len(position), 4, 4))
    world[:, :3, :3] = quat.to_matrix(rotation) * np.array(ob.matrix_world.to_scale())
    world[:, :3, 3] = position
    world[:, 3, 3] = 1.0
    basis = np.linalg.inv(space) @ world
    lin = basis[:, :3, :3]
    return basis[:, :3, 3], quat.from_matrix(lin / np.linalg.norm(lin, axis=1)[:, None, :])


def plan_keys(scene, objects: list, folder: str, frame_start: int, frame_end: int,
              simulated, clock: TimeMap | None = None, com: np.ndarray | None = None) -> list:
    """Every key :func:`write_keys` will write, computed and checked before anything is
    written: the location and rotation_quaternion of every body ``simulated`` (indices: the
    bodies not on their animation for at least one frame) once per frame, and its scale under
    Squash & Stretch; the others keep their own animation. ``clock``: the bake's time map
    (default: time scale 1); ``com``: (n, 3) the bodies' centres of mass in their own axes
    (what Hang Time and Exaggeration shape; default: their origins).

    Raises :class:`PhysanimError` (naming the body and frame) while nothing is written yet: the
    bake computes this before it swaps any cache in, so a failure here keeps every previous
    bake. Returns ``[(object, frames (f,) float32, location (f, 3), rotation (f, 4), scale
    (f, 3) or None)]``."""
    frames, pos, rot = _tracks(folder, frame_start, frame_end)
    clock = clock or TimeMap.constant(frame_start, frame_end)
    times = timing.frame_seconds(clock, scene, frames)
    if not len(frames):
        return []
    dynamic = [(i, ob) for i, ob in enumerate(objects) if i in simulated]
    spaces = _parent_spaces(scene, [ob for _, ob in dynamic], frames)
    f32 = frames.astype(np.float32)
    plan = []
    for i, ob in dynamic:
        shown_pos, shown_rot = _flights(scene, clock, ob, times, pos[:, i], rot[:, i],
                                        None if com is None else com[i])
        loc, q = _local(ob, spaces.get(ob.name), shown_pos, shown_rot)
        scale = None
        if ob.physanim.rigid_body.squash > 0.0:
            factors = squash_factors(scene, ob, shown_pos, shown_rot, times)
            scale = _own_scale(ob) * factors
        plan.append((ob, f32, loc, _continuous(q), scale))
    return plan


def write_keys(plan: list) -> None:
    """Key each body of a :func:`plan_keys` plan, in bulk, into its baked action."""
    for ob, f32, loc, q, scale in plan:
        bag = compat.channelbag_for(ob, _baked_action(ob))
        for axis in range(3):
            compat.set_keys(compat.fcurve_ensure(bag, "location", axis), f32, loc[:, axis])
        for axis in range(4):
            compat.set_keys(compat.fcurve_ensure(bag, "rotation_quaternion", axis), f32,
                            q[:, axis])
        ob.rotation_mode = 'QUATERNION'
        if scale is not None:
            for axis in range(3):
                compat.set_keys(compat.fcurve_ensure(bag, "scale", axis), f32, scale[:, axis])


def _flights(scene, clock: TimeMap, ob, times, origins: np.ndarray, rotations: np.ndarray,
             com):
    """The body's origins and rotations with its Hang Time and Exaggeration applied to its
    flights (:mod:`..core.controls.hang`), which shape the path of its centre of mass."""
    p = ob.physanim.rigid_body
    settings = FlightSettings(p.hang_time, p.exaggeration)
    if settings.off:
        return origins, rotations
    offset = np.zeros(3) if com is None else np.asarray(com, np.float64)
    centres = origins + quat.rotate(rotations, np.broadcast_to(offset, origins.shape))
    # a flight to the body's mark stays as simulated: it arrives there on its frame
    keep = tuple(np.nonzero(np.isclose(times, timing.frame_seconds(clock, scene,
                                                                   p.target_frame)))[0]) \
        if p.target is not None else ()
    substep = convert.seconds_per_frame(scene) / scene.physanim.rigid_substeps
    centres, rotations = shape_flights(times, centres, rotations, convert.gravity(scene),
                                       settings, keep, substep if not clock.identity else 0.0)
    return centres - quat.rotate(rotations, np.broadcast_to(offset, centres.shape)), rotations


def squash_factors(scene, ob, position: np.ndarray, rotation: np.ndarray,
                   times: np.ndarray) -> np.ndarray:
    """(f, 3) scale factors along the body's own axes for squash and stretch (their product is
    1): the world deformation (:mod:`..core.controls.squash`) from the baked motion (at the
    simulated ``times`` [s] of its frames), seen in the body's axes. Exact when an axis lies
    along the motion or the contact normal (a ball dropped without spin, a box landing flat);
    otherwise the nearest deformation along its axes."""
    p = ob.physanim.rigid_body
    settings = SquashSettings(p.squash, p.squash_recovery)
    steps = np.diff(times)
    velocity = np.zeros_like(position)  # over the frame just ended (the first: the next one)
    if len(position) > 1:
        velocity[1:] = np.diff(position, axis=0) / steps[:, None]
        velocity[0] = velocity[1]
    steps = np.concatenate([steps[:1] if len(steps) else [convert.seconds_per_frame(scene)],
                            steps])
    tracker = ImpactTracker(settings, convert.gravity(scene))
    axes = quat.to_matrix(rotation)
    out = np.empty((len(position), 3))
    for k in range(len(position)):
        impact, age = tracker.update(np.zeros(1, np.int64), velocity[k:k + 1], float(steps[k]))
        world = log_deformation(velocity[k:k + 1], impact, age, settings)[0]
        local = axes[k].T @ world @ axes[k]
        diagonal = np.diag(local)
        with np.errstate(over="ignore"):  # an overflow is reported below, naming the frame
            out[k] = np.exp(diagonal - diagonal.sum() / 3.0)
    bad = ~(np.abs(out) <= np.finfo(np.float32).max).all(axis=1)  # keys are float32
    if bad.any():
        k = int(np.argmax(bad))
        raise PhysanimError(f"Squash & Stretch came to a scale of {out[k].tolist()} (moving at "
                            f"{np.linalg.norm(velocity[k]):.4g} m/s) — lower Squash & Stretch",
                            obj=ob.name, frame=scene.physanim.frame_start + k, kind="rigid body")
    return out


def _own_scale(ob) -> np.ndarray:
    """The object's own scale: as :func:`_baked_action` sets it aside (or set aside already)."""
    p = ob.physanim.rigid_body
    return np.array(p.previous_pose[14:17] if p.baked_action is not None else ob.scale)


def _baked_action(ob) -> bpy.types.Action:
    """The action the bake keys: an earlier bake's, else a new one — then the object's own
    animation and pose are set aside first, for Free Bake to give back."""
    p = ob.physanim.rigid_body
    if p.baked_action is None:
        anim = ob.animation_data
        p.previous_action = anim.action if anim is not None else None
        slot = getattr(anim, "action_slot", None) if anim is not None else None
        p.previous_slot = slot.identifier if slot is not None else ""
        p.previous_rotation_mode = ob.rotation_mode
        p.previous_basis = [v for row in ob.matrix_basis for v in row]
        p.previous_pose = [*ob.location, *ob.rotation_euler, *ob.rotation_quaternion,
                           *ob.rotation_axis_angle, *ob.scale]
        p.baked_action = bpy.data.actions.new(f"PhysAnim {ob.name}")
    return p.baked_action


def _own_animation(ob) -> None:
    """Give the object its own animation, rotation mode and pose (as before its first bake)."""
    p = ob.physanim.rigid_body
    anim = ob.animation_data
    if anim is not None:
        anim.action = p.previous_action
        if p.previous_action is not None and p.previous_slot and compat.HAS_SLOTS:
            slot = next((s for s in p.previous_action.slots
                         if s.identifier == p.previous_slot), None)
            if slot is not None:
                anim.action_slot = slot
    ob.rotation_mode = p.previous_rotation_mode or ob.rotation_mode
    if p.previous_action is not None:
        return
    pose = list(p.previous_pose)
    if any(pose):
        ob.location, ob.rotation_euler = pose[:3], pose[3:6]
        ob.rotation_quaternion, ob.rotation_axis_angle = pose[6:10], pose[10:14]
        ob.scale = pose[14:]
        return
    basis = np.array(p.previous_basis).reshape(4, 4)  # set aside by an older version
    if np.any(basis):
        # a Matrix from rows: a nested list assigned to the property would be read as columns
        # (the translation would land in the bottom row and the object at the origin)
        ob.matrix_basis = Matrix(basis.tolist())


def suspend(ob):
    """While baking, the object shows its own animation (the bake starts from it, not from an
    earlier bake's keys). Returns what :func:`restore` needs (None: nothing was baked)."""
    p = ob.physanim.rigid_body
    if p.baked_action is None:
        return None
    _own_animation(ob)
    return p.baked_action


def restore(ob, baked) -> None:
    """Put an earlier bake's keys back (the new bake failed or was cancelled)."""
    if baked is not None:
        compat.channelbag_for(ob, baked)
        ob.rotation_mode = 'QUATERNION'


def free_keys(ob) -> bool:
    """Remove the bake's keys and give the object its own animation back. True if it had one."""
    p = ob.physanim.rigid_body
    baked = p.baked_action
    if baked is None:
        return False
    _own_animation(ob)
    p.previous_action = None
    p.previous_slot = ""
    p.previous_rotation_mode = ""
    p.baked_action = None
    p.bake_hash = ""
    if baked.users == 0:
        bpy.data.actions.remove(baked)
    return True
