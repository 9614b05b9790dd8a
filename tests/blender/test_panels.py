"""Every PhysAnim panel draws, for an object with every role and in every mode the panels
branch on, without an error and without drawing a property that does not exist."""
from __future__ import annotations

import sys

import bpy
import pytest

from physanim.tests.blender.probes import LabelRecorder


def _panels(ext):
    return sys.modules[f"{ext.__name__}.addon.panels"]._classes()


@pytest.mark.parametrize("render_as", ['OBJECT', 'BILLBOARD', 'GLOW', 'BLOBS', 'STREAKS'])
def test_every_panel_draws_for_every_role(physanim_ext, render_as):
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_cube_add()
    cube = bpy.context.object
    parent = bpy.data.objects.new("Parent", None)
    scene.collection.objects.link(parent)
    cube.parent = parent
    roles = cube.physanim
    for role in ("emitter", "collider", "force", "rigid_body", "constraint", "follow"):
        getattr(roles, role).enabled = True
    roles.emitter.render_as = render_as
    roles.emitter.squash = 1.0 if render_as == 'OBJECT' else 0.0
    roles.rigid_body.squash = 1.0
    roles.rigid_body.target = parent
    bpy.ops.mesh.primitive_grid_add()
    cloth = bpy.context.object
    cloth.physanim.spring_mesh.enabled = True  # (it excludes the rigid body role)
    drawn = 0
    for ob in (cube, cloth):
        context = type("Context", (), {"object": ob, "scene": scene})()
        for panel in _panels(physanim_ext):
            if hasattr(panel, "poll") and not panel.poll(context):
                continue
            labels: list[str] = []
            helpers = {k: v for k, v in vars(panel).items() if isinstance(v, staticmethod)}
            panel.draw(type("Panel", (), {"layout": LabelRecorder(labels), **helpers})(),
                       context)
            drawn += 1
    assert drawn >= 10
