"""Blender properties: ``scene.physanim`` and ``object.physanim.<role>`` (DESIGN.md names).

Every number has hard limits (``min``/``max``) that keep a bake finite; ``soft_*`` limits shape the
sliders. Values an animator may want to change over time are plain animatable properties: the
extract step samples them per frame.
"""
from __future__ import annotations

import math

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty,
                       FloatVectorProperty, IntProperty, PointerProperty, StringProperty)

from ..core.bounds import DEFAULT_POSITION, DEFAULT_SPEED
from ..core.controls.timing import MAX_SCALE, MIN_SCALE
from ..core.integrators import INTEGRATORS, SPRING_INTEGRATORS
from . import render_modes
from .compat import BLEND_RELATIVE_PATH_OPTIONS
from .props_base import STATIC, recovery_property, squash_property
from .render_modes import RENDER_ITEMS
from .rigid_props import PHYSANIM_PG_constraint, PHYSANIM_PG_rigid_body


INTEGRATOR_ITEMS = [
    ('EULER', "Euler", "Explicit Euler: first order, cheapest, least stable"),
    ('SYMPLECTIC_EULER', "Symplectic Euler", "Semi-implicit Euler: first order, keeps energy bounded"),
    ('MIDPOINT', "Midpoint", "Explicit midpoint: second order"),
    ('RK4', "RK4", "Classic Runge-Kutta: fourth order"),
    ('RK45', "RK45 (adaptive)", "Dormand-Prince 5(4): adapts its step to the tolerance"),
    ('IMPLICIT', "Implicit Euler", "Backward Euler: stable for stiff springs, damps motion"),
]
assert tuple(i[0] for i in INTEGRATOR_ITEMS) == INTEGRATORS

SOURCE_ITEMS = [
    ('ORIGIN', "Origin", "Emit from the object's origin"),
    ('VERTS', "Vertices", "Emit from the mesh's vertices"),
    ('FACES', "Faces", "Emit from the mesh's faces, evenly by area"),
    ('VOLUME', "Volume", "Emit from inside a closed mesh"),
    ('DEATHS', "Particle Deaths", "Burst where particles of the parent emitter die (sub-emitter)"),
]
DIRECTION_ITEMS = [
    ('NORMAL', "Normal", "Along the surface normal (origin: the axis; deaths: the dying particle's velocity)"),
    ('AXIS', "Axis", "Along an axis of the emitter object"),
    ('RANDOM', "Random", "In every direction"),
]
AXIS_ITEMS = [(a, a, f"Local {a} axis") for a in ("X", "Y", "Z", "-X", "-Y", "-Z")]
# Explicit numbers: files store the number, and 'POINTS' (0) and 'OBJECTS' (1) came first.
OUTPUT_ITEMS = [
    ('USD_POINTS', "Points", "A point cloud read from a USD file per frame by Blender's Mesh "
     "Sequence Cache modifier and instanced by Geometry Nodes (any count): plays and renders "
     "without PhysAnim, e.g. on a render farm; ids up to 16,777,216", 2),
    ('POINTS', "Points (Extension)", "A points mesh the extension loads from the bake's cache on "
     "every frame change, instanced by Geometry Nodes (any count): needs PhysAnim enabled "
     "wherever the scene plays or renders", 0),
    ('OBJECTS', "Objects", "One keyframed object per particle (small counts)", 1),
]
COLLIDER_SHAPE_ITEMS = [
    ('AUTO', "Automatic", "What you see: a mesh that is exactly a box or a filled rectangle "
     "collides as that analytic shape (fastest), any other or deforming mesh as itself (Mesh), "
     "an empty as the ground"),
    ('HALF_SPACE', "Ground", "Infinite plane through the origin along local XY; below it is solid"),
    ('PLANE', "Plane", "Two-sided square of Blender's plane primitive (local XY, -1..1)"),
    ('SPHERE', "Sphere", "Blender's UV/ico sphere primitive (radius 1, scaled by the object)"),
    ('BOX', "Box", "Blender's cube primitive (-1..1, scaled and rotated by the object)"),
    ('MESH', "Mesh", "The object's own (evaluated, deforming) mesh: any shape, open or closed"),
]
FORCE_ITEMS = [
    ('WIND', "Wind", "Push along the object's local Z axis, with optional gusts"),
    ('DRAG', "Drag", "Air resistance opposing each particle's velocity"),
    ('ATTRACTOR', "Attractor", "Pull towards (or push away from) the object's origin"),
    ('VORTEX', "Vortex", "Swirl around the object's local Z axis"),
    ('GRAVITY', "Mutual Gravity", "The particles attract each other (N-body gravity, Barnes-Hut)"),
    ('LENNARD_JONES', "Lennard-Jones", "The particles repel up close and attract a little "
                                       "farther: they clump into drops"),
    ('COULOMB', "Coulomb", "Charged particles push (like charges) or pull (unlike) each other"),
    ('COLLISIONS', "Particle Collisions", "The particles collide with each other as spheres "
                                          "of their size: they bounce, slide and heap up"),
]
INTERACTION_TYPES = ('GRAVITY', 'LENNARD_JONES', 'COULOMB', 'COLLISIONS')  # among particles


class PHYSANIM_PG_stop(bpy.types.PropertyGroup):
    """One stop of a curve over a particle's life (0 = birth, 1 = death)."""

    position: FloatProperty(name="Position", min=0.0, max=1.0, subtype='FACTOR',
                            description="Fraction of the particle's life", options=STATIC)
    color: FloatVectorProperty(name="Color", size=4, subtype='COLOR', min=0.0, max=1.0e3,
                               soft_max=1.0, default=(1.0, 1.0, 1.0, 1.0),
                               description="Color and alpha (alpha 0 = fully transparent)", options=STATIC)
    value: FloatProperty(name="Size", min=0.0, max=1.0e3, soft_max=2.0, default=1.0,
                         description="Size factor", options=STATIC)


def _on_render_changed(self, context):
    """A render setting changed: set up the baked result (if any) again, at once."""
    res = self.result
    if res is not None and res.name in bpy.data.objects and res.physanim.result.cache:
        render_modes.apply(res, self)


def _on_emitter_enabled(self, context):
    ob = self.id_data
    if not self.enabled:
        return
    if not len(self.color_stops):
        for pos, col in ((0.0, (1.0, 0.85, 0.3, 1.0)), (1.0, (0.9, 0.2, 0.05, 0.0))):
            stop = self.color_stops.add()
            stop.position, stop.color = pos, col
    if not len(self.size_stops):
        for pos, val in ((0.0, 1.0), (1.0, 0.5)):
            stop = self.size_stops.add()
            stop.position, stop.value = pos, val
    if ob.type == 'MESH' and len(ob.data.polygons) and self.source == 'ORIGIN':
        self.source = 'FACES'


class PHYSANIM_PG_emitter(bpy.types.PropertyGroup):
    enabled: BoolProperty(name="Emitter", update=_on_emitter_enabled,
                          description="Emit particles from this object")
    source: EnumProperty(name="Source", items=SOURCE_ITEMS, default='ORIGIN', options=STATIC)
    parent: PointerProperty(name="Parent Emitter", type=bpy.types.Object,
                            description="Emitter whose particle deaths spawn these particles")
    direction: EnumProperty(name="Direction", items=DIRECTION_ITEMS, default='NORMAL', options=STATIC)
    axis: EnumProperty(name="Axis", items=AXIS_ITEMS, default='Z', options=STATIC)
    rate: FloatProperty(name="Rate", min=0.0, max=1.0e6, soft_max=1000.0, default=20.0,
                        description="Mean births per frame (per death for sub-emitters)")
    rate_random: FloatProperty(name="Rate Random", min=0.0, max=1.0e6, soft_max=1000.0,
                               description="Births per frame = rate + Rand()*this, Rand in [-1, 1]")
    even_timing: BoolProperty(name="Even Timing", options=STATIC,
                              description="Births evenly spaced in time within each frame, not "
                                          "at random times: a moving emitter lays them out "
                                          "evenly (a rope of particles)")
    frame_start: IntProperty(name="Start", default=1, min=-1_000_000, max=1_000_000,
                             description="First frame whose births show (births of frame f happen "
                                         "during the frame before it)")
    frame_end: IntProperty(name="End", default=200, min=-1_000_000, max=1_000_000,
                           description="Last frame that gives births (inclusive: Start = End is "
                                       "a one-frame burst)")
    lifetime: FloatProperty(name="Lifetime", min=0.0, max=1.0e6, soft_max=1000.0, default=50.0,
                            description="Life span in frames")
    lifetime_random: FloatProperty(name="Lifetime Random", min=0.0, max=1.0e6, soft_max=1000.0,
                                   description="Life span +- uniform random, frames")
    speed: FloatProperty(name="Speed", min=0.0, max=1.0e5, soft_max=100.0, default=5.0,
                         unit='VELOCITY', description="Initial speed, m/s")
    speed_random: FloatProperty(name="Speed Random", min=0.0, max=1.0e5, soft_max=100.0,
                                unit='VELOCITY', description="Initial speed +- uniform random")
    spread: FloatProperty(name="Spread", min=0.0, max=math.pi, default=math.radians(15.0),
                          subtype='ANGLE', description="Half angle of the cone of directions")
    inherit_velocity: FloatProperty(name="Inherit Velocity", min=-100.0, max=100.0,
                                    soft_min=0.0, soft_max=1.0, default=0.0,
                                    description="Factor of the emitter's own velocity at the birth "
                                                "point (1 = thrown by the moving emitter)")
    launch_velocity: FloatVectorProperty(
        name="Launch Velocity", size=3, subtype='VELOCITY', unit='VELOCITY', min=-1.0e5,
        max=1.0e5, description="World velocity added to every particle at birth, m/s (the bake "
                               "solves it when the emitter has a Target)")
    target: PointerProperty(
        name="Target", type=bpy.types.Object,
        description="Hit the mark: the bake sets Launch Velocity so the centre of the "
                    "emitter's burst reaches this object's origin at Target Frame (solved on the "
                    "simulation itself)")
    target_frame: IntProperty(name="Target Frame", default=48, options=STATIC,
                              description="The frame the burst's centre arrives at its target")
    mass: FloatProperty(name="Mass", min=1.0e-6, max=1.0e6, default=0.1, unit='MASS')
    charge: FloatProperty(name="Charge", min=-1.0e6, max=1.0e6, soft_min=-10.0, soft_max=10.0,
                          description="Electric charge of each particle, C (Coulomb forces)")
    size: FloatProperty(name="Size", min=0.0, max=1.0e3, soft_max=1.0, default=0.05,
                        unit='LENGTH', description="Radius of a particle's instance")
    size_random: FloatProperty(name="Size Random", min=0.0, max=1.0e3, soft_max=1.0,
                               unit='LENGTH')
    seed: IntProperty(name="Seed", min=0, max=2**31 - 1, options=STATIC)
    color_stops: CollectionProperty(type=PHYSANIM_PG_stop)
    size_stops: CollectionProperty(type=PHYSANIM_PG_stop)
    squash: squash_property("Instances stretch along their velocity in flight and squash along "
                            "the contact normal on impact, their volume kept (0: off; replaces "
                            "Stretch); the particles' motion stays as simulated")
    squash_recovery: recovery_property()
    stretch: FloatProperty(name="Stretch", min=0.0, max=100.0, soft_max=1.0, default=0.0,
                           description="Shape from velocity: stretch along the velocity by "
                                       "1 + stretch*speed (s/m); 0 keeps particles round", options=STATIC)
    link: BoolProperty(name="Spring Chain", description="Join each particle to the previous one "
                                                       "with a damped spring", options=STATIC)
    link_stiffness: FloatProperty(name="Stiffness", min=0.0, max=1.0e7, soft_max=1000.0,
                                  default=50.0, description="Spring constant ks, N/m", options=STATIC)
    link_damping: FloatProperty(name="Damping", min=0.0, max=1.0e6, soft_max=10.0, default=0.5,
                                description="Spring damping kd, N s/m", options=STATIC)
    link_rest_length: FloatProperty(name="Rest Length", min=-1.0, max=1.0e4, default=-1.0,
                                    unit='LENGTH', description="Negative: distance at birth", options=STATIC)
    link_hard: BoolProperty(name="Rigid Links",
                            description="Links are rods of fixed length (hard constraints): a "
                                        "rope that never stretches; stiffness and damping unused",
                            options=STATIC)
    output: EnumProperty(name="Output", items=OUTPUT_ITEMS, default='USD_POINTS',
                         options=STATIC)
    instance_object: PointerProperty(name="Instance", type=bpy.types.Object,
                                     description="Object drawn at each particle (default: a "
                                                 "sphere that shows the particle colors)",
                                     update=_on_render_changed)
    # How the result renders: applied to a baked result at once, no re-bake (render_modes.py).
    render_as: EnumProperty(name="Render As", items=RENDER_ITEMS, default='OBJECT',
                            options=STATIC, update=_on_render_changed)
    sprite: PointerProperty(name="Sprite", type=bpy.types.Image, update=_on_render_changed,
                            description="Image on each billboard, tinted by the particle colour "
                                        "(default: a soft round dot)")
    glow_strength: FloatProperty(name="Glow Strength", min=0.0, max=1.0e4, soft_max=50.0,
                                 default=5.0, options=STATIC, update=_on_render_changed,
                                 description="Light emitted by each glowing point (W/m², "
                                             "times its colour's alpha)")
    streak_time: FloatProperty(name="Streak Time", min=0.0, max=10.0, soft_max=0.2,
                               default=0.04, unit='TIME_ABSOLUTE', options=STATIC,
                               update=_on_render_changed,
                               description="Each streak covers the path its particle travels "
                                           "in this time, s")
    blob_size: FloatProperty(name="Blob Size", min=0.01, max=100.0, soft_max=5.0, default=2.0,
                             options=STATIC, update=_on_render_changed,
                             description="Radius of each particle's blob, in particle sizes: "
                                         "blobs that overlap merge into one surface")
    blob_resolution: FloatProperty(name="Blob Resolution", min=1.0, max=64.0, default=6.0,
                                   options=STATIC, update=_on_render_changed,
                                   description="Voxels across one blob's radius: higher is "
                                               "smoother and slower")
    result: PointerProperty(name="Result", type=bpy.types.Object,
                            description="Points object made by the bake")


class PHYSANIM_PG_collider(bpy.types.PropertyGroup):
    enabled: BoolProperty(name="Collider", description="Particles bounce off this object")
    shape: EnumProperty(name="Shape", items=COLLIDER_SHAPE_ITEMS, default='AUTO', options=STATIC)
    restitution: FloatProperty(name="Restitution", min=0.0, max=1.0, default=0.5,
                               subtype='FACTOR', description="Normal speed kept after a bounce")
    friction: FloatProperty(name="Friction", min=0.0, max=100.0, soft_max=2.0, default=0.3,
                            description="Coulomb friction coefficient")
    thickness: FloatProperty(name="Thickness", min=0.0, max=100.0, soft_max=0.1, default=0.0,
                             unit='LENGTH', description="Grow the surface outwards by this much: "
                             "particles and cloth stop that far from it")


class PHYSANIM_PG_force(bpy.types.PropertyGroup):
    enabled: BoolProperty(name="Force", description="This object is a force field")
    type: EnumProperty(name="Type", items=FORCE_ITEMS, default='WIND', options=STATIC)
    strength: FloatProperty(name="Strength", min=-1.0e6, max=1.0e6, soft_min=-100.0,
                            soft_max=100.0, default=1.0, description="N per particle; a spring mesh feels it as one particle (shared "
                                        "by vertex mass), except wind: N/m² on its faces held still "
                                        "across it (faces moving with the air feel less, against it more)")
    noise: FloatProperty(name="Gusts", min=0.0, max=100.0, soft_max=2.0,
                         description="Strength of gusts relative to the steady wind")
    noise_scale: FloatProperty(name="Gust Size", min=1.0e-3, max=1.0e4, default=2.0,
                               unit='LENGTH', description="Size of a gust")
    noise_speed: FloatProperty(name="Gust Frequency", min=0.0, max=1.0e3, default=0.5,
                               description="How fast gusts change, 1/s")
    linear: FloatProperty(name="Linear", min=0.0, max=1.0e6, soft_max=10.0, default=0.05,
                          description="Drag proportional to speed, kg/s")
    quadratic: FloatProperty(name="Quadratic", min=0.0, max=1.0e6, soft_max=10.0,
                             description="Drag proportional to speed squared, kg/m")
    falloff: FloatProperty(name="Falloff", min=0.0, max=10.0, default=2.0,
                           description="Power of the distance in the attractor's falloff")
    min_distance: FloatProperty(name="Min Distance", min=1.0e-4, max=1.0e4, default=0.1,
                                unit='LENGTH')
    max_distance: FloatProperty(name="Max Distance", min=0.0, max=1.0e6, default=0.0,
                                unit='LENGTH', description="0 = unlimited")
    seed: IntProperty(name="Seed", min=0, max=2**31 - 1)
    # interactions among particles (types in INTERACTION_TYPES)
    affects: PointerProperty(name="Emitters", type=bpy.types.Collection,
                             description="The emitters whose particles interact, all with all "
                                         "(empty: every emitter's)")
    gravity_constant: FloatProperty(name="G", min=0.0, max=1.0e9, soft_max=100.0, default=1.0,
                                    description="Gravitational constant, m³/(kg s²), at the "
                                                "scene's scale (6.674e-11 is the real one)")
    theta: FloatProperty(name="Opening Angle", min=0.0, max=2.0, default=0.5,
                         description="Barnes-Hut accuracy: a far group of particles acts as one "
                                     "when its size is under this times its distance (0: exact, "
                                     "slow; 0.5: about 0.1 % error; 1: fast, a few %)")
    softening: FloatProperty(name="Softening", min=0.0, max=1.0e3, soft_max=1.0, default=0.05,
                             unit='LENGTH', description="Distance that keeps close passes "
                                                        "finite (Plummer)")
    sigma: FloatProperty(name="Sigma", min=1.0e-5, max=1.0e3, soft_max=1.0, default=0.1,
                         unit='LENGTH', description="Distance where the Lennard-Jones force "
                                                    "turns from push to pull is 1.12 times this")
    epsilon: FloatProperty(name="Epsilon", min=0.0, max=1.0e6, soft_max=1.0, default=0.002,
                           description="Depth of the Lennard-Jones well, J: how strongly "
                                       "particles cling (stronger needs more sub-steps: the "
                                       "bake says how many)")
    core_softness: FloatProperty(name="Core Softness", min=0.0, max=1.9, default=0.5,
                                 description="0: Lennard-Jones' hard core (particles never "
                                             "overlap; needs short steps); higher: a finite "
                                             "push up close, so fast or overlapping particles "
                                             "bounce off at ordinary sub-steps")
    cutoff: FloatProperty(name="Cutoff", min=1.0e-5, max=1.0e3, soft_max=10.0, default=0.25,
                          unit='LENGTH', description="No force beyond this distance")
    restitution: FloatProperty(name="Restitution", min=0.0, max=1.0, default=0.3,
                               description="Particle collisions: the share of the approach "
                                           "speed two particles part with")
    friction: FloatProperty(name="Friction", min=0.0, max=10.0, soft_max=2.0, default=0.5,
                            description="Particle collisions: Coulomb friction between "
                                        "particles (more: steeper heaps)")
    coulomb_constant: FloatProperty(name="k", min=0.0, max=1.0e12, soft_max=100.0, default=1.0,
                                    description="Coulomb constant, N m²/C², at the scene's "
                                                "scale (8.988e9 is the real one)")


BEND_ITEMS = [
    ('ANGULAR', "Angular", "Angular spring-dampers: a restoring torque about each shared edge"),
    ('DISTANCE', "Distance", "Cheaper: springs between the far corners of neighbouring triangles"),
    ('NONE', "None", "No bending resistance"),
]
MASS_ITEMS = [
    ('EVEN', "Even", "Every vertex gets the same share of the mass"),
    ('AREA', "By Area", "Each vertex gets the mass of the surface around it"),
]
VIRTUAL_ITEMS = [
    ('PIN', "Pin", "Hold the vertex group at its animated rest position (zero-length springs)"),
    ('ATTACH', "Attach", "Attach the vertex group to the target object: it follows its animation"),
    ('DISTANCE', "Keep Distance", "Keep the vertex group at the rest length from the target's origin"),
]
SPRING_INTEGRATOR_ITEMS = [('SCENE', "Scene", "Use the scene's integrator")] + INTEGRATOR_ITEMS + [
    ('BDF2', "Implicit BDF2", "Second-order implicit (BDF2): stable for stiff springs and damps "
     "swings far less than implicit Euler"),
]
assert tuple(i[0] for i in SPRING_INTEGRATOR_ITEMS[1:]) == SPRING_INTEGRATORS


class PHYSANIM_PG_virtual(bpy.types.PropertyGroup):
    """A group of virtual springs (seed: virtual springs)."""

    mode: EnumProperty(name="Mode", items=VIRTUAL_ITEMS, default='ATTACH', options=STATIC)
    target: PointerProperty(name="Target", type=bpy.types.Object,
                            description="Object the springs attach to or keep away from")
    vertex_group: StringProperty(name="Vertex Group",
                                 description="Vertices with springs; weight scales their strength")
    rest_length: FloatProperty(name="Rest Length", min=0.0, max=1.0e4, unit='LENGTH',
                               options=STATIC)
    stiffness: FloatProperty(name="Stiffness", min=0.0, max=1.0e8, soft_max=1.0e4, default=200.0,
                             options=STATIC, description="N/m")
    damping: FloatProperty(name="Damping", min=0.0, max=1.0e6, soft_max=100.0, default=1.0,
                           options=STATIC, description="N s/m")


class PHYSANIM_PG_spring_mesh(bpy.types.PropertyGroup):
    enabled: BoolProperty(name="Spring Mesh", options=STATIC,
                          description="Simulate this mesh as point masses joined by springs")
    mass: FloatProperty(name="Mass", min=1.0e-6, max=1.0e7, default=1.0, unit='MASS',
                        options=STATIC, description="Total mass of the mesh")
    mass_mode: EnumProperty(name="Mass Distribution", items=MASS_ITEMS, default='EVEN',
                            options=STATIC)
    stiffness: FloatProperty(name="Stiffness", min=0.0, max=1.0e9, soft_max=1.0e5,
                             default=2000.0, options=STATIC,
                             description="Edge (structural) springs, N/m")
    damping: FloatProperty(name="Damping", min=0.0, max=1.0e7, soft_max=100.0, default=2.0,
                           options=STATIC, description="Edge springs, N s/m")
    shear_stiffness: FloatProperty(name="Shear Stiffness", min=0.0, max=1.0e9, soft_max=1.0e5,
                                   default=1000.0, options=STATIC,
                                   description="Face-diagonal springs, N/m (0 = none)")
    shear_damping: FloatProperty(name="Shear Damping", min=0.0, max=1.0e7, soft_max=100.0,
                                 default=1.0, options=STATIC)
    bend_mode: EnumProperty(name="Bending", items=BEND_ITEMS, default='ANGULAR', options=STATIC)
    bend_stiffness: FloatProperty(name="Bend Stiffness", min=0.0, max=1.0e7, soft_max=10.0,
                                  default=0.02, options=STATIC,
                                  description="N m/rad (angular) or N/m (distance)")
    bend_damping: FloatProperty(name="Bend Damping", min=0.0, max=1.0e5, soft_max=1.0,
                                default=0.0005, options=STATIC)
    drag: FloatProperty(name="Air Drag", min=0.0, max=1.0e4, soft_max=10.0, default=0.5,
                        options=STATIC, description="Viscous drag per unit mass, 1/s")
    max_stretch: FloatProperty(name="Max Stretch", min=0.0, max=10.0, soft_max=0.5, default=0.0,
                               subtype='FACTOR', options=STATIC,
                               description="Strain limit of edge and shear springs (0.1 = never "
                                           "longer than 110%; 0 = off): soft springs solve fast "
                                           "and still do not stretch like rubber")
    self_collision: BoolProperty(name="Self Collision", default=False, options=STATIC,
                                 description="Keep the mesh off itself: its vertices off its "
                                             "faces and its edges off its edges, no crossing "
                                             "ever (cloth folding onto itself, a heap)")
    self_distance: FloatProperty(name="Distance", min=1.0e-4, max=1.0, soft_max=0.05,
                                 default=0.01, subtype='DISTANCE', unit='LENGTH', options=STATIC,
                                 description="Kept between the mesh's layers")
    self_friction: FloatProperty(name="Friction", min=0.0, max=100.0, soft_max=2.0, default=0.2,
                                 options=STATIC, description="Coulomb friction between the "
                                 "mesh's layers")
    sleep: BoolProperty(name="Sleep When Still", default=True, options=STATIC,
                        description="Stop simulating the mesh once it has come to rest (for "
                                    "half a second no vertex further than 1 mm from where it "
                                    "was, or a thousandth of a small mesh's size, nor faster "
                                    "than 8 mm/s) while nothing around it changes; a moving "
                                    "collider or pin, a force keyed or gusting or a change of "
                                    "gravity wakes it")
    pin_group: StringProperty(name="Pin Group", description="Vertex group: weight 1 pins a "
                              "vertex to its animated position, less holds it with a spring")
    pin_stiffness: FloatProperty(name="Pin Stiffness", min=0.0, max=1.0e9, soft_max=1.0e5,
                                 default=1000.0, options=STATIC,
                                 description="Springs of partly weighted pins, N/m")
    virtual_springs: CollectionProperty(type=PHYSANIM_PG_virtual)
    integrator: EnumProperty(name="Integrator", items=SPRING_INTEGRATOR_ITEMS, default='IMPLICIT',
                             options=STATIC,
                             description="Implicit Euler (default) is stable for every stiffness "
                                         "at any step; Implicit BDF2 too, with far less damping; "
                                         "explicit methods need small steps")
    substeps: IntProperty(name="Substeps", min=0, max=1000, default=0, options=STATIC,
                          description="Steps per frame (0 = the scene's Spring Mesh Substeps)")
    bake_hash: StringProperty(name="Bake Hash", options={'HIDDEN'})


class PHYSANIM_PG_result(bpy.types.PropertyGroup):
    """Set on the points object a bake makes: where its per-frame cache lives."""

    cache: StringProperty(name="Cache", subtype='DIR_PATH', options=BLEND_RELATIVE_PATH_OPTIONS,
                          description="Folder of this result's per-frame point files")
    emitter: StringProperty(name="Emitter", description="Name of the emitter that made this result")
    hash: StringProperty(name="Inputs Hash", options={'HIDDEN'},
                         description="Digest of the inputs of the bake (outdated detection)")


class PHYSANIM_PG_follow(bpy.types.PropertyGroup):
    enabled: BoolProperty(name="Follow-Through", options=STATIC,
                          description="This object trails its parent through a damped spring: it "
                                      "runs on when the parent stops and swings back (baked to "
                                      "Delta Location keys; its own animation stays)")
    frequency: FloatProperty(name="Frequency", min=0.01, max=1000.0, soft_max=20.0, default=2.0,
                             options=STATIC, description="How fast it swings, Hz: higher "
                                                         "follows more tightly")
    damping: FloatProperty(name="Damping", min=0.0, max=100.0, soft_max=2.0, default=0.3,
                           options=STATIC, description="Damping ratio: 0 swings on forever, 1 "
                                                       "settles without overshoot")
    bake_hash: StringProperty(options={'HIDDEN'})


class PHYSANIM_PG_object(bpy.types.PropertyGroup):
    emitter: PointerProperty(type=PHYSANIM_PG_emitter)
    collider: PointerProperty(type=PHYSANIM_PG_collider)
    force: PointerProperty(type=PHYSANIM_PG_force)
    spring_mesh: PointerProperty(type=PHYSANIM_PG_spring_mesh)
    rigid_body: PointerProperty(type=PHYSANIM_PG_rigid_body)
    constraint: PointerProperty(type=PHYSANIM_PG_constraint)
    follow: PointerProperty(type=PHYSANIM_PG_follow)
    result: PointerProperty(type=PHYSANIM_PG_result)


class PHYSANIM_PG_scene(bpy.types.PropertyGroup):
    frame_start: IntProperty(name="Start", default=1, min=-1_000_000, max=1_000_000, options=STATIC)
    frame_end: IntProperty(name="End", default=250, min=-1_000_000, max=1_000_000, options=STATIC)
    substeps: IntProperty(name="Substeps", default=2, min=1, max=1000, soft_max=50,
                          description="Simulation steps per frame", options=STATIC)
    integrator: EnumProperty(name="Integrator", items=INTEGRATOR_ITEMS, default='SYMPLECTIC_EULER',
                             options=STATIC)
    spring_substeps: IntProperty(
        name="Spring Mesh Substeps", default=1, min=1, max=1000, soft_max=50, options=STATIC,
        description="Implicit steps per frame for spring meshes (more: less numerical damping, "
                    "slower; a mesh attached to rigid bodies it moves takes at least 2; a mesh's "
                    "own Substeps overrides this)")
    rigid_substeps: IntProperty(name="Rigid Body Substeps", default=8, min=1, max=1000,
                                soft_max=50, options=STATIC,
                                description="Contact solver steps per frame for rigid bodies "
                                            "(more: stiffer stacks, fewer: faster)")
    time_scale: FloatProperty(
        name="Time Scale", default=1.0, min=MIN_SCALE, max=MAX_SCALE, soft_min=0.05, soft_max=4.0,
        description="Simulated time per frame, in frames: 0.25 is four times slow motion, 2 "
                    "double speed; keyframe it for speed ramps. Paths in space stay as at 1 "
                    "(the simulation keeps its steps; frames between them are interpolated)")
    tolerance: FloatProperty(name="Tolerance", default=1.0e-4, min=1.0e-10, max=1.0,
                             precision=6, description="Error tolerance of the adaptive RK45", options=STATIC)
    seed: IntProperty(name="Seed", min=0, max=2**31 - 1, options=STATIC)
    world_bound: FloatProperty(name="World Bound", default=DEFAULT_POSITION, min=1.0, max=1.0e7,
                               unit='LENGTH', options=STATIC,
                               description="A particle or vertex farther than this from the world "
                                           "origin (in any axis) stops the bake with an error")
    speed_limit: FloatProperty(name="Speed Limit", default=DEFAULT_SPEED, min=1.0, max=1.0e7,
                               unit='VELOCITY', options=STATIC,
                               description="A particle or vertex faster than this stops the bake "
                                           "with an error")
    cache_dir: StringProperty(name="Cache", subtype='DIR_PATH', default="//physanim_cache",
                              options=BLEND_RELATIVE_PATH_OPTIONS,
                              description="Folder for bake caches ('//' = next to the .blend)")
    bake_hash: StringProperty(name="Bake Hash", options={'HIDDEN'})
    bake_info: StringProperty(name="Bake Info", options={'HIDDEN'})


CLASSES = (PHYSANIM_PG_stop, PHYSANIM_PG_emitter, PHYSANIM_PG_collider, PHYSANIM_PG_force,
           PHYSANIM_PG_virtual, PHYSANIM_PG_spring_mesh, PHYSANIM_PG_rigid_body,
           PHYSANIM_PG_constraint, PHYSANIM_PG_result, PHYSANIM_PG_follow, PHYSANIM_PG_object,
           PHYSANIM_PG_scene)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.physanim = PointerProperty(type=PHYSANIM_PG_object)
    bpy.types.Scene.physanim = PointerProperty(type=PHYSANIM_PG_scene)


def unregister() -> None:
    del bpy.types.Scene.physanim
    del bpy.types.Object.physanim
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
