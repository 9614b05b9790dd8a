"""The assembled block-sparse matrix of the implicit solve and its multigrid preconditioner.

References are independent: a dense matrix filled block by block in plain Python loops, and
numpy's dense linear algebra.
"""
from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest
from physanim.core.springs import (
    SpringFrameInputs,
    SpringMeshBuilder,
    SpringMeshSettings,
    SpringMeshSolver,
    topology,
)
from physanim.core.springs.bdf2 import BDF2
from physanim.core.springs.implicit import BaraffWitkin
from physanim.core.springs.multigrid import (
    DIRECT_LIMIT,
    AggregationHierarchy,
    aggregate,
)
from physanim.core.springs.sparse import BlockMatrix, BlockPattern, MatrixBuilder
from physanim.tests.core.helpers import grid as _grid


def _symmetric(rng, count: int) -> np.ndarray:
    m = rng.normal(size=(count, 3, 3))
    return m + m.transpose(0, 2, 1)


def _random_terms(seed: int):
    """A 7 x 6 grid's springs (some listed twice, some reversed) and hinges, random blocks."""
    rng = np.random.default_rng(seed)
    x, edges, tris, *_ = _grid(7, 6)
    n = len(x)
    pairs = topology.unique_pairs(edges)
    pairs = np.concatenate([pairs, pairs[rng.choice(len(pairs), 9, replace=False)]])
    flip = rng.random(len(pairs)) < 0.5
    pairs[flip] = pairs[flip][:, ::-1]
    hinge = topology.hinges(tris)
    return (n, pairs, _symmetric(rng, len(pairs)), hinge, rng.normal(size=(len(hinge), 4, 3)),
            float(rng.normal()), rng.integers(0, n, 30), _symmetric(rng, 30))


def _dense(n, pairs, blocks, hinge, grad, c, index, values) -> np.ndarray:
    dense = np.zeros((3 * n, 3 * n))

    def add(r: int, col: int, block: np.ndarray) -> None:
        dense[3 * r:3 * r + 3, 3 * col:3 * col + 3] += block

    for (i, j), block in zip(pairs, blocks):
        add(i, i, block)
        add(j, j, block)
        add(i, j, -block)
        add(j, i, -block)
    for h in range(len(hinge)):
        for a in range(4):
            for b in range(4):
                add(hinge[h, a], hinge[h, b], c * np.outer(grad[h, a], grad[h, b]))
    for v, block in zip(index, values):
        add(v, v, block)
    return dense


@pytest.mark.parametrize("seed", range(5))
def test_assembled_matrix_equals_a_dense_reference(seed):
    n, pairs, blocks, hinge, grad, c, index, values = _random_terms(seed)
    pattern = BlockPattern(n, [pairs, hinge])
    builder = MatrixBuilder(pattern)
    builder.add_pairs(pairs, blocks)
    builder.add_rank_one(hinge, grad, c)
    builder.add_diagonal(index, values)
    matrix = builder.finish()
    dense = _dense(n, pairs, blocks, hinge, grad, c, index, values)
    u = np.random.default_rng(seed + 100).normal(size=(n, 3))
    np.testing.assert_allclose(matrix @ u, (dense @ u.ravel()).reshape(n, 3), atol=1e-12)
    diagonal = np.stack([dense[3 * v:3 * v + 3, 3 * v:3 * v + 3] for v in range(n)])
    np.testing.assert_allclose(matrix.diagonal(), diagonal, atol=1e-12)
    # a saved bake state's matrix multiplies the same (its work buffer is not saved; one saved
    # by an older version, in another shape, is made anew)
    expected = matrix @ u
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(matrix)) @ u, expected)
    old = copy.copy(matrix.__dict__)
    old["_gathered"] = np.empty((n, 3 * pattern.width))
    restored = BlockMatrix.__new__(BlockMatrix)
    restored.__setstate__(old)
    np.testing.assert_array_equal(restored @ u, expected)
    # a reused buffer starts from zero again
    again = MatrixBuilder(pattern, out=matrix.data.ravel())
    again.add_pairs(pairs, blocks)
    np.testing.assert_allclose(again.finish() @ u,
                               (_dense(n, pairs, blocks, hinge[:0], grad[:0], c, [], [])
                                @ u.ravel()).reshape(n, 3), atol=1e-12)


def test_pattern_rejects_terms_outside_it_and_degenerate_pairs():
    pattern = BlockPattern(4, [np.array([[0, 1], [1, 2]])])
    with pytest.raises(ValueError, match="outside the block pattern"):
        MatrixBuilder(pattern).add_pairs(np.array([[0, 3]]), np.eye(3)[None])
    with pytest.raises(ValueError, match="two different vertices"):
        MatrixBuilder(BlockPattern(4, [np.array([[2, 2]])])).add_pairs(
            np.array([[2, 2]]), np.eye(3)[None])


def _stiff_grid(count: int, stiffness: float):
    x, edges, tris, ls, lt, lv = _grid(count, count)
    pin = np.zeros(count * count)
    pin[[count * (count - 1), count * count - 1]] = 1.0
    settings = SpringMeshSettings("Sheet", mass=1.0, stiffness=stiffness, damping=1.0,
                                  shear_stiffness=stiffness / 2, shear_damping=0.5)
    return SpringMeshBuilder(settings, x, edges, tris, ls, lt, lv, pin_weight=pin).finalize(1)


def _system_matrix(model, h: float = 1 / 24):
    """A = M - h df/dv - h^2 df/dx of the model at rest, through the solver's own pieces."""
    solver = SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=h)
    from physanim.core.forces import ParticleView
    view = ParticleView(model.rest_x, np.zeros_like(model.rest_x), model.vertex_mass, 0.0)
    blocks = [solver.springs.linearize(view), solver.bending.linearize(view)]
    return solver.integrator._assemble(blocks, model.vertex_mass, h), solver.integrator


def test_multigrid_preconditioner_is_symmetric_positive_definite():
    model = _stiff_grid(40, 1e5)
    matrix, integrator = _system_matrix(model)
    hierarchy = integrator._pattern[2]
    assert len(hierarchy.levels) == 2  # 1600 vertices -> ~180 (V-cycle) -> ~20 (direct)
    apply = hierarchy.preconditioner(matrix)
    rng = np.random.default_rng(3)
    for _ in range(5):
        u, v = rng.normal(size=(2, 1600, 3))
        pu, pv = apply(u), apply(v)
        assert np.vdot(v, pu) == pytest.approx(np.vdot(u, pv), rel=1e-10)
        assert np.vdot(u, pu) > 0.0


def test_aggregation_covers_every_vertex_and_coarsens_a_grid():
    _x, edges, *_ = _grid(20, 20)
    pattern = BlockPattern(400, [topology.unique_pairs(edges)])
    owner, count = aggregate(pattern.neighbours)
    assert owner.min() == 0 and owner.max() == count - 1
    assert np.all(np.bincount(owner, minlength=count) >= 1)
    assert 400 / count >= 3.0  # a vertex and its untaken neighbours
    # every aggregate is connected through its own members (a vertex and its neighbours)
    for a in range(count):
        members = np.nonzero(owner == a)[0]
        linked = np.isin(pattern.neighbours[members], members).sum(axis=1) > 1
        assert linked.all() or len(members) == 1


def test_loose_vertices_fall_back_to_jacobi_beyond_the_direct_limit():
    n = DIRECT_LIMIT + 100
    pattern = BlockPattern(n, [])
    builder = MatrixBuilder(pattern)
    rng = np.random.default_rng(0)
    a = rng.normal(size=(n, 3, 3))
    blocks = np.matmul(a, a.transpose(0, 2, 1)) + np.eye(3)
    builder.add_diagonal(np.arange(n), blocks)
    matrix = builder.finish()
    hierarchy = AggregationHierarchy(pattern)
    assert hierarchy.levels == []  # nothing to aggregate along
    r = rng.normal(size=(n, 3))
    np.testing.assert_allclose(hierarchy.preconditioner(matrix)(r),
                               np.linalg.solve(blocks, r[:, :, None])[:, :, 0], rtol=1e-9)


def _frames(model, frames: int, substeps: int = 1, **integrator):
    """The model baked implicitly at 24 fps (``integrator``: BaraffWitkin's arguments): yields
    the solver and the state after each frame."""
    solver = SpringMeshSolver(model, "IMPLICIT", substeps, frame_dt=1 / 24, frame=1)
    solver.integrator = BaraffWitkin(**integrator)
    state = model.state()
    for frame in range(1, frames + 1):
        solver.advance(state, SpringFrameInputs(frame, (frame - 1) / 24, 1 / 24))
        yield solver, state


def _run(model, frames: int, **integrator):
    iterations, residual = 0, 0.0
    for solver, state in _frames(model, frames, **integrator):
        iterations += solver.integrator.last_iterations
        residual = max(residual, solver.integrator.last_residual)
        x = state.x
    return x, iterations, residual


def test_multigrid_solves_a_stiff_sheet_block_jacobi_cannot_within_the_cap():
    """A 30 x 30 sheet, k = 1e5 N/m on 1.1 g vertices (h^2 k / m = 1.6e5), pinned at two
    corners, 8 frames at one step each. Reference: both preconditioners solved to 1e-7 — they
    agree, and block Jacobi needs over 3x the iterations. At a tolerance of 1e-3 (BDF2's; implicit
    Euler's default 1e-2 is within block Jacobi's reach too) and the default cap,
    multigrid meets the tolerance and stays within a few tolerances of the reference (a
    relative residual rho moves the step by about rho of the distance travelled), while block
    Jacobi runs into its cap, short of the tolerance and over 5x farther from the reference."""
    model = _stiff_grid(30, 1e5)
    tight = {"tolerance": 1e-7, "max_iterations": 20000}
    reference, jacobi_tight, _ = _run(model, 8, preconditioner="JACOBI", **tight)
    multigrid_ref, multigrid_tight, _ = _run(model, 8, preconditioner="MULTIGRID", **tight)
    fallen = np.abs(reference - model.rest_x).max()
    assert fallen > 0.5
    assert np.abs(multigrid_ref - reference).max() < 1e-5 * fallen
    assert 3 * multigrid_tight <= jacobi_tight, (multigrid_tight, jacobi_tight)

    tolerance = BDF2.TOLERANCE
    x, iterations, residual = _run(model, 8, preconditioner="MULTIGRID", tolerance=tolerance)
    assert residual <= 3 * tolerance
    error = np.abs(x - reference).max()
    assert error < 5 * tolerance * fallen
    capped, capped_iterations, residual = _run(model, 8, preconditioner="JACOBI",
                                               tolerance=tolerance)
    assert residual > 5 * tolerance  # what multigrid is for
    assert capped_iterations >= 3 * iterations
    assert np.abs(capped - reference).max() > 5 * error


def test_unknown_preconditioner_is_refused():
    with pytest.raises(ValueError, match="preconditioner"):
        BaraffWitkin(preconditioner="ILU")


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("normals", ["one", "each", "none", "axis", "axes"])
def test_filtered_matrix_equals_s_a_s_plus_i_minus_s(seed, normals):
    """What the implicit step's preconditioner is built from: S A S + (I - S), S removing each
    pinned vertex's motion and each pressed vertex's normal — the same whether the pressed
    vertices share one normal (a flat ground: its own faster path), each have a coordinate
    axis as theirs (S diagonal: its own faster path, ground and box faces) or not."""
    from physanim.core.springs.implicit import BaraffWitkin

    n, pairs, blocks, hinge, grad, c, index, values = _random_terms(seed)
    builder = MatrixBuilder(BlockPattern(n, [pairs, hinge]))
    builder.add_pairs(pairs, blocks)
    builder.add_rank_one(hinge, grad, c)
    builder.add_diagonal(index, values)
    matrix = builder.finish()
    dense = _dense(n, pairs, blocks, hinge, grad, c, index, values)
    rng = np.random.default_rng(seed + 7)
    free = rng.random(n) > 0.2
    pressed = np.zeros(0, np.int64) if normals == "none" else \
        np.nonzero(free & (rng.random(n) > 0.4))[0]
    normal = rng.normal(size=(len(pressed), 3)) if normals == "each" else \
        np.tile(rng.normal(size=3), (len(pressed), 1))
    if normals in ("axis", "axes"):  # -z as on a ceiling, or any of +-x, +-y, +-z
        axes = np.concatenate([np.eye(3), -np.eye(3)])
        normal = axes[np.full(len(pressed), 5) if normals == "axis" else
                      rng.integers(0, 6, len(pressed))]
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    s = np.zeros((3 * n, 3 * n))
    for v in range(n):
        s[3 * v:3 * v + 3, 3 * v:3 * v + 3] = np.eye(3) * free[v]
    for v, nv in zip(pressed, normal):
        s[3 * v:3 * v + 3, 3 * v:3 * v + 3] -= np.outer(nv, nv)
    expected = s @ dense @ s + np.eye(3 * n) - s
    filtered = BaraffWitkin._filtered(matrix, free.copy(), pressed, normal)
    u = rng.normal(size=(n, 3))
    np.testing.assert_allclose(filtered @ u, (expected @ u.ravel()).reshape(n, 3), atol=1e-10)
    np.testing.assert_allclose(matrix @ u, (dense @ u.ravel()).reshape(n, 3), atol=1e-12)
    # the step's projection applies the same S to vectors, by its diagonal where S is one
    from physanim.core.springs.implicit_parts import VelocityFilter, diagonal_filter

    diagonal = diagonal_filter(free, pressed, normal)
    assert (diagonal is not None) == (normals in ("axis", "axes"))
    general = VelocityFilter(np.zeros((n, 3)), free[:, None].astype(float), pressed, normal,
                             None)
    fast = VelocityFilter(np.zeros((n, 3)), free[:, None].astype(float), pressed, normal, None,
                          diagonal)
    expected_su = (s @ u.ravel()).reshape(n, 3)
    np.testing.assert_allclose(general.project(u.copy()), expected_su, atol=1e-14)
    np.testing.assert_array_equal(fast.project(u.copy()), general.project(u.copy()))


def test_matrix_free_product_equals_the_assembled_matrix():
    """A step with nothing free (every vertex pinned or held by static friction) multiplies by
    A from the Jacobian blocks without assembling it: the same products, to rounding."""
    from physanim.core.forces import ParticleView
    from physanim.core.springs.implicit_parts import MatrixFree

    model = _stiff_grid(12, 3e4)
    rng = np.random.default_rng(5)
    x = model.rest_x + rng.normal(scale=0.02, size=model.rest_x.shape)  # stretched, bent
    view = ParticleView(x, rng.normal(size=x.shape), model.vertex_mass, 0.0)
    solver = SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=1 / 24)
    blocks = [solver.springs.linearize(view), solver.bending.linearize(view)]
    h = 1 / 48
    matrix = solver.integrator._assemble(blocks, model.vertex_mass, h)
    free = MatrixFree(blocks, model.vertex_mass, h)
    for _ in range(3):
        u = rng.normal(size=x.shape)
        product = matrix @ u
        np.testing.assert_allclose(free(u), product, rtol=0, atol=1e-12 * np.abs(product).max())


def _swing(model, frames: int, substeps: int, tolerance: float | None):
    return np.array([state.x.copy() for _, state in
                     _frames(model, frames, substeps, tolerance=tolerance)])


def test_the_default_solve_errs_far_less_than_implicit_euler_itself():
    """Implicit Euler's CG stops at TOLERANCE (1e-2, as Blender's cloth solver) because the
    step's own error is far larger: a 12 x 12 sheet at the default stiffness, pinned at two
    corners, swinging for half a second at the default 2 sub-steps per frame, keeps within a
    two-hundredth of that error of its exactly solved path (the error: the exactly solved
    path's distance from one at 16 sub-steps; 0.0005 of it at 1e-3, 0.003 at 1e-2, 0.0055 at
    3e-2, 0.07 at 0.3: a looser default fails here)."""
    model = _stiff_grid(12, 2000.0)
    default = _swing(model, 12, 2, None)
    exact = _swing(model, 12, 2, 1e-10)
    finer = _swing(model, 12, 16, 1e-10)
    own = np.abs(exact - finer).max()
    assert own > 0.05  # [m]: the swing is under way
    assert np.abs(default - exact).max() < 0.005 * own
