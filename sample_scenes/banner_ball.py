"""Banner and ball: a cloth banner hangs from a bar, a wooden sign attached to its bottom edge
(a constraint holding the banner's "Hook" vertex group on the sign, a rigid body); a rubber
ball thrown at the banner strikes it. Everything couples both ways: the ball pushes the cloth
and is slowed by it, the cloth swings the sign, and the sign's weight keeps the banner taut.
The banner, the sign and the ball are the product's defaults apart from their sizes, masses,
the ball's throw and the banner's pin group.

Self-check: the sign stays on the banner (the hook row on the sign's top edge within 5 mm in
every frame), the banner bellies out where the ball hits (over 15 cm) and the sign swings with
it and swings back (the banner pulls it home), the ball loses at least a third of its speed to
the cloth, and no banner vertex gets inside the ball.
"""
from __future__ import annotations

import math

import bpy
import numpy as np

from sample_scenes import _common

NAME = "banner_ball"
WIDTH, HEIGHT = 1.6, 1.2  # banner [m]
TOP = 2.6  # [m] the bar's height
SIGN = (0.9, 0.05, 0.15)  # the sign's half extents [m]
BALL_RADIUS = 0.15  # [m]
THROW = (0.0, 5.0, 2.2)  # [m/s] the ball's initial velocity
FRAMES = 96
ON_SIGN = 0.005  # [m] the hook row's largest distance from the sign's top edge
BELLY = 0.15  # [m] how far the ball must push the banner out
SLOWED = 2.0 / 3.0  # the ball keeps at most this share of its speed

# the throw (1), the ball in the banner (10), bounced off with the sign swinging (16), (40)
SHOWCASE = (1, 10, 16, 40)
README_FRAME = 10


def build(scene) -> None:
    import bmesh
    from mathutils import Matrix

    _common.stage(scene, (5.4, -2.6, 2.2), (0.0, 0.2, 1.5), frame_end=FRAMES)
    _common.ground(scene)
    bar = _common.add_mesh(scene, "Bar", lambda bm: bmesh.ops.create_cone(
        bm, cap_ends=True, segments=16, radius1=0.03, radius2=0.03, depth=WIDTH + 0.4,
        matrix=Matrix.Rotation(math.pi / 2, 4, 'Y')))
    bar.location = (0.0, 0.0, TOP + 0.03)
    bar.data.materials.append(_common.material("Bar", (0.6, 0.6, 0.62)))

    banner = _common.grid(scene, "Banner", 24, 18, 1.0)
    banner.scale = (WIDTH, HEIGHT, 1.0)
    banner.rotation_euler = (math.radians(90.0), 0.0, 0.0)  # hang in the XZ plane
    banner.location = (0.0, 0.0, TOP - HEIGHT / 2)
    banner.data.materials.append(_common.material("Banner", (0.1, 0.3, 0.75)))
    for poly in banner.data.polygons:
        poly.use_smooth = True
    z = np.array([v.co.y for v in banner.data.vertices])  # the grid's y is the banner's height
    for name, rows in (("Bar", z > z.max() - 1e-6), ("Hook", z < z.min() + 1e-6)):
        group = banner.vertex_groups.new(name=name)
        group.add([int(i) for i in np.nonzero(rows)[0]], 1.0, 'REPLACE')
    p = banner.physanim.spring_mesh
    p.enabled, p.pin_group, p.substeps = True, "Bar", 4

    bottom = TOP - HEIGHT
    sign = _common.add_mesh(scene, "Sign", lambda bm: bmesh.ops.create_cube(
        bm, size=2.0, matrix=Matrix.Diagonal((*SIGN, 1.0))))
    sign.location = (0.0, 0.0, bottom - SIGN[2])
    sign.data.materials.append(_common.material("Wood", (0.45, 0.28, 0.12)))
    sign.physanim.rigid_body.enabled = True
    sign.physanim.rigid_body.mass = 4.0  # a solid board

    hook = bpy.data.objects.new("SignHook", None)
    hook.empty_display_size = 0.1
    hook.location = (0.0, 0.0, bottom)
    scene.collection.objects.link(hook)
    c = hook.physanim.constraint
    c.enabled, c.object1, c.group1, c.object2 = True, banner, "Hook", sign

    ball = _common.add_mesh(scene, "Ball", lambda bm: bmesh.ops.create_uvsphere(
        bm, u_segments=32, v_segments=16, radius=BALL_RADIUS))
    ball.location = (0.25, -1.6, 1.6)
    ball.data.materials.append(_common.material("Rubber", (0.85, 0.55, 0.1)))
    for poly in ball.data.polygons:
        poly.use_smooth = True
    r = ball.physanim.rigid_body
    r.enabled, r.mass, r.initial_velocity = True, 0.4, THROW


def check(scene) -> list[str]:
    problems = []
    banner, sign, ball = (bpy.data.objects[n] for n in ("Banner", "Sign", "Ball"))
    group = banner.vertex_groups["Hook"].index
    hook = np.array([v.index for v in banner.data.vertices
                     if any(g.group == group for g in v.groups)])
    x, sign_at, ball_at = [], [], []
    for f in range(1, FRAMES + 1):
        scene.frame_set(f)
        x.append(_common.evaluated_vertices(banner))
        sign_at.append(np.array(sign.matrix_world))
        ball_at.append(np.array(ball.matrix_world.translation))
    x, sign_at, ball_at = np.array(x), np.array(sign_at), np.array(ball_at)
    if not np.all(np.isfinite(x)):
        return ["the banner has non-finite vertices"]
    # the hook row in the sign's own frame: on its top face (local z = half height)
    local = np.einsum("fij,fkj->fki", np.linalg.inv(sign_at)[:, :3, :3],
                      x[:, hook] - sign_at[:, None, :3, 3])
    off = np.abs(local[..., 2] - SIGN[2]).max()
    if off > ON_SIGN:
        problems.append(f"the banner came off the sign ({off * 1000:.1f} mm)")
    belly = (x[:, :, 1] - x[0, :, 1]).max()
    if belly < BELLY:
        problems.append(f"the ball pushed the banner out only {belly * 100:.0f} cm")
    swing = (sign_at[:, 1, 3] - sign_at[0, 1, 3]).max()
    if swing < 0.02:
        problems.append(f"the sign did not swing with the banner ({swing * 1000:.0f} mm)")
    v = np.diff(ball_at, axis=0) * scene.render.fps
    speed0, after = np.linalg.norm(v[0]), np.abs(v[16:30, 1]).max()
    if after > SLOWED * speed0:
        problems.append(f"the ball kept {after / speed0:.0%} of its speed through the cloth")
    inside = (np.linalg.norm(x - ball_at[:, None], axis=2) - BALL_RADIUS).min()
    if inside < -0.02:
        problems.append(f"a banner vertex went {-inside * 100:.1f} cm inside the ball")
    y = sign_at[:, 1, 3] - sign_at[0, 1, 3]
    out = int(np.argmax(y))
    if y[out:].min() > -0.25 * y[out]:
        problems.append("the sign does not swing back: nothing pulls it home")
    return problems
