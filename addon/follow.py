"""Follow-through on Blender objects: a child object trails its parent — animated or simulated —
through a damped spring (:mod:`..core.controls.follow`), baked to ``delta_location`` keys.

The child's own animation stays as it is (``location``, rotation, scale): the spring moves it
by Delta Location only, the offset from where the parent carries it, in the parent's space.
The bake runs after every other system has been written, so a rigid-body parent swings its
child with the motion it was just baked with. Free Bake removes the keys.
"""
from __future__ import annotations

import bpy
import numpy as np

from ..core.controls import FollowSettings, follow_through
from ..core.controls.timing import TimeMap
from ..core.errors import PhysanimError
from . import compat, timing

DATA_PATH = "delta_location"
_CREATED = "physanim_follow"  # custom property on an action the bake made (Free removes it)


def check(ob, frame: int) -> FollowSettings:
    """The follower's spring; a clear error when it cannot follow."""
    if ob.parent is None:
        raise PhysanimError("Follow-Through trails the object's parent, and it has none — "
                            "parent it to what it should follow", obj=ob.name, frame=frame,
                            kind="follow-through")
    p = ob.physanim.follow
    if _own_delta_keys(ob):
        raise PhysanimError("Follow-Through writes Delta Location keys, and the object has "
                            "keys of its own there — remove them first", obj=ob.name,
                            frame=frame, kind="follow-through")
    try:
        return FollowSettings(p.frequency, p.damping)
    except ValueError as exc:
        raise PhysanimError(str(exc), obj=ob.name, frame=frame, kind="follow-through") from exc


def bake(scene, objects: list, frame_start: int, frame_end: int,
         clock: TimeMap | None = None) -> None:
    """Sample where each parent carries its child, frame by frame, and key the child's
    follow-through as Delta Location (one key per frame). The frame before the first is
    sampled too: the child starts at rest on its place, moving as the parent moved then (a
    parent that sets off at the first frame leaves it behind). ``clock``: the bake's time map
    (the spring swings in simulated time: slow motion slows the jiggle too)."""
    if not objects:
        return
    settings = [check(ob, frame_start) for ob in objects]
    frames = np.arange(frame_start - 1, frame_end + 1)
    targets = np.empty((len(frames), len(objects), 3))
    spaces = np.empty((len(frames), len(objects), 3, 3))
    for k, frame in enumerate(frames):
        scene.frame_set(int(frame))
        for i, ob in enumerate(objects):
            carrier = np.array(ob.parent.matrix_world @ ob.matrix_parent_inverse)
            targets[k, i] = carrier[:3, :3] @ np.array(ob.location) + carrier[:3, 3]
            spaces[k, i] = carrier[:3, :3]
    if not np.isfinite(targets).all():
        k, i = np.argwhere(~np.isfinite(targets).all(axis=2))[0]
        raise PhysanimError(f"the parent carries it to {targets[k, i].tolist()}",
                            obj=objects[i].name, frame=int(frames[k]), kind="follow-through")
    clock = clock or TimeMap.constant(frame_start, frame_end)  # springs swing in simulated time
    times = timing.frame_seconds(clock, scene, frames) - timing.frame_seconds(clock, scene,
                                                                              frame_start)
    for i, ob in enumerate(objects):
        trail = follow_through(times, targets[:, i], settings[i])
        local = np.linalg.solve(spaces[:, i], (trail - targets[:, i])[:, :, None])[:, :, 0]
        _write(ob, frames[1:].astype(np.float32), local[1:])


def _write(ob, frames: np.ndarray, delta: np.ndarray) -> None:
    remove_keys(ob)
    anim = ob.animation_data
    created = anim is None or anim.action is None
    bag = compat.channelbag_for(ob)
    if created:
        ob.animation_data.action[_CREATED] = True
    for axis in range(3):
        compat.set_keys(compat.fcurve_ensure(bag, DATA_PATH, axis), frames, delta[:, axis])


def _own_delta_keys(ob) -> bool:
    """Delta Location keys that are not a follow-through bake's."""
    if ob.physanim.follow.bake_hash:
        return False
    return any(fc.data_path == DATA_PATH for fc in compat.action_fcurves(ob.animation_data))


def remove_keys(ob) -> bool:
    """Remove the follow-through keys (and an action the bake made, once empty) and zero Delta
    Location. True when there were keys."""
    anim = ob.animation_data
    curves = [fc for fc in compat.action_fcurves(anim) if fc.data_path == DATA_PATH]
    if not curves:
        return False
    action = anim.action
    for fc in curves:
        compat.remove_fcurve(ob, fc)
    ob.delta_location = (0.0, 0.0, 0.0)
    if action.get(_CREATED) and not compat.action_fcurves(anim):
        anim.action = None
        if action.users == 0:
            bpy.data.actions.remove(action)
    return True
