"""Which objects take part in a bake and in what role: the scene's role objects, the chain of
emitters a sub-emitter depends on, and what each constraint object holds."""
from __future__ import annotations

from dataclasses import dataclass, field

from ..core.errors import PhysanimError
from .rigid_props import CONSTRAINT_TYPE_ITEMS, POINT_TYPES


@dataclass
class Roles:
    """Objects taking part in a bake, in a stable (name) order."""

    emitters: list = field(default_factory=list)
    colliders: list = field(default_factory=list)
    forces: list = field(default_factory=list)
    spring_meshes: list = field(default_factory=list)
    rigid_bodies: list = field(default_factory=list)
    constraints: list = field(default_factory=list)  # every enabled constraint object
    followers: list = field(default_factory=list)  # Follow-Through objects

    def __bool__(self) -> bool:
        """Whether anything bakes."""
        return bool(self.emitters or self.spring_meshes or self.rigid_bodies or self.followers)

    @property
    def joints(self) -> list:
        """The constraints joining rigid bodies (baked with them): not those holding a spring
        mesh's vertices or an emitter's particles."""
        return [c for c in self.constraints if holds(c) == "joint"] if self.rigid_bodies else []


def holds(constraint) -> str:
    """What a constraint object holds, so which bake takes it: "particles" (its First's
    particles: the On Plane / On Sphere / On Wire types, or any type on a plain emitter, which
    that bake then refuses), "attachment" (its First spring mesh's vertices) or "joint" (a
    rigid body). An object in two roles is held as its type says."""
    p = constraint.physanim.constraint
    first = p.object1
    if first is None:
        return "joint"
    roles = first.physanim
    if roles.emitter.enabled and (p.type in POINT_TYPES or not (
            roles.spring_mesh.enabled or roles.rigid_body.enabled)):
        return "particles"
    return "attachment" if roles.spring_mesh.enabled else "joint"


def is_attachment(constraint) -> bool:
    """Whether a constraint object holds a spring mesh's vertices (baked with the mesh)."""
    return holds(constraint) == "attachment"


def attachments(scene, ob, what: str = "attachment") -> list:
    """The constraint objects of ``scene`` holding ``ob`` as ``what`` (:func:`holds`), by
    name."""
    return sorted((c for c in scene.objects if c.physanim.constraint.enabled
                   and c.physanim.constraint.object1 == ob and holds(c) == what),
                  key=lambda c: c.name)


def type_name(identifier: str) -> str:
    """A constraint type as the panel names it (``ON_CIRCLE`` -> "On Wire")."""
    return next(name for key, name, _ in CONSTRAINT_TYPE_ITEMS if key == identifier)


def object_kind(ob) -> str:
    """What an object is, as the interface names its type, with its article ("an Empty", "a
    Curve"): for messages."""
    name = ob.bl_rna.properties["type"].enum_items[ob.type].name
    return f"{'an' if name[:1].upper() in 'AEIOU' else 'a'} {name}"


def gather(scene, only: set[str] | None = None) -> Roles:
    """Objects of ``scene`` with a physanim role enabled.

    Args:
        only: names of emitters and spring meshes to bake (None = all). The parents of selected
            sub-emitters are added, since their particles' deaths drive the sub-emitter.
    """
    objects = sorted(scene.objects, key=lambda o: o.name)
    emitters = [o for o in objects if o.physanim.emitter.enabled]
    meshes = [o for o in objects if o.physanim.spring_mesh.enabled]
    rigid = [o for o in objects if o.physanim.rigid_body.enabled]
    followers = [o for o in objects if o.physanim.follow.enabled]
    if only is not None:
        unknown = only - {o.name for o in emitters + meshes + rigid + followers}
        if unknown:
            raise PhysanimError(f"not an emitter, spring mesh, rigid body or follower in scene "
                                f"\"{scene.name}\": {', '.join(sorted(unknown))}")
        meshes = [o for o in meshes if o.name in only]
        chosen = {a.name for o in emitters if o.name in only for a in emitter_chain(o)}
        emitters = [o for o in emitters if o.name in chosen]
        # rigid bodies push each other: choosing one bakes them all
        rigid = rigid if any(o.name in only for o in rigid) else []
        followers = [o for o in followers if o.name in only]
    return Roles(emitters,
                 [o for o in objects if o.physanim.collider.enabled],
                 [o for o in objects if o.physanim.force.enabled], meshes, rigid,
                 [o for o in objects if o.physanim.constraint.enabled], followers)


def check_exclusive(roles: Roles) -> None:
    """Roles one object cannot have together, an error naming it otherwise: a spring mesh and
    a rigid body (the keys would move the mesh its cache already moves); a spring mesh and a
    collider (the other systems would meet its undeformed shape, not the simulated one); a
    rigid body that is not animated and a collider (the body is already the other systems'
    collider: they would also meet a still copy of it where it starts)."""
    rigid = {o.name: o for o in roles.rigid_bodies}
    colliders = {o.name for o in roles.colliders}
    for ob in roles.spring_meshes:
        if ob.name in rigid:
            _refuse(ob, "a spring mesh and a rigid body", "the rigid body's keys would move the "
                    "mesh its cache already moves")
        if ob.name in colliders:
            _refuse(ob, "a spring mesh and a collider", "particles and rigid bodies would meet "
                    "its undeformed shape, not the simulated one")
    for ob in rigid.values():
        if ob.name in colliders and not ob.physanim.rigid_body.kinematic:
            _refuse(ob, "a rigid body and a collider", "a rigid body is already a collider for "
                    "particles and spring meshes (they would also meet a still copy of it where "
                    "it starts)", "turn Collider off")


def _refuse(ob, both: str, why: str, fix: str = "turn one of them off") -> None:
    raise PhysanimError(f"it is both {both}: {why} — {fix}", obj=ob.name, kind="object")


def emitter_chain(ob) -> list:
    """``ob`` and the emitters above it: a sub-emitter (source Particle Deaths) bursts where its
    parent's particles die, so it depends on its parent, and on its parent's parent... The one
    walk up the chain (stops at the top or where the chain would loop)."""
    chain, names, current = [], set(), ob
    while current is not None and current.name not in names:
        chain.append(current)
        names.add(current.name)
        p = current.physanim.emitter
        current = p.parent if p.source == 'DEATHS' else None
    return chain


def made_by_bake(modifier) -> bool:
    """The bake's own output modifiers are not inputs of the bake."""
    return ((modifier.type == 'NODES' and modifier.name == "physanim_instances")
            or (modifier.type == 'MESH_CACHE' and modifier.name == "physanim"))
