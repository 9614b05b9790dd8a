"""Two-way coupling of spring meshes and rigid bodies: a body hanging from a rope or a cloth
pulls it and is held by it (closed-form statics and oscillation period), momentum of the coupled
system is conserved to rounding, and a cloth striking a free body pushes it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.errors import PhysanimError
from physanim.core.rigid.solver import RigidBodySystem
from physanim.core.springs import (
    Attachment, SpringDrive, SpringMeshBuilder, SpringMeshSettings, SpringMeshSolver,
    SpringMeshSystem,
)
from physanim.core.springs.solver import COUPLED_SUBSTEPS
from physanim.core.world import World, WorldFrame
from physanim.tests.core.helpers import grid
from physanim.tests.core.rigid_helpers import DT, box
from physanim.tests.core.rigid_helpers import world as rigid_world

G = 9.81


def rope(n=11, length=1.0, top=2.0, mass=0.1, stiffness=1000.0, damping=2.0):
    """A vertical rope of n vertices (edges only) from z = top down, its top vertex pinned."""
    x = np.stack([np.zeros(n), np.zeros(n), top - np.linspace(0.0, length, n)], axis=1)
    edges = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    pin = np.zeros(n)
    pin[0] = 1.0
    settings = SpringMeshSettings("Rope", mass=mass, stiffness=stiffness, damping=damping,
                                  shear_stiffness=0.0, bend_stiffness=0.0, bend_damping=0.0,
                                  drag=0.0)
    return SpringMeshBuilder(settings, x, edges, np.zeros((0, 3), np.int64), pin_weight=pin)


def coupled(builder, *bodies, integrator="IMPLICIT"):
    """(world, rigid state, mesh model, mesh state) of one mesh and some rigid bodies."""
    model = builder.finalize()
    _, rigid, rstate = rigid_world(*bodies)
    mesh = SpringMeshSolver(model, integrator)
    mstate = model.state()
    return World([RigidBodySystem(rigid, rstate), SpringMeshSystem(mesh, mstate)]), rstate, \
        model, mstate


def run(world, frames, gravity=-G, each=None):
    for f in range(frames):
        report = world.advance(WorldFrame(f, f * DT, DT, (0.0, 0.0, gravity)))
        assert not report.failed, report.failed
        if each is not None:
            each(f)


N, HALF = 11, 0.1  # rope vertices; the box's half size [m]


def box_on_rope(mass, frames=240):
    """A box of ``mass`` hung by its top from the bottom vertex of :func:`rope`, run ``frames``
    (10 s): (its heights per frame, the mesh model and state)."""
    builder = rope(N)
    builder.add_attachment(Attachment([N - 1], "Box"))
    world, rstate, model, mstate = coupled(builder, box("Box", (HALF,) * 3, (0, 0, 1.0 - HALF),
                                                        mass=mass))
    heights = []
    run(world, frames, each=lambda f: heights.append(rstate.body_x[0, 2]))
    return np.array(heights), model, mstate


def test_a_box_hanging_from_a_rope_stretches_it_as_statics_says():
    # A 1 kg box hangs from the bottom vertex of a 10-spring rope (k = 1000 N/m each, 0.1 kg)
    # pinned at its top. Spring j carries the box and every vertex below it, so it stretches
    # W_j / k; the box settles where the sum of those puts it (within 1.5 mm after 20 s) and
    # stays (frame to frame within 1e-6 m), and the top spring is as long as its load says
    # (within 0.1 mm). One-way, the box would fall through. (The rope takes two sub-steps a
    # frame, COUPLED_SUBSTEPS: at the first it holds its bottom vertex on the box's path half
    # way through the frame, which the box, stepped first, took falling freely — its pull comes
    # at the frame's end. So the rope's lower springs are up to 0.25 mm short and the box
    # rests 1.15 mm above statics, 0.5 % of the rope's 204 mm stretch; 0.16 mm at one sub-step,
    # 1.34 and 1.40 mm at three and four.)
    mass = 1.0
    heights, model, mstate = box_on_rope(mass, frames=480)
    vertex = model.vertex_mass[0]
    loads = np.array([(mass + vertex * (N - 1 - j)) * G for j in range(N - 1)])
    expected = 2.0 - (1.0 + float(np.sum(loads)) / 1000.0) - HALF
    assert abs(heights[-1] - expected) < 1.5e-3
    assert np.ptp(heights[-24:]) < 1e-6
    top = np.linalg.norm(mstate.x[1] - mstate.x[0])
    assert abs(top - (0.1 + loads[0] / 1000.0)) < 1e-4


def test_a_box_bouncing_on_a_rope_has_the_springs_period():
    # A 5 kg box released where the unstretched rope leaves it: it bounces on the rope's ten
    # springs in series, k_eff = k / 10, with the rope's mass m/3 added to it (Rayleigh):
    # T = 2 pi sqrt((M + m/3) / k_eff) = 1.41 s. Backward Euler at omega h = 0.19 lengthens
    # the period by about (omega h)^2 / 3 and the one-frame split of body and rope adds its
    # own: asserted within 3 %.
    mass = 5.0
    z, model, _ = box_on_rope(mass)
    z = z - np.mean(z[-96:])
    t = np.arange(1, len(z) + 1) * DT
    up = np.nonzero((z[:-1] < 0.0) & (z[1:] >= 0.0))[0]
    crossings = t[up] - z[up] * DT / (z[up + 1] - z[up])
    period = 2 * math.pi * math.sqrt((mass + model.vertex_mass.sum() / 3) / (1000.0 / (N - 1)))
    assert len(crossings) >= 4
    assert abs(np.mean(np.diff(crossings[:4])) / period - 1.0) < 0.03


def _floating(spin=True):
    """A 9 x 9 cloth (0.3 kg) hung by its bottom row from a 1 kg box, both drifting and the box
    tumbling, gravity off, no drag or damping to the air: they fold, wrap and hit each other."""
    x, edges, tris, ls, lt, lv = grid(9, 9)
    x = np.stack([x[:, 0] - 0.5, np.zeros(len(x)), 2.0 - x[:, 1]], axis=1)
    bottom = np.nonzero(np.isclose(x[:, 2], 1.0))[0]
    builder = SpringMeshBuilder(SpringMeshSettings("Cloth", mass=0.3, drag=0.0), x, edges, tris,
                                ls, lt, lv)
    builder.add_attachment(Attachment(bottom, "Box"))
    world, rstate, model, mstate = coupled(builder, box(
        "Box", (0.5, 0.1, 0.1), (0, 0, 0.9), linear_damping=0.0, angular_damping=0.0))
    rstate.body_P[0] = (0.3, 0.5, -0.2)
    rstate.body_L[0] = (0.01, 0.02, 0.0) if spin else (0.0, 0.0, 0.0)
    mstate.v[:] = (-0.1, 0.2, 0.3)
    return world, rstate, model, mstate


def test_momentum_of_a_cloth_and_the_box_it_hangs_on_is_conserved():
    # Gravity off, nothing outside: every impulse between the cloth and the box — through the
    # attachment and through their collisions — is equal and opposite, so the total momentum
    # stays what it was to rounding (the issue asks 1e-9) over 10 s of tumbling, and the
    # kinetic energy does not grow (the cloth's damping only takes).
    world, rstate, model, mstate = _floating()

    def momentum():
        return rstate.body_P[0] + (model.vertex_mass[:, None] * mstate.v).sum(axis=0)

    p0, energy = momentum(), []

    def each(f):
        assert np.max(np.abs(momentum() - p0)) < 1e-9
        energy.append(0.5 * float(np.sum(model.vertex_mass[:, None] * mstate.v ** 2))
                      + 0.5 * float(rstate.body_P[0] @ rstate.body_P[0]))

    run(world, 240, gravity=0.0, each=each)
    assert max(energy[120:]) < 1.05 * energy[0]


def test_a_cloth_thrown_at_a_free_box_pushes_it():
    # A cloth flying at 3 m/s strikes a 0.5 kg box floating still (gravity off): the box leaves
    # in the cloth's direction, and what the cloth lost the box gained (to rounding).
    x, edges, tris, ls, lt, lv = grid(9, 9)
    x = np.stack([x[:, 0] - 0.5, np.full(len(x), -0.5), x[:, 1] - 0.5], axis=1)  # in y = -0.5
    builder = SpringMeshBuilder(SpringMeshSettings("Flag", mass=0.3, drag=0.0), x, edges, tris,
                                ls, lt, lv)
    world, rstate, model, mstate = coupled(builder, box("Box", (0.2, 0.2, 0.2), (0, 0.3, 0),
                                                        mass=0.5, linear_damping=0.0))
    mstate.v[:] = (0.0, 3.0, 0.0)
    p0 = (model.vertex_mass[:, None] * mstate.v).sum(axis=0)
    run(world, 24, gravity=0.0)
    p = rstate.body_P[0] + (model.vertex_mass[:, None] * mstate.v).sum(axis=0)
    np.testing.assert_allclose(p, p0, atol=1e-9)
    assert rstate.body_P[0, 1] > 0.2 * p0[1]  # the box took a good share of the push
    assert rstate.body_x[0, 1] > 0.35  # and moved off in the cloth's direction


def test_a_cloth_striking_a_free_box_square_pushes_it_without_pulling_or_spinning_it():
    # Contacts only push. The cloth of the test above strikes the box square (both symmetric
    # about the line of flight but for the grid's diagonals): the impulses holding its pressed
    # vertices on the box push, and the box leaves without a spin. Before contacts were made
    # unilateral, the ones that held vertices on the box pulled too (their pulls summed to half
    # the pushes) and spun the box at up to 2.4 rad/s.
    x, edges, tris, ls, lt, lv = grid(9, 9)
    x = np.stack([x[:, 0] - 0.5, np.full(len(x), -0.5), x[:, 1] - 0.5], axis=1)
    builder = SpringMeshBuilder(SpringMeshSettings("Flag", mass=0.3, drag=0.0), x, edges, tris,
                                ls, lt, lv)
    half, mass = 0.2, 0.5
    world, rstate, _, mstate = coupled(builder, box("Box", (half,) * 3, (0, 0.3, 0), mass=mass,
                                                    linear_damping=0.0))
    mstate.v[:] = (0.0, 3.0, 0.0)
    integrator = world.systems[1].solver.integrator
    step, normal_impulses = integrator._step_impl, []

    def observed(system, *args):  # the real step; afterwards its contacts' normal impulses
        out = step(system, *args)
        _, constraints, _, residual = integrator.last_solve
        normal_impulses.append(np.einsum("ij,ij->i", residual[constraints.pressed],
                                         constraints.normal))
        return out

    integrator._step_impl = observed
    spin = []
    run(world, 24, gravity=0.0, each=lambda f: spin.append(np.linalg.norm(rstate.body_L[0])))
    rn = np.concatenate(normal_impulses)
    push, pull = rn[rn > 0.0].sum(), -rn[rn < 0.0].sum()
    assert push > 0.0 and pull < 0.01 * push
    inertia = mass * (2.0 * half) ** 2 / 6.0  # a cube's about any axis through its centre
    assert max(spin) / inertia < 0.5  # rad/s
    assert rstate.body_P[0, 1] > 0.2 * 0.3 * 3.0  # pushed: the test above's share


def test_an_attachment_to_a_rigid_body_needs_the_implicit_integrator():
    builder = rope(stiffness=1.0)  # soft enough for RK4's own stability check
    builder.add_attachment(Attachment([10], "Box"))
    world, *_ = coupled(builder, box("Box", (0.1,) * 3, (0, 0, 0.9)), integrator="RK4")
    report = world.advance(WorldFrame(0, 0.0, DT))
    (system, error), = report.failed
    assert isinstance(error, PhysanimError)
    assert 'rigid body "Box"' in str(error) and "IMPLICIT" in str(error) and "RK4" in str(error)


def test_attachments_hold_vertices_on_animated_objects_and_the_world():
    # Held on an animated object (not simulated: nothing goes back), the vertices move rigidly
    # with it; held on the world (target None) they stay where they were.
    from physanim.core.springs import SpringDrive
    from physanim.tests.core.helpers import rotation, translation
    n = 11
    builder = rope(n)
    builder.add_attachment(Attachment([n - 1], "Hook"))
    builder.add_attachment(Attachment([5], None))
    model = builder.finalize()
    solver = SpringMeshSolver(model, "IMPLICIT")
    state = model.state()
    system = SpringMeshSystem(solver, state)
    world = World([system])
    start = state.x.copy()
    for f in range(12):
        m0 = translation(0.1 * f) @ rotation((0, 0, 1), 0.1 * f)
        m1 = translation(0.1 * (f + 1)) @ rotation((0, 0, 1), 0.1 * (f + 1))
        world.advance(WorldFrame(f, f * DT, DT), {system: SpringDrive(targets={"Hook": (m0, m1)})})
        np.testing.assert_allclose(state.x[n - 1], (m1 @ np.append(start[n - 1], 1.0))[:3],
                                   atol=1e-12)
        np.testing.assert_allclose(state.x[5], start[5], atol=1e-12)
    with pytest.raises(ValueError, match="needs vertices"):
        Attachment([], "Hook")


def test_a_mesh_holding_a_body_it_moves_takes_two_substeps_a_frame_at_least():
    """Asked for one sub-step a frame (the spring meshes' default), a rope holding a box takes
    COUPLED_SUBSTEPS in every frame its attachment moves the box (frame-staggered two-way
    coupling blows up at one: the rope bridge, below); the same rope attached to an object that
    is no body (an animated hook: one-way) takes the one asked for, and so does one asked for
    more than two."""
    for target, asked, expected in (("Box", 1, COUPLED_SUBSTEPS), ("Hook", 1, 1),
                                    ("Box", 3, 3)):
        builder = rope(N)
        builder.add_attachment(Attachment([N - 1], target))
        model = builder.finalize()
        _, rigid, rstate = rigid_world(box("Box", (HALF,) * 3, (1.0, 0.0, 1.0 - HALF)))
        mesh = SpringMeshSystem(SpringMeshSolver(model, "IMPLICIT", asked), model.state())
        world = World([RigidBodySystem(rigid, rstate), mesh])
        drive = SpringDrive(targets={"Hook": (np.eye(4), np.eye(4))})
        report = world.advance(WorldFrame(0, 0.0, DT, (0.0, 0.0, -G)), {mesh: drive})
        assert not report.failed, report.failed
        assert mesh.substeps == expected, (target, asked, mesh.substeps)


@pytest.mark.parametrize("substeps", [1, 2])
def test_a_rope_bridge_of_twelve_planks_settles_at_the_substeps_asked(substeps):
    # Two ropes (44 segments of 10 cm, 50,000 N/m each, 2 kg in all) slung 4.4 m between
    # pinned ends with 30 cm of sag carry twelve 2 kg planks, each held on the three or four
    # rope vertices under it (the rope bridge sample scene, without its barrel). The ropes'
    # tension runs through the planks' attached vertices, 4 cm below each plank's centre: a
    # plank turned by the coupled step turns those arms, and the moments of the holding
    # impulses change with it — a stiffness of about 0.2 T h^2 on a plank of 0.015 kg m^2.
    # Left out of the coupled solve, it made the step explicit in the planks' pitch and the
    # bridge blew up within 15 frames at 2 sub-steps; with it, the bridge sags under its planks
    # and is at rest (every plank slower than 5 cm/s) after 4 s, its planks held on the ropes.
    # Asked for one sub-step a frame it takes COUPLED_SUBSTEPS (at one, its planks reached
    # 650 km/s by frame 6).
    span, sag, gauge, cuts = 4.4, 0.3, 0.9, 44
    along = np.linspace(-span / 2, span / 2, cuts + 1)
    z = 2.0 - sag * (1.0 - (2.0 * along / span) ** 2)
    x = np.concatenate([np.stack([along, np.full(cuts + 1, y), z], axis=1)
                        for y in (-gauge / 2, gauge / 2)])
    line = np.stack([np.arange(cuts), np.arange(1, cuts + 1)], axis=1)
    edges = np.concatenate([line, line + cuts + 1])
    pin = np.zeros(len(x))
    pin[[0, cuts, cuts + 1, 2 * cuts + 1]] = 1.0
    settings = SpringMeshSettings("Ropes", mass=2.0, stiffness=50_000.0, damping=2.0,
                                  shear_stiffness=0.0, bend_stiffness=0.0, bend_damping=0.0)
    builder = SpringMeshBuilder(settings, x, edges, np.zeros((0, 3), np.int64), pin_weight=pin)
    planks, thick = [], 0.04
    for i, cx in enumerate(np.linspace(-(0.45 * span - 0.15), 0.45 * span - 0.15, 12)):
        under = np.nonzero(np.abs(along - cx) <= 0.15)[0]
        builder.add_attachment(Attachment(np.concatenate([under, under + cuts + 1]), f"P{i}",
                                          collide=False))  # a constraint's default
        top = 2.0 - sag * (1.0 - (2.0 * cx / span) ** 2)  # flat planks, on the ropes' line
        planks.append(box(f"P{i}", (0.15, 0.55, thick / 2), (cx, 0.0, top + thick / 2 + 0.02),
                          mass=2.0))
    model = builder.finalize()
    _, rigid, rstate = rigid_world(*planks)
    mesh = SpringMeshSolver(model, "IMPLICIT", substeps=substeps)
    mstate = model.state()
    world = World([RigidBodySystem(rigid, rstate), SpringMeshSystem(mesh, mstate)])
    bound = [mstate.x[a.index] - rstate.body_x[k] for k, a in enumerate(model.attachments)]
    path = [rstate.body_x.copy()]

    def each(f):
        path.append(rstate.body_x.copy())
        for k, a in enumerate(model.attachments):  # the held vertices turn with the plank
            r = mstate.x[a.index] - rstate.body_x[k]
            assert abs(np.linalg.norm(r, axis=1) - np.linalg.norm(bound[k], axis=1)).max() < 1e-3

    run(world, 96, each=each)
    speeds = np.linalg.norm(np.diff(path, axis=0), axis=2).max(axis=1) / DT  # as keys show
    assert max(speeds) < 2.0  # it swings (about 0.4 m/s), it does not fly apart
    assert max(speeds[-12:]) < 0.05
    assert rstate.body_x[:, 2].min() > 1.2  # hanging from the ropes, not fallen
