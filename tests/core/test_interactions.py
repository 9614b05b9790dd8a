"""Interactions among particles (core/forces/interactions.py, barnes_hut.py, and the neighbour
grid of core/collision/neighbours.py) against closed forms: a circular two-body orbit's period,
momentum and angular momentum of a cloud, the tree code's error against the exact sum,
Lennard-Jones oscillation about 2^(1/6) sigma and a condensing droplet, Coulomb repulsion's
energy, and which emitters take part."""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.collision.neighbours import neighbour_pairs
from physanim.core.forces import Drag
from physanim.core.forces import barnes_hut as bh
from physanim.core.forces.interactions import Coulomb, LennardJones, MutualGravity
from physanim.core.particles import EmitterFrame, EmitterSettings, FrameInputs, ParticleSolver
from physanim.tests.core.helpers import particle_model, place

ZERO_G = (0.0, 0.0, 0.0)


def _run(model, state, interactions, frames, dt, substeps=1, integrator="SYMPLECTIC_EULER",
         forces=(), each=None):
    solver = ParticleSolver(model, integrator, substeps)
    idle = [EmitterFrame(active=False)] * model.emitter_count
    for f in range(frames):
        solver.advance(state, FrameInputs(frame=f, t0=f * dt, frame_dt=dt, gravity=ZERO_G,
                                          emitters=idle, forces=forces,
                                          interactions=interactions))
        if each is not None:
            each(f, state)


# -- neighbours ---------------------------------------------------------------------------------

@pytest.mark.parametrize("scale", [1.0, 1e6])
def test_neighbour_grid_finds_exactly_the_pairs_within_the_radius(scale):
    rng = np.random.default_rng(3)
    x = rng.random((1500, 3)) * scale
    x[:40] = x[40:80]  # coincident points count too
    r = 0.08 * scale
    i, j = neighbour_pairs(x, r)
    found = set(map(tuple, np.sort(np.stack([i, j], 1), axis=1)))
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    a, b = np.nonzero(np.triu(d <= r, 1))
    assert found == set(zip(a.tolist(), b.tolist()))
    assert len(found) == len(i)  # each pair once


@pytest.mark.parametrize("offset", [(-0.82269028759918, -0.1819861337355423, -0.5385737997878917),
                                    (0.5073918867149162, -0.1955161964323342, -0.8392418544308373)])
def test_a_pair_at_the_radius_is_in_as_its_own_squared_distance_rounds(offset):
    """Two points about the radius apart, whose squared distance rounds to either side of
    it by the order its three squares are summed in: the search decides as the pair's own
    row sum (einsum over its differences) does, however it lays out its candidates; and
    nothing, not an error, for no points at all."""
    x = np.array([[0.0, 0.0, 0.0], offset])
    d = x[1:] - x[:1]
    inside = bool(np.einsum("ij,ij->i", d, d)[0] <= 1.0)
    i, j = neighbour_pairs(x, 1.0)
    assert len(i) == int(inside)
    # (the same pair among many others: the dense blocks' sums take another order)
    rng = np.random.default_rng(6)
    cloud = np.concatenate([x, rng.uniform(5.0, 9.0, (400, 3))])
    i, j = neighbour_pairs(cloud, 1.0)
    assert (((i == 0) & (j == 1)) | ((i == 1) & (j == 0))).sum() == int(inside)
    assert len(neighbour_pairs(np.zeros((0, 3)), 1.0)[0]) == 0


def test_a_crowded_cell_is_searched_in_parts_and_too_many_pairs_are_refused():
    """3,000 points in one cell (4.5 million pairs, more than one batch): every pair comes out
    once; past the limit the search refuses with the number of pairs."""
    rng = np.random.default_rng(4)
    x = rng.random((3000, 3)) * 0.5
    i, j = neighbour_pairs(x, 1.0)
    assert len(i) == 3000 * 2999 // 2
    assert len(set((np.minimum(i, j) * 3000 + np.maximum(i, j)).tolist())) == len(i)
    with pytest.raises(ValueError, match="4,498,500 point pairs lie within 1 m"):
        neighbour_pairs(x, 1.0, limit=1_000_000)


# -- gravity ------------------------------------------------------------------------------------

def test_two_body_circular_orbit_period():
    """Two equal masses D apart, each at v = sqrt(G m / (2 D)) across the line between them:
    a circular orbit of period 2 pi sqrt(D^3 / (2 G m)); measured within 0.5 %."""
    G, m, D = 1.0, 2.0, 1.0
    v = math.sqrt(G * m / (2 * D))
    period = 2 * math.pi * math.sqrt(D ** 3 / (2 * G * m))
    model = particle_model(EmitterSettings("Stars"))
    state = model.state()
    place(state, [[-D / 2, 0, 0], [D / 2, 0, 0]], [[0, -v, 0], [0, v, 0]], mass=m)
    gravity = MutualGravity("Pull", G, softening=0.0, theta=0.0)
    dt = period / 200
    angles = []
    _run(model, state, [gravity], 260, dt, substeps=10,
         each=lambda f, s: angles.append(math.atan2(*(s.particle_x[1] - s.particle_x[0])[1::-1])))
    unwrapped = np.unwrap(angles)
    t = (np.arange(len(angles)) + 1) * dt
    k = int(np.argmax(unwrapped >= unwrapped[0] + 2 * math.pi))
    crossed = np.interp(unwrapped[0] + 2 * math.pi, unwrapped[k - 1:k + 1], t[k - 1:k + 1])
    assert crossed - t[0] == pytest.approx(period, rel=5e-3)
    sep = np.linalg.norm(state.particle_x[1] - state.particle_x[0])
    assert sep == pytest.approx(D, rel=1e-2)  # still circular


def _cloud(n: int = 1000):
    rng = np.random.default_rng(7)
    model = particle_model(EmitterSettings("Cloud"))
    state = model.state()
    place(state, rng.normal(size=(n, 3)), 0.3 * rng.normal(size=(n, 3)))
    state.particle_mass[:] = rng.uniform(0.5, 1.5, n)
    return model, state


def _energy(s, G: float, eps: float) -> float:
    m, x = s.particle_mass, s.particle_x
    i, j = np.triu_indices(len(m), 1)
    r = np.sqrt(((x[i] - x[j]) ** 2).sum(1) + eps * eps)
    return 0.5 * (m * (s.particle_v ** 2).sum(1)).sum() - G * (m[i] * m[j] / r).sum()


def test_a_cloud_keeps_its_momentum_and_angular_momentum():
    """1,000 bodies under the exact sum (equal and opposite pairs) and symplectic Euler:
    momentum and angular momentum change by rounding only (1e-9 relative); the energy error
    over a second is first order in the step (halving the step halves it) and small."""
    G, eps = 1e-3, 0.1
    gravity = MutualGravity("Pull", G, softening=eps, theta=0.0)

    def totals(s):
        p = (s.particle_mass[:, None] * s.particle_v).sum(axis=0)
        ang = np.cross(s.particle_x, s.particle_mass[:, None] * s.particle_v).sum(axis=0)
        return p, ang

    model, state = _cloud()
    p0, l0 = totals(state)
    e0 = _energy(state, G, eps)
    scale_p = (state.particle_mass[:, None] * np.abs(state.particle_v)).sum()
    scale_l = (np.linalg.norm(state.particle_x, axis=1) * state.particle_mass
               * np.linalg.norm(state.particle_v, axis=1)).sum()
    _run(model, state, [gravity], 20, 0.05)
    p1, l1 = totals(state)
    assert np.abs(p1 - p0).max() < 1e-9 * scale_p
    assert np.abs(l1 - l0).max() < 1e-9 * scale_l
    drift = abs(_energy(state, G, eps) - e0)
    assert drift < 2e-3 * abs(e0)
    model, state = _cloud()
    _run(model, state, [gravity], 40, 0.025)
    assert abs(_energy(state, G, eps) - e0) == pytest.approx(drift / 2, rel=0.1)


@pytest.mark.parametrize("shape", ["ball", "disk"])
def test_barnes_hut_error_below_one_percent_at_theta_half(shape):
    """The tree code's force field against the exact sum: RMS relative error under 1 % at
    theta 0.5, smaller at 0.3 (it converges to the sum)."""
    rng = np.random.default_rng(11)
    n = 6000
    x = rng.normal(size=(n, 3))
    if shape == "disk":
        x[:, 2] *= 0.05
    m = rng.uniform(0.5, 1.5, n)
    exact = bh.exact_accelerations(x, m, 1.0, 0.01)
    errors = {}
    for theta in (0.3, 0.5):
        a = bh.Octree(x, m).accelerations(1.0, 0.01, theta)
        errors[theta] = math.sqrt(((a - exact) ** 2).sum() / (exact ** 2).sum())
    assert errors[0.5] < 0.01
    assert errors[0.3] < errors[0.5]
    assert bh.accelerations(x[:500], m[:500], 1.0, 0.01, 0.5) == pytest.approx(
        bh.exact_accelerations(x[:500], m[:500], 1.0, 0.01))  # few points: the exact sum


def test_a_crowded_traversal_takes_fewer_groups_at_once_to_the_same_accelerations(monkeypatch):
    """A small opening angle opens nearly every node for every group: the traversal then takes
    fewer groups at a time (its frontier held under FRONTIER_LIMIT) and every point's
    acceleration is the same to the bit (each group's sources in the same order)."""
    rng = np.random.default_rng(3)
    x = rng.normal(size=(4000, 3))
    m = rng.uniform(0.5, 1.5, len(x))
    whole = bh.Octree(x, m).accelerations(1.0, 0.01, 0.05)
    frontiers = []
    interactions = bh.Octree.interactions

    def watched(self, theta, groups=None):
        try:
            return interactions(self, theta, groups)
        except bh.TooManyInteractions as exc:
            frontiers.append(exc.interactions)
            raise

    monkeypatch.setattr(bh, "FRONTIER_LIMIT", 3000)
    monkeypatch.setattr(bh.Octree, "interactions", watched)
    parts = bh.Octree(x, m).accelerations(1.0, 0.01, 0.05)
    assert frontiers and min(frontiers) > 3000  # it did split
    assert np.array_equal(parts, whole)


def test_dense_blocks_of_any_size_give_the_same_accelerations(monkeypatch):
    """Each bucket's points meet its sources in dense blocks of buckets with like source
    counts: however few or many buckets a block holds, every point's acceleration is the same
    to the bit, and it is the sum over its sources computed pair by pair (to rounding) — the
    tree's own far nodes and near points, each source once. Points stacked on one place with
    no softening pull each other along no axis (no NaN)."""
    rng = np.random.default_rng(5)
    x = rng.normal(size=(3000, 3))
    x[100:100 + bh.LEAF_SIZE + 8] = x[100]  # more points at one place than a bucket holds
    m = rng.uniform(0.5, 1.5, len(x))
    tree = bh.Octree(x, m)
    assert tree.node_count[tree.groups].max() > bh.LEAF_SIZE  # (their cell's bucket)
    big = tree.accelerations(1.0, 0.0, 0.5)
    monkeypatch.setattr(bh, "BLOCK", 64)  # one bucket per block
    small = bh.Octree(x, m).accelerations(1.0, 0.0, 0.5)
    assert np.isfinite(big).all()
    assert np.array_equal(small, big)
    # the same sources pair by pair: each bucket's far nodes' monopoles and near points
    (far_g, far_n), (near_g, near_l) = tree.interactions(0.5)
    expected = np.zeros_like(x)
    for g in range(len(tree.groups)):
        s, c = tree.node_start[tree.groups[g]], tree.node_count[tree.groups[g]]
        near = [np.arange(tree.node_start[k], tree.node_start[k] + tree.node_count[k])
                for k in near_l[near_g == g]]
        sx = np.concatenate([tree.node_com[far_n[far_g == g]], *(tree.x[i] for i in near)])
        sm = np.concatenate([tree.node_mass[far_n[far_g == g]], *(tree.m[i] for i in near)])
        d = sx[None] - tree.x[s:s + c, None]
        r2 = (d * d).sum(axis=2)
        with np.errstate(divide="ignore", invalid="ignore"):
            w = np.where(r2 > 0.0, sm / (r2 * np.sqrt(r2)), 0.0)
        expected[tree.order[s:s + c]] = (d * w[..., None]).sum(axis=1)
    assert big == pytest.approx(expected, rel=1e-12, abs=1e-9)


def test_a_bucket_s_sums_do_not_depend_on_its_block(monkeypatch):
    """A bucket of three points with 9,000 sources (more than numpy's einsum sums alike in
    every shape): met in one block, or a point at a time (a bucket bigger than a block), each
    point's acceleration is the same to the bit."""
    rng = np.random.default_rng(8)
    x = rng.normal(size=(3, 3))
    sources = np.concatenate([rng.normal(size=(9000, 3)) * 10.0, rng.uniform(0.5, 1.5, (9000, 1))],
                             axis=1)
    tables = np.concatenate([sources, [[bh.PAD_AWAY] * 3 + [0.0]]])
    args = (x, np.array([0]), np.array([3]), tables, np.arange(9000), np.array([9000]), 1.0,
            0.01)
    whole, sliced = np.zeros((3, 3)), np.zeros((3, 3))
    bh._pull_groups(whole, *args)
    monkeypatch.setattr(bh, "BLOCK", 100)  # a block too small for even one point's sources
    bh._pull_groups(sliced, *args)
    assert np.array_equal(whole, sliced)
    d = sources[None, :, :3] - x[:, None]
    r2 = (d * d).sum(axis=2) + 0.01 ** 2
    assert whole == pytest.approx((d * (sources[:, 3] / r2 ** 1.5)[..., None]).sum(axis=1),
                                  rel=1e-12)


def test_an_opening_angle_too_small_for_the_point_count_is_refused_naming_the_force(
        monkeypatch):
    """Nearly the exact sum over many points (a tiny opening angle) would take days a step at
    240,000 points, and its lists filled the memory: it is refused up front, naming the
    force, the interactions it would take and what to change (the limit lowered here so a
    small cloud reaches it)."""
    from physanim.core.errors import PhysanimError

    monkeypatch.setattr(bh, "MAX_INTERACTIONS", 2_000_000)  # (theta 1 takes 1.2 million here)
    monkeypatch.setattr(bh, "PER_BODY", 100)
    rng = np.random.default_rng(5)
    x = rng.normal(size=(3000, 3))
    m = np.ones(len(x))
    with pytest.raises(bh.TooManyInteractions) as caught:
        bh.accelerations(x, m, 1.0, 0.01, 1e-3)
    assert caught.value.interactions > 2_000_000
    bh.accelerations(x, m, 1.0, 0.01, 1.0)  # a wide angle stays within it
    model = particle_model(EmitterSettings("Stars"))
    state = model.state()
    place(state, x, np.zeros_like(x))
    with pytest.raises(PhysanimError, match=r'force "Pull" at frame \d+: .*Opening Angle 0.001 '
                                            r"over 3,000 particles .* raise the Opening Angle"):
        _run(model, state, [MutualGravity("Pull", 1.0, 0.01, 1e-3)], 1, 0.05)


# -- Lennard-Jones ------------------------------------------------------------------------------

def test_lennard_jones_pair_oscillates_about_its_minimum():
    """Two particles released near r* = 2^(1/6) sigma oscillate about it, at the harmonic
    period 2 pi sqrt(mu / U''(r*)) for a small amplitude (within 2 %), energy kept."""
    sigma, eps, m = 0.1, 0.05, 0.1
    lj = LennardJones("Drops", sigma, eps, 2.5 * sigma, softness=0.0)  # the hard 12-6 core
    r_star = 2 ** (1 / 6) * sigma
    assert lj.minimum == pytest.approx(r_star)
    k = 36 * 2 ** (2 / 3) * eps / sigma ** 2  # U''(r*)
    mu = m / 2
    period = 2 * math.pi * math.sqrt(mu / k)
    model = particle_model(EmitterSettings("Drops"))
    state = model.state()
    r0 = 1.01 * r_star
    place(state, [[0, 0, 0], [r0, 0, 0]], [[0, 0, 0], [0, 0, 0]], mass=m)
    dt = period / 40
    seps = []
    _run(model, state, [lj], 200, dt, substeps=10,
         each=lambda f, s: seps.append(s.particle_x[1, 0] - s.particle_x[0, 0]))
    seps = np.array(seps)
    assert seps.min() < r_star < seps.max()
    assert seps.max() == pytest.approx(r0, rel=1e-3)  # energy: it comes back to where it began
    peaks = np.flatnonzero((seps[1:-1] > seps[:-2]) & (seps[1:-1] >= seps[2:])) + 1
    measured = np.diff(peaks).mean() * dt
    assert measured == pytest.approx(period, rel=0.02)
    v = lj.energy(np.array([r_star, 2.5 * sigma, 3 * sigma]))
    assert v[0] < 0 and v[1] == v[2] == 0.0


def test_lennard_jones_cloud_condenses_into_a_droplet():
    """A loose cube of particles with drag (it sheds heat) and the hard 12-6 core pulls into
    one round drop: nearly all in one cluster (a few evaporate as it heats up collapsing),
    neighbours at 2^(1/6) sigma, no pair closer than sigma, the cloud rounder."""
    rng = np.random.default_rng(5)
    sigma = 0.1
    side = (np.arange(7) - 3.0) * 1.3 * sigma  # a loose lattice, jittered: nothing overlaps
    grid = np.stack(np.meshgrid(side, side, side), axis=-1).reshape(-1, 3)
    n = len(grid)
    model = particle_model(EmitterSettings("Mist"))
    state = model.state()
    place(state, grid + rng.uniform(-0.01, 0.01, grid.shape), np.zeros((n, 3)), mass=0.1)
    lj = LennardJones("Cling", sigma, 0.05, 2.5 * sigma, softness=0.0)
    steps = math.ceil((1 / 24) / lj.max_step(0.1))
    _run(model, state, [lj], 150, 1 / 24, substeps=steps, forces=[Drag("Air", 0.05)])
    x = state.particle_x
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    reach = d < 1.5 * sigma  # bonded; the cluster of particle 0 by repeated reach
    seen = reach[np.argmin(np.linalg.norm(x - np.median(x, axis=0), axis=1))].copy()
    for _ in range(n):
        grown = reach[seen].any(axis=0)
        if (grown == seen).all():
            break
        seen = grown
    assert seen.sum() >= 0.9 * n
    drop = x[seen]
    nearest = (d[np.ix_(seen, seen)] + np.eye(int(seen.sum())) * 1e9).min(axis=1)
    assert np.median(nearest) == pytest.approx(lj.minimum, rel=0.06)
    assert nearest.min() > 0.85 * sigma
    r = np.linalg.norm(drop - drop.mean(0), axis=1)
    r0 = np.linalg.norm(grid - grid.mean(0), axis=1)
    assert r.max() / r.mean() < r0.max() / r0.mean()  # the cube's corners pulled in


# -- Coulomb ------------------------------------------------------------------------------------

def test_like_charges_fly_apart_with_the_coulomb_energy():
    """Two like charges released at r0: at separation r their relative speed satisfies
    mu v^2 / 2 = k q^2 (1 / r0 - 1 / r) (within 0.5 %); unlike charges close in."""
    k, q, m, r0 = 1.0, 0.2, 0.1, 0.1
    mu = m / 2
    coulomb = Coulomb("Charge", k, cutoff=10.0, softening=0.0, charges=(q,))
    model = particle_model(EmitterSettings("Ions"))
    state = model.state()
    place(state, [[0, 0, 0], [r0, 0, 0]], [[0, 0, 0], [0, 0, 0]], mass=m)
    _run(model, state, [coulomb], 40, 1 / 24, substeps=50, integrator="RK4")
    r = state.particle_x[1, 0] - state.particle_x[0, 0]
    v = state.particle_v[1, 0] - state.particle_v[0, 0]
    assert r > 2 * r0
    assert 0.5 * mu * v * v == pytest.approx(k * q * q * (1 / r0 - 1 / r), rel=5e-3)
    unlike = Coulomb("Charge", k, cutoff=10.0, softening=0.01, charges=(q, -q))
    model = particle_model(EmitterSettings("Plus"), EmitterSettings("Minus"))
    state = model.state()
    place(state, [[0, 0, 0]], [[0, 0, 0]], emitter=0, mass=m)
    place(state, [[r0, 0, 0]], [[0, 0, 0]], emitter=1, mass=m)
    _run(model, state, [unlike], 1, 1 / 240, substeps=10)
    assert state.particle_x[1, 0] - state.particle_x[0, 0] < r0


def test_only_the_named_emitters_take_part():
    """Gravity among emitter 0's particles leaves emitter 1's alone (and they feel none)."""
    model = particle_model(EmitterSettings("A"), EmitterSettings("B"))
    state = model.state()
    place(state, [[0, 0, 0], [1, 0, 0]], np.zeros((2, 3)), emitter=0)
    place(state, [[0, 1, 0], [1, 1, 0]], np.zeros((2, 3)), emitter=1)
    gravity = MutualGravity("Pull", 1.0, 0.01, 0.0, emitters=(0,))
    _run(model, state, [gravity], 1, 0.1)
    assert np.abs(state.particle_v[:2, 0]).min() > 0.0
    assert np.array_equal(state.particle_v[2:], np.zeros((2, 3)))


@pytest.mark.parametrize("make", [lambda: MutualGravity("G", softening=-1.0),
                                  lambda: LennardJones("L", sigma=0.2, cutoff=0.1),
                                  lambda: Coulomb("C", cutoff=0.0),
                                  lambda: MutualGravity("G", theta=float("nan"))])
def test_bad_settings_name_the_force(make):
    with pytest.raises(ValueError, match='force "'):
        make()


def test_a_too_stiff_lennard_jones_stops_up_front_naming_the_substeps_it_needs():
    from physanim.core.errors import PhysanimError

    model = particle_model(EmitterSettings("Mist"))
    state = model.state()
    place(state, [[0, 0, 0], [0.11, 0, 0]], np.zeros((2, 3)), mass=0.1)
    lj = LennardJones("Cling", 0.1, 0.05, 0.25)
    with pytest.raises(PhysanimError, match=r'force "Cling" at frame 0: too stiff .* raise the '
                                            r"scene's Substeps to 9"):
        _run(model, state, [lj], 1, 1 / 24, substeps=2)
    _run(model, state, [LennardJones("Cling")], 24, 1 / 24, substeps=2)  # the defaults run
    assert np.isfinite(state.particle_x).all()
