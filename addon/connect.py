"""Connect Selected: constraint objects between the selected rigid bodies in one go — a chain
(each to its nearest not yet joined, from the active one), a star (each to the active one) or
a wall (every pair that nearly touches) — as Blender's own Connect for rigid bodies."""
from __future__ import annotations

import bpy
import numpy as np
from bpy.props import EnumProperty, FloatProperty

from .rigid_props import CONSTRAINT_TYPE_ITEMS, POINT_TYPES

# the joints that join two rigid bodies (not those holding an emitter's particles)
JOINT_TYPE_ITEMS = [item for item in CONSTRAINT_TYPE_ITEMS if item[0] not in POINT_TYPES]

COLLECTION = "PhysAnim Constraints"
PATTERN_ITEMS = [
    ('CHAIN', "Chain", "From the active object, each to the nearest not yet joined (a rope, a "
     "chain, a bridge's planks)"),
    ('ACTIVE', "To Active", "Each selected object to the active one"),
    ('NEIGHBOURS', "Neighbours", "Every pair whose bounding boxes come within the distance (a "
     "wall, a pile held together)"),
]
PIVOT_ITEMS = [
    ('CENTER', "Center", "Midway between the two objects' origins"),
    ('TOUCH', "Touching", "Midway between the two objects' bounding boxes where they are "
     "closest"),
    ('FIRST', "First", "At the first object's origin"),
]


def world_boxes(objects) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (n, 3) world-axis bounds of the objects' bounding boxes."""
    lo, hi = [], []
    for ob in objects:
        m = np.array(ob.matrix_world)
        corners = np.array([list(c) + [1.0] for c in ob.bound_box]) @ m.T
        lo.append(corners[:, :3].min(axis=0))
        hi.append(corners[:, :3].max(axis=0))
    return np.array(lo).reshape(-1, 3), np.array(hi).reshape(-1, 3)


def pairs(objects: list, active, pattern: str, distance: float) -> list[tuple[int, int]]:
    """Index pairs of ``objects`` to join."""
    n = len(objects)
    origins = np.array([list(ob.matrix_world.translation) for ob in objects]).reshape(-1, 3)
    start = objects.index(active) if active in objects else 0
    if pattern == 'ACTIVE':
        return [(start, i) for i in range(n) if i != start]
    if pattern == 'CHAIN':
        order, left = [start], set(range(n)) - {start}
        while left:
            here = origins[order[-1]]
            nxt = min(left, key=lambda i: (np.linalg.norm(origins[i] - here), i))
            order.append(nxt)
            left.remove(nxt)
        return list(zip(order[:-1], order[1:]))
    lo, hi = world_boxes(objects)
    gap = np.maximum(0.0, np.maximum(lo[:, None] - hi[None], lo[None] - hi[:, None])).max(axis=2)
    return [(i, j) for i in range(n) for j in range(i + 1, n) if gap[i, j] <= distance]


def pivot(a, b, how: str) -> np.ndarray:
    """Where the joint between objects a and b goes."""
    pa, pb = np.array(a.matrix_world.translation), np.array(b.matrix_world.translation)
    if how == 'FIRST':
        return pa
    if how == 'CENTER':
        return 0.5 * (pa + pb)
    lo, hi = world_boxes([a, b])
    # per axis, the middle of where the boxes overlap, or of the gap between them
    return 0.5 * (lo.max(axis=0) + hi.min(axis=0))


class PHYSANIM_OT_connect(bpy.types.Operator):
    """Join the selected rigid bodies with constraint objects (Empties in the "PhysAnim
    Constraints" collection)"""

    bl_idname = "physanim.connect"
    bl_label = "Connect Selected"
    bl_options = {'REGISTER', 'UNDO'}

    type: EnumProperty(name="Type", items=JOINT_TYPE_ITEMS, default='BALL')
    pattern: EnumProperty(name="Pattern", items=PATTERN_ITEMS, default='CHAIN')
    pivot: EnumProperty(name="Pivot", items=PIVOT_ITEMS, default='TOUCH')
    distance: FloatProperty(name="Distance", min=0.0, max=100.0, default=0.01, unit='LENGTH',
                            description="Neighbours: how far apart two objects' bounding "
                                        "boxes may be and still be joined")

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    def execute(self, context):
        bodies = sorted((ob for ob in context.selected_objects
                         if ob.physanim.rigid_body.enabled), key=lambda o: o.name)
        if len(bodies) < 2:
            self.report({'ERROR'}, "Select at least two rigid bodies to connect")
            return {'CANCELLED'}
        collection = bpy.data.collections.get(COLLECTION)
        if collection is None:
            collection = bpy.data.collections.new(COLLECTION)
            context.scene.collection.children.link(collection)
        made = 0
        for i, j in pairs(bodies, context.active_object, self.pattern, self.distance):
            a, b = bodies[i], bodies[j]
            empty = bpy.data.objects.new(f"Constraint.{a.name}.{b.name}", None)
            empty.empty_display_type = 'ARROWS'
            empty.empty_display_size = 0.25
            empty.location = pivot(a, b, self.pivot)
            collection.objects.link(empty)
            c = empty.physanim.constraint
            c.enabled, c.type, c.object1, c.object2 = True, self.type, a, b
            made += 1
        self.report({'INFO'}, f"{made} constraint(s) made")
        return {'FINISHED'}


CLASSES = (PHYSANIM_OT_connect,)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister() -> None:
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
