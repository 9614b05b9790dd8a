"""Spring-mass meshes: every vertex a point mass, every edge a spring-damper, plus shear,
bending and virtual springs; explicit integrators or Baraff-Witkin implicit Euler."""
from .model import (Attachment, SpringMeshBuilder, SpringMeshModel, SpringMeshSettings,
                    SpringMeshState, VirtualSprings)
from .solver import SpringDrive, SpringFrameInputs, SpringMeshSolver, SpringMeshSystem

__all__ = ["Attachment", "SpringDrive", "SpringFrameInputs", "SpringMeshBuilder", "SpringMeshModel", "SpringMeshSettings",
           "SpringMeshSolver", "SpringMeshState", "SpringMeshSystem", "VirtualSprings"]
