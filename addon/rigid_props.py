"""Blender properties of the rigid-body roles: ``object.physanim.rigid_body`` and
``object.physanim.constraint`` (registered by :mod:`.props`)."""
from __future__ import annotations

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty,
                       IntProperty, PointerProperty, StringProperty)

from .props_base import STATIC, recovery_property, squash_property

RIGID_SHAPE_ITEMS = [
    ('AUTO', "Automatic", "What you see: a mesh that is exactly a box collides as a box, one "
     "whose vertices all lie on a sphere as a sphere, a closed concave one (a ring, a cup) as "
     "itself (Mesh), any other as its convex hull"),
    ('BOX', "Box", "The mesh's bounding box (in the object's axes)"),
    ('SPHERE', "Sphere", "A sphere around the mesh's bounding box centre"),
    ('CAPSULE', "Capsule", "A capsule along the object's local Z axis around the mesh"),
    ('CONVEX_HULL', "Convex Hull", "The convex hull of the mesh's vertices"),
    ('MESH', "Mesh", "The closed mesh itself, concave parts included (rings fall over pegs); "
     "its vertices touch what they meet. Slower than the convex shapes"),
]


class PHYSANIM_PG_rigid_body(bpy.types.PropertyGroup):
    enabled: BoolProperty(name="Rigid Body", options=STATIC,
                          description="Simulate this object as a rigid body")
    shape: EnumProperty(name="Shape", items=RIGID_SHAPE_ITEMS, default='AUTO', options=STATIC)
    mass: FloatProperty(name="Mass", min=1.0e-6, max=1.0e9, default=1.0, unit='MASS',
                        options=STATIC, description="Total mass, kg")
    use_density: BoolProperty(name="Use Density", options=STATIC,
                              description="Mass from the shape's volume times the density")
    density: FloatProperty(name="Density", min=1.0e-6, max=1.0e6, default=1000.0,
                           options=STATIC, description="kg/m³ (water: 1000, wood: 500-900, "
                                                       "steel: 7850)")
    restitution: FloatProperty(name="Restitution", min=0.0, max=1.0, default=0.0,
                               subtype='FACTOR', options=STATIC,
                               description="Bounciness, multiplied by the other side's (a "
                                           "collider's or body's); impacts slower than 1 m/s "
                                           "never bounce")
    friction: FloatProperty(name="Friction", min=0.0, max=100.0, soft_max=2.0, default=0.5,
                            options=STATIC, description="Coulomb friction coefficient "
                                                        "(combined with the other side's)")
    initial_velocity: FloatVectorProperty(name="Initial Velocity", size=3, unit='VELOCITY',
                                          min=-1.0e5, max=1.0e5, options=STATIC,
                                          description="World velocity at the start, m/s")
    initial_angular_velocity: FloatVectorProperty(
        name="Initial Angular Velocity", size=3, min=-1.0e4, max=1.0e4, options=STATIC,
        description="World angular velocity at the start, rad/s")
    kinematic: BoolProperty(name="Animated",
                            description="Follows its own animation and pushes other bodies "
                                        "(is not pushed). Keyframe it off to let the body go "
                                        "with the velocity its animation gives it (a throw), "
                                        "on to have it join its animation")
    linear_damping: FloatProperty(name="Damping", min=0.0, max=1.0e3, soft_max=1.0,
                                  default=0.04, options=STATIC,
                                  description="Fraction of linear velocity lost per second")
    angular_damping: FloatProperty(name="Angular Damping", min=0.0, max=1.0e3, soft_max=1.0,
                                   default=0.1, options=STATIC,
                                   description="Fraction of angular velocity lost per second")
    use_custom_com: BoolProperty(name="Custom Center of Mass", options=STATIC)
    com: FloatVectorProperty(name="Center of Mass", size=3, unit='LENGTH', min=-1.0e5,
                             max=1.0e5, options=STATIC,
                             description="From the object's origin, in its axes (scaled), m")
    use_custom_inertia: BoolProperty(name="Custom Inertia", options=STATIC)
    inertia: FloatVectorProperty(name="Inertia", size=3, min=1.0e-12, max=1.0e12,
                                 default=(1.0, 1.0, 1.0), options=STATIC,
                                 description="Principal moments about the object's X, Y, Z "
                                             "axes through the center of mass, kg m²")
    target: PointerProperty(name="Target", type=bpy.types.Object,
                            description="Hit the mark: the bake sets Initial Velocity so the "
                                        "body's centre reaches this object's origin at Target "
                                        "Frame (solved on the simulation itself)")
    target_frame: IntProperty(name="Target Frame", default=48, options=STATIC,
                              description="The frame the body arrives at its target")
    squash: squash_property("Keys scale so the body stretches along its velocity in flight and "
                            "squashes on impact, its volume kept (0: off); the simulation itself "
                            "stays rigid")
    squash_recovery: recovery_property()
    hang_time: FloatProperty(
        name="Hang Time (Slow In, Slow Out)", min=0.0, max=0.95, soft_max=0.8, default=0.0,
        options=STATIC,
        description="Eases the body's clock around the apex of each jump: it lingers there at "
                    "(1 - Hang Time) of its speed and leaves and lands faster, on the frames "
                    "and along the path simulated (0: off); drawn on the keys, the simulation "
                    "stays as it was")
    exaggeration: FloatProperty(
        name="Bounce Exaggeration", min=0.05, max=10.0, soft_max=3.0, default=1.0,
        options=STATIC,
        description="Each flight's height above the line from take-off to landing, times this "
                    "(1: as simulated); take-off and landing keep their frames and places")
    previous_action: PointerProperty(type=bpy.types.Action, options={'HIDDEN'},
                                     description="The animation the bake set aside")
    previous_slot: StringProperty(options={'HIDDEN'})
    previous_rotation_mode: StringProperty(options={'HIDDEN'})
    previous_basis: FloatVectorProperty(size=16, options={'HIDDEN'})
    # location (3), Euler (3), quaternion (4), axis angle (4) and scale (3) as they were: given
    # back exactly (through a matrix they would be rounded)
    previous_pose: FloatVectorProperty(size=17, options={'HIDDEN'})
    baked_action: PointerProperty(type=bpy.types.Action, options={'HIDDEN'})
    bake_hash: StringProperty(name="Bake Hash", options={'HIDDEN'})


CONSTRAINT_TYPE_ITEMS = [
    ('FIXED', "Fixed", "The two move as one (welded)"),
    ('BALL', "Ball", "Held at the pivot (this object's origin), free to turn about it"),
    ('HINGE', "Hinge", "Turns about this object's Z axis through its origin only (a door)"),
    ('SLIDER', "Slider", "Slides along this object's Z axis only, without turning (a drawer)"),
    ('CONE_TWIST', "Cone Twist", "Held at the pivot; this object's Z axis on the second object "
     "stays within a cone around it on the first (a shoulder, a rope's link)"),
    ('SPRING', "Spring", "Held at the pivot by a damped spring of zero rest length (its "
     "Stiffness and Damping): a bungee, free to turn"),
    ('ON_PLANE', "On Plane", "An emitter's particles stay on the plane through this object's "
     "origin, normal to its Z axis (they slide on it)"),
    ('ON_SPHERE', "On Sphere", "An emitter's particles stay at Radius from this object's "
     "origin (on a sphere; each a pendulum on a rod to it)"),
    ('ON_CIRCLE', "On Wire", "An emitter's particles run along a wire (beads on it): this "
     "object's curve when it is a Curve object, else the circle of Radius about its origin, "
     "in its XY plane"),
    ('TIE', "Tie", "An emitter's particles within Reach of this object's origin are tied where "
     "they are to the Second object (a rope's end to a hook; a rigid body swings on the rope "
     "and pulls it), or to the world"),
]


POINT_TYPES = ('ON_PLANE', 'ON_SPHERE', 'ON_CIRCLE', 'TIE')  # for an emitter's particles


def _is_rigid_body_or_spring_mesh(self, ob) -> bool:
    p = ob.physanim
    return p.rigid_body.enabled or p.spring_mesh.enabled or p.emitter.enabled


class PHYSANIM_PG_constraint(bpy.types.PropertyGroup):
    """A joint between two rigid bodies, or a rigid body and another object (which holds it
    where it is animated) or the world, placed by this object's origin and axes at the first
    frame (as Blender's rigid body constraints). With a spring mesh as First, its vertex group
    is held on the Second object (an attachment: a rigid body moves with the mesh)."""

    enabled: BoolProperty(name="Constraint", options=STATIC,
                          description="Join two objects at this object's origin")
    type: EnumProperty(name="Type", items=CONSTRAINT_TYPE_ITEMS, default='BALL', options=STATIC)
    object1: PointerProperty(name="First", type=bpy.types.Object,
                             poll=_is_rigid_body_or_spring_mesh, options=STATIC,
                             description="What is held: a rigid body, a spring mesh (its "
                                         "vertex group) or an emitter (its particles: On "
                                         "Plane, On Sphere, On Wire)")
    group1: StringProperty(name="Vertex Group", options=STATIC,
                           description="The First spring mesh's vertices held on the Second "
                                       "object where they are at the start (empty: all of "
                                       "them); a rigid body they hang on moves with the mesh")
    object2: PointerProperty(name="Second", type=bpy.types.Object, options=STATIC,
                             description="What holds it: a rigid body, any other object "
                                         "(which holds it where it is animated to be), or "
                                         "nothing (the world)")
    use_limits: BoolProperty(name="Limits",
                             description="Limit the hinge's angle, the slider's distance or "
                                         "the cone twist's twist")
    angle_lower: FloatProperty(name="Lower", min=-3.14159, max=3.14159, default=-0.785398,
                               unit='ROTATION',
                               description="Smallest angle of the first object about Z "
                                           "(hinge) or twist (cone twist)")
    angle_upper: FloatProperty(name="Upper", min=-3.14159, max=3.14159, default=0.785398,
                               unit='ROTATION',
                               description="Largest angle")
    distance_lower: FloatProperty(name="Lower", min=-1.0e5, max=1.0e5, default=-1.0,
                                  unit='LENGTH',
                                  description="Smallest distance along Z (slider)")
    distance_upper: FloatProperty(name="Upper", min=-1.0e5, max=1.0e5, default=1.0,
                                  unit='LENGTH',
                                  description="Largest distance along Z (slider)")
    cone_angle: FloatProperty(name="Cone", min=0.001, max=3.1, default=0.785398,
                              unit='ROTATION',
                              description="Largest angle between the two objects' Z axes")
    use_motor: BoolProperty(name="Motor",
                            description="Drive the hinge or slider at a speed")
    motor_velocity: FloatProperty(name="Speed", min=-1.0e4, max=1.0e4, default=1.0,
                                  description="rad/s (hinge) or m/s (slider) of the first "
                                              "object relative to the second")
    motor_max: FloatProperty(name="Max Torque / Force", min=0.0, max=1.0e9, default=10.0,
                             description="The motor's strength: N m (hinge) or N (slider)")
    use_spring: BoolProperty(name="Spring",
                             description="A damped spring pulls the hinge or slider back to "
                                         "where it started")
    spring_stiffness: FloatProperty(name="Stiffness", min=0.0, max=1.0e9, default=10.0,
                                    description="N m/rad (hinge) or N/m (slider, spring)")
    spring_damping: FloatProperty(name="Damping", min=0.0, max=1.0e9, default=0.5,
                                  description="N m s/rad (hinge) or N s/m (slider, spring)")
    use_breaking: BoolProperty(name="Breakable",
                               description="Let go when the force it carries exceeds a "
                                           "threshold")
    break_force: FloatProperty(name="Breaking Force", min=1.0e-6, max=1.0e12, default=100.0,
                               unit='NONE', description="Newtons")
    radius: FloatProperty(name="Radius", min=1e-6, max=1.0e5, default=1.0, unit='LENGTH',
                          description="The sphere's or the circular wire's radius (On Sphere, "
                                      "On Wire on an object that is not a curve)")
    reach: FloatProperty(name="Reach", min=1e-6, max=1.0e5, default=0.05, unit='LENGTH',
                         description="Tie: the emitter's particles this close to this object's "
                                     "origin when first seen are tied (a rope's end: the "
                                     "particle born there)")
    disable_collisions: BoolProperty(name="Disable Collisions", default=True, options=STATIC,
                                     description="The two objects do not collide with each "
                                                 "other")
    broken_frame: IntProperty(name="Broke at Frame", default=-1, options={'HIDDEN'},
                              description="Set by the bake: the frame it broke at (-1: held)")
