"""Spring-mass meshes: every vertex a point mass, every edge a spring-damper, plus shear,
bending and virtual springs; explicit integrators or Baraff-Witkin implicit Euler."""
from .model import (Attachment, SpringMeshBuilder, SpringMeshModel, SpringMeshSettings,
                    SpringMeshState, VirtualSprings)
from .frame_step import SpringMeshSystem
from .inputs import SpringDrive, SpringFrameInputs
from .solver import SpringMeshSolver

__all__ = ["Attachment", "SpringDrive", "SpringFrameInputs", "SpringMeshBuilder", "SpringMeshModel", "SpringMeshSettings",
           "SpringMeshSolver", "SpringMeshState", "SpringMeshSystem", "VirtualSprings"]
