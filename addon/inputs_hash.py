"""Is a bake outdated? A digest of what a bake depends on that does not change with the current
frame: property values that are not animated, and the keyframes/drivers of those that are. The
bake stores it with the cache; the panels compare it with the scene's."""
from __future__ import annotations

import hashlib
import json

import bpy
import numpy as np

from . import compat, convert
from .roles import Roles, attachments, emitter_chain, gather, is_attachment, made_by_bake

def _animated_paths(id_data) -> set[str]:
    ad = getattr(id_data, "animation_data", None)
    if ad is None:
        return set()
    paths = {fc.data_path for fc in ad.drivers}
    if ad.action is not None:
        paths |= {fc.data_path for fc in _fcurves(ad)}
    return paths


def _rna_dump(pg, prefix: str = "", animated: frozenset = frozenset()) -> dict:
    out = {}
    for prop in pg.bl_rna.properties:
        key = prop.identifier
        if key in ("rna_type", "result", "bake_hash", "bake_info", "enabled", "broken_frame",
                   *RIGID_BAKE_PROPS):
            continue
        path = f"{prefix}{key}"
        if path in animated:
            continue  # its keys are hashed instead: the current value depends on the frame
        value = getattr(pg, key)
        if prop.type == 'POINTER':
            out[key] = value.name if isinstance(value, bpy.types.ID) else (
                _rna_dump(value, path + ".", animated) if value is not None else None)
        elif prop.type == 'COLLECTION':
            out[key] = [_rna_dump(item, f"{path}[{i}].", animated) for i, item in enumerate(value)]
        elif getattr(prop, "is_array", False):
            out[key] = [round(float(v), 9) for v in value]
        else:
            out[key] = value if not isinstance(value, float) else round(value, 9)
    return out


def _animation_dump(id_data) -> list:
    ad = getattr(id_data, "animation_data", None)
    if ad is None:
        return []
    keys = []
    curves = list(_fcurves(ad)) if ad.action is not None else []
    for fc in curves:
        co = np.empty(len(fc.keyframe_points) * 2, np.float32)
        fc.keyframe_points.foreach_get("co", co)
        keys.append((fc.data_path, fc.array_index, hashlib.sha1(co.tobytes()).hexdigest()))
    for fc in ad.drivers:
        keys.append((fc.data_path, fc.array_index, fc.driver.expression))
    return sorted(keys)


def _fcurves(ad):
    return compat.action_fcurves(ad)


def _input_modifiers(ob) -> list:
    """Modifiers that feed a bake: not the bake's own, and not those after the spring-mesh cache
    (they deform the played-back result)."""
    out = []
    for m in ob.modifiers:
        if m.type == 'MESH_CACHE' and m.name == "physanim":
            break
        if not made_by_bake(m):
            out.append((m.type, m.name, m.show_render, m.show_viewport))
    return out


RIGID_BAKE_PROPS = ("previous_action", "previous_slot", "previous_rotation_mode",
                    "previous_basis", "previous_pose", "baked_action")  # what a bake sets: not inputs
TRANSFORM_PATHS = ("location", "rotation_euler", "rotation_quaternion", "rotation_axis_angle",
                   "scale", "delta_location", "delta_rotation_euler", "delta_scale")


def _own_motion(ob) -> dict:
    """A rigid body's own animation and pose — before its bake's keys, which are outputs: the
    action and pose the bake set aside when it has keyed the object, else the current ones."""
    p = ob.physanim.rigid_body
    if p.baked_action is not None:
        action, slot, mode = p.previous_action, p.previous_slot, p.previous_rotation_mode
        basis = list(p.previous_basis)
    else:
        ad = ob.animation_data
        action = ad.action if ad is not None else None
        slot = getattr(ad, "action_slot", None) if ad is not None else None
        slot, mode = (slot.identifier if slot is not None else ""), ob.rotation_mode
        basis = [v for row in ob.matrix_basis for v in row]
    keys = []
    for fc in compat.curves_of(action, slot):
        co = np.empty(len(fc.keyframe_points) * 2, np.float32)
        fc.keyframe_points.foreach_get("co", co)
        keys.append((fc.data_path, fc.array_index, hashlib.sha1(co.tobytes()).hexdigest()))
    moving = any(path in TRANSFORM_PATHS for path, _, _ in keys)
    return {"keys": sorted(keys), "mode": mode,
            "basis": None if moving else [round(float(v), 6) for v in basis]}


def _object_record(ob, role: str | None) -> dict:
    """Everything about one object a bake reads, independent of the current frame."""
    if role == "rigid_body":
        return _rigid_record(ob)
    animated = frozenset(_animated_paths(ob))
    record = {"name": ob.name, "type": ob.type, "anim": _animation_dump(ob),
              "parent": _object_record(ob.parent, None) if ob.parent else None,
              "parent_type": ob.parent_type, "parent_bone": ob.parent_bone,
              "constraints": [(c.type, c.name, round(c.influence, 7), c.mute)
                              for c in ob.constraints],
              "modifiers": _input_modifiers(ob)}
    for channel in TRANSFORM_PATHS:
        if channel not in animated:
            record[channel] = [round(float(v), 7) for v in getattr(ob, channel)]
    record["rotation_mode"] = ob.rotation_mode
    if role is not None:
        record["props"] = _rna_dump(getattr(ob.physanim, role), f"physanim.{role}.", animated)
    if ob.type == 'CURVE' and role is not None:  # a wire's shape
        record["curve"] = _curve_record(ob.data)
    if ob.type == 'MESH' and role is not None:
        co = np.empty(len(ob.data.vertices) * 3, np.float32)
        ob.data.vertices.foreach_get("co", co)
        record["mesh"] = (hashlib.sha1(co.tobytes()).hexdigest(), len(ob.data.polygons),
                          _animation_dump(ob.data.shape_keys) if ob.data.shape_keys else [])
    return record


def _curve_record(curve) -> list:
    """A curve's splines: type, resolution, cyclic and every control point (and handle), and
    its animation (shape keys)."""
    out = [curve.resolution_u, _animation_dump(curve.shape_keys) if curve.shape_keys else []]
    for spline in curve.splines:
        arrays = []
        for points, keys in ((spline.points, ("co",)),
                             (spline.bezier_points, ("co", "handle_left", "handle_right"))):
            for key in keys:
                width = 4 if points == spline.points else 3
                co = np.empty(len(points) * width, np.float32)
                points.foreach_get(key, co)
                arrays.append(hashlib.sha1(co.tobytes()).hexdigest())
        out.append((spline.type, spline.resolution_u, spline.use_cyclic_u, arrays))
    return out


def _rigid_record(ob) -> dict:
    """A rigid body's record: its own motion instead of its channels (its keys are outputs)."""
    co = np.empty(len(ob.data.vertices) * 3, np.float32) if ob.type == 'MESH' else np.zeros(0)
    if ob.type == 'MESH':
        ob.data.vertices.foreach_get("co", co)
    return {"name": ob.name, "type": ob.type, "own": _own_motion(ob),
            "parent": _object_record(ob.parent, None) if ob.parent else None,
            "parent_type": ob.parent_type, "modifiers": _input_modifiers(ob),
            "props": _rna_dump(ob.physanim.rigid_body, "physanim.rigid_body."),
            "mesh": hashlib.sha1(co.tobytes()).hexdigest()}


def inputs_hash(scene, ob, role: str, roles: Roles | None = None) -> str:
    """Digest of everything the bake of ``ob`` in ``role`` ("emitter" or "spring_mesh") depends
    on: scene settings, every collider and force, the object (with its parent chain), for
    sub-emitters their parent emitter, for spring meshes their virtual-spring targets."""
    roles = roles if roles is not None else gather(scene)
    h = hashlib.sha256()
    settings = _rna_dump(scene.physanim)
    settings.update(fps=convert.fps(scene), gravity=convert.gravity(scene),
                    anim=_animation_dump(scene), role=role)
    h.update(json.dumps(settings, sort_keys=True).encode())
    records = []
    if role == "emitter":
        records += [_object_record(o, "emitter") for o in emitter_chain(ob)]
        held = [c for o in emitter_chain(ob) for c in attachments(scene, o, "particles")]
        records += [_object_record(c, "constraint") for c in held]  # what holds its particles
        targets = {c.physanim.constraint.object2.name: c.physanim.constraint.object2
                   for c in held if c.physanim.constraint.object2 is not None}  # ties' objects
        records += [_object_record(targets[name], None) for name in sorted(targets)]
    else:
        records.append(_object_record(ob, role))
        targets = {v.target.name: v.target for v in ob.physanim.spring_mesh.virtual_springs
                   if v.target is not None}
        held = attachments(scene, ob)  # the objects its vertices hang on, and how
        records += [_object_record(c, "constraint") for c in held]
        targets.update({c.physanim.constraint.object2.name: c.physanim.constraint.object2
                        for c in held if c.physanim.constraint.object2 is not None})
        records += [_object_record(targets[name], None) for name in sorted(targets)]
    records += [_object_record(o, "collider") for o in roles.colliders]
    records += [_object_record(o, "force") for o in roles.forces]
    h.update(json.dumps(records, sort_keys=True).encode())
    return h.hexdigest()


def emitter_hash(scene, emitter, roles: Roles | None = None) -> str:
    return inputs_hash(scene, emitter, "emitter", roles)


def scene_hash(hashes: list[str]) -> str:
    return hashlib.sha256("".join(sorted(hashes)).encode()).hexdigest()


def rigid_hash(scene, objects: list, roles: Roles | None = None) -> str:
    """Digest of what the rigid bodies' bake depends on: scene settings, every rigid body, every
    collider, every constraint (they all push each other, so one hash covers them all)."""
    roles = roles if roles is not None else gather(scene)
    h = hashlib.sha256()
    settings = _rna_dump(scene.physanim)
    settings.update(fps=convert.fps(scene), gravity=convert.gravity(scene),
                    anim=_animation_dump(scene), role="rigid_body")
    records = [_object_record(o, "rigid_body") for o in objects]
    records += [_object_record(o.physanim.rigid_body.target, None) for o in objects
                if o.physanim.rigid_body.target is not None]  # where a body aims
    records += [_object_record(o, "collider") for o in roles.colliders]
    names = {o.name for o in objects}
    for c in roles.constraints:  # the joints, and the animated objects holding them
        records.append(_object_record(c, "constraint"))
        holder = c.physanim.constraint.object2
        if holder is not None and holder.name not in names:
            records.append(_object_record(holder, None))
        if is_attachment(c):  # a spring mesh hangs on a body: it pulls it
            records.append(_object_record(c.physanim.constraint.object1, "spring_mesh"))
    h.update(json.dumps([settings, records], sort_keys=True).encode())
    return h.hexdigest()


def follow_hash(scene, ob, roles: Roles | None = None) -> str:
    """Digest of what a follower's bake depends on: its spring, its own motion (not the Delta
    Location keys the bake writes), the frame range and rate, and its parent — through the
    rigid bodies' hash when the parent is one (its motion is their bake's)."""
    roles = roles if roles is not None else gather(scene)
    own = [k for k in _animation_dump(ob) if k[0] != "delta_location"]
    record = {"follow": _rna_dump(ob.physanim.follow), "own": own,
              "location": [round(float(v), 7) for v in ob.location],
              "parent_inverse": [round(float(v), 7) for row in ob.matrix_parent_inverse
                                 for v in row],
              "frames": (scene.physanim.frame_start, scene.physanim.frame_end),
              "fps": convert.fps(scene)}
    parent = ob.parent
    if parent is not None and parent.physanim.rigid_body.enabled:
        record["parent"] = rigid_hash(scene, roles.rigid_bodies, roles)
    elif parent is not None:
        record["parent"] = _object_record(parent, None)
    return hashlib.sha256(json.dumps(record, sort_keys=True).encode()).hexdigest()
