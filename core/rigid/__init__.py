"""Rigid bodies (Witkin & Baraff's x, R, P, L): mass properties from shapes and meshes, a
builder -> frozen model -> state, free motion with the angular momentum held, contacts found
by a broad phase and a narrow phase per shape pair (sphere, box, capsule, convex hull, the
ground), and a soft-step contact solver with manifold blocks, warm starting and friction."""
from .mass import MassProperties, box_mass, capsule_mass, polyhedron_mass, sphere_mass
from .model import SHAPES, RigidBodyBuilder, RigidBodyModel, RigidBodySettings, RigidBodyState
from .frame_inputs import RigidFrameInputs, RigidPaths, RigidReport
from .solver import RigidBodySolver, RigidBodySystem

__all__ = ["SHAPES", "MassProperties", "RigidBodyBuilder", "RigidBodyModel", "RigidBodySettings",
           "RigidBodySolver", "RigidBodyState", "RigidBodySystem", "RigidFrameInputs",
           "RigidPaths", "RigidReport", "box_mass", "capsule_mass", "polyhedron_mass", "sphere_mass"]
