"""What the Baraff-Witkin stepper (:mod:`.implicit`) asks of a system and the records one step
passes between its passes: the velocity filter (pins and contacts), the linear system and its
products (matrix-free, block Jacobi), the Newton result, the solve pattern, and the memory
carried from step to step."""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, NamedTuple, Protocol

import numpy as np

from ..integrators import System
from ..integrators.krylov import Product
from ..transforms import inverse3, scale_rows, transform_vectors
from .multigrid import AggregationHierarchy
from .sparse import BlockMatrix, BlockPattern, MatrixBuilder

if TYPE_CHECKING:
    from ..contact import Contacts


class JacobianBlocks(Protocol):
    """One force's Jacobian at one state, as 3 x 3 blocks (what ``linearize`` returns a list of;
    :mod:`physanim.core.forces.springs`, :mod:`.forces`)."""

    #: (m, k) the fixed index array of the vertices each row couples, or None (per-vertex blocks)
    clique: np.ndarray | None

    def add_to(self, builder: MatrixBuilder, cx: float, cv: float) -> None:
        """Put ``cx df/dx + cv df/dv`` into an assembled matrix."""

    def product(self, cx: float, cv: float, u: np.ndarray, out: np.ndarray) -> None:
        """``out += (cx df/dx + cv df/dv) u``, matrix-free, u and out (n, 3)."""


class BaraffWitkinSystem(System, Protocol):
    """What :class:`BaraffWitkin` steps: a :class:`~physanim.core.integrators.System` whose state
    is ``y = [x.ravel(), v.ravel()]``, positions x and velocities v (n, 3), and that offers the
    forces and Jacobians at any state and the constraints of a step.

    Attributes:
        mass: (n,) vertex masses [kg]. free: (n,) bool, False for pinned vertices.
        contact: the vertices touching colliders (:class:`~physanim.core.contact.Contacts`,
            sorted by index): constrained to move with the surface along its normal while
            forces press them into it (or always, if ``held``).
        bodies: (b,) the colliders (as in ``contact.collider``) that are bodies taking the
            contacts' impulses back (two-way coupling): their contacts only push.
        coupled: vertices are attached to bodies that take their impulses back (two-way).
    """

    mass: np.ndarray
    free: np.ndarray
    contact: Contacts
    bodies: np.ndarray
    coupled: bool

    def pinned_velocity(self, t: float) -> np.ndarray:
        """(n, 3) velocity of the pinned vertices at ``t`` [m/s] (rows of free ones unused)."""

    def weight_norm(self) -> float:
        """|M g| [N]: the force scale residuals are judged against."""

    def forces_at(self, t: float, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(n, 3) total force [N] at time ``t`` [s] and state ``(x, v)``."""

    def linearize(self, t: float, x: np.ndarray, v: np.ndarray) -> list[JacobianBlocks]:
        """The Jacobian blocks of every force at ``(t, x, v)``."""

    def energy(self, x: np.ndarray, v: np.ndarray) -> float:
        """Total conserved energy [J] (what a step must not increase when nothing drives it)."""


@dataclass(frozen=True)
class VelocityFilter:
    """Baraff & Witkin's constraints on one step's velocity change dv (n, 3) [m/s]: pinned
    vertices have a prescribed change; vertices pressed onto a collider have a prescribed normal
    velocity (the surface's) and move freely along the surface — unless static friction holds
    them (``stuck``): then their whole velocity is prescribed, the surface's, as a pin's.

    Attributes:
        given: (n, 3) the prescribed part of dv [m/s] (zero in the free directions).
        free_scale: (n, 1) 1.0 for a free vertex, 0.0 for a pinned or stuck one.
        pressed: (k,) vertices held on a collider, with their unit normals ``normal`` (k, 3).
        contact: the step's contacts ``pressed`` was chosen from (friction reads them).
        diagonal: (n, 3) the filter's diagonal when it is one (:func:`diagonal_filter`: every
            pressed normal a coordinate axis, as on a ground), else None.
        stuck: (k,) bool, the pressed vertices static friction holds (None: none).
    """

    given: np.ndarray
    free_scale: np.ndarray
    pressed: np.ndarray
    normal: np.ndarray
    contact: Contacts
    diagonal: np.ndarray | None = None
    stuck: np.ndarray | None = None

    @property
    def free(self) -> np.ndarray:
        """(n,) bool: the vertices with a free direction (neither pinned nor stuck)."""
        return self.free_scale[:, 0] > 0.0

    @property
    def rows(self) -> np.ndarray:
        """(k,) each pressed vertex's row in ``contact`` (whose index is sorted)."""
        return np.searchsorted(self.contact.index, self.pressed)

    @property
    def sliding(self) -> np.ndarray:
        """(k,) bool: the pressed vertices free to slide along their surface."""
        return np.ones(len(self.pressed), bool) if self.stuck is None else ~self.stuck

    @cached_property
    def _scale(self) -> np.ndarray:
        """``free_scale`` as (n, 3): numpy multiplies an (n, 3) by an (n, 1) row by row, ten
        times slower than two (n, 3) arrays (every CG iteration projects)."""
        return np.repeat(self.free_scale, 3, axis=1)

    def project(self, u: np.ndarray) -> np.ndarray:
        """Remove the constrained directions, in place (callers pass fresh arrays)."""
        if self.diagonal is not None:  # one pass; the same values as the general route
            u *= self.diagonal
            return u
        u *= self._scale
        if len(self.pressed):
            un = np.einsum("ij,ij->i", u[self.pressed], self.normal)
            u[self.pressed] -= un[:, None] * self.normal
        return u


def diagonal_filter(free: np.ndarray, pressed: np.ndarray,
                    normal: np.ndarray) -> np.ndarray | None:
    """The filter S (I on a free vertex, 0 on a pinned one, I - n n^T on a pressed one) as its
    diagonal (n, 3) when it is diagonal: every pressed normal ``normal`` (k, 3) a coordinate axis
    (a ground, a box's faces), the common case; else None. S u is then ``diagonal * u``, with
    the same values as I - n n^T applied (for n = +-e_k, u - (u.n) n only zeroes u_k)."""
    if not len(pressed):
        return None
    nonzero = normal != 0.0
    if not ((nonzero.sum(axis=1) == 1) & (np.abs(normal).max(axis=1) == 1.0)).all():
        return None
    diagonal = np.repeat(free.astype(np.float64)[:, None], 3, axis=1)
    diagonal[pressed, np.argmax(nonzero, axis=1)] = 0.0
    return diagonal


@dataclass(frozen=True)
class Linearisation:
    """One linearisation of a step: ``A = M - h df/dv - h^2 df/dx`` (as its product), the
    right-hand side ``rhs`` (n, 3) [N s], the preconditioner CG solves it with and the
    assembled matrix (a :class:`~.sparse.BlockMatrix`; None when A is only a product)."""

    rhs: np.ndarray
    apply_a: Product
    precondition: Product
    matrix: BlockMatrix | None = None


@dataclass
class NewtonResult:
    """What the Newton iterations of one step leave for the passes after them.

    Attributes:
        dv: (n, 3) velocity change [m/s]. iterations: CG iterations spent.
        reaction: (n, 3) the constraints' impulses of the first solve [N s] (None: no solve).
        residual: (n, 3) A dv - rhs of the last solve [N s]: its constraints' impulses.
        last: the last linearisation (None: no solve). energy: the energy at the step's end
            when the Newton check computed it and accepted the step there, else None [J].
        scale: the size of the step's right-hand side [N s] its solves were relative to (the
            tolerance times this is the step's accuracy).
        first: the first linearisation's (Jacobian blocks, right-hand side, assembled matrix
            or None, its preconditioner or None): the same for a step solved again with other
            constraints (the preconditioner for looser ones).
    """

    dv: np.ndarray
    iterations: int = 0
    reaction: np.ndarray | None = None
    residual: np.ndarray | None = None
    last: Linearisation | None = None
    energy: float | None = None
    scale: float = 0.0
    first: tuple | None = None


class SolvePattern(NamedTuple):
    """The block pattern of a mesh's matrix and its multigrid hierarchy (None: block Jacobi),
    built from the cliques of the Jacobian blocks and kept while they stay the same arrays."""

    cliques: list
    pattern: BlockPattern
    hierarchy: AggregationHierarchy | None


@dataclass
class StepMemory:
    """What a :class:`BaraffWitkin` stepper carries from one step to the next; all of it only
    speeds the next step up.

    Attributes:
        warm: the last steps' solutions dv (n, 3), newest first (BaraffWitkin.WARM_HISTORY of
            them): the next first guess.
        warm_t: the step time [s] of ``warm[0]``.
        smooth: for each of them, whether its step pressed no vertex on a collider.
        end: ``(x, v, energy)`` at the end of the last step, when the Newton check computed it.
        friction: the last friction solve's correction to the velocities (n, 3), or None: the
            next one's first guess.
    """

    warm: list = field(default_factory=list)
    warm_t: float | None = None
    smooth: list = field(default_factory=list)
    end: tuple | None = None
    friction: np.ndarray | None = None


def positions_and_velocities(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Views ``(x, v)``, each (n, 3), of a spring mesh's flat state ``y = [x, v]`` (6 n,)."""
    n = y.shape[0] // 6
    if y.shape[0] != 6 * n:
        raise ValueError(f"a spring mesh's state has 6 values per vertex (got {y.shape[0]})")
    return y[:3 * n].reshape(n, 3), y[3 * n:].reshape(n, 3)


class MatrixFree:
    """u -> A u for A = M - h df/dv - h^2 df/dx from the Jacobian blocks themselves, without
    assembling A: for a step that only needs a product or two (every vertex pinned or held by
    static friction: a cloth at rest on the ground); a plain callable, as :class:`BlockJacobi`."""

    def __init__(self, blocks: list, mass: np.ndarray, h: float):
        self.blocks, self.mass, self.h = blocks, mass, h

    def __call__(self, u: np.ndarray) -> np.ndarray:
        out = scale_rows(u, self.mass)
        for blk in self.blocks:
            blk.product(-self.h * self.h, -self.h, u, out)
        return out


class BlockJacobi:
    """r -> D^-1 r with the inverse 3 x 3 diagonal blocks ``inverse`` (n, 3, 3); a plain
    callable (not a closure) so a bake's state can be saved and resumed."""

    def __init__(self, inverse: np.ndarray):
        self.inverse = inverse

    def __call__(self, r: np.ndarray) -> np.ndarray:
        return transform_vectors(self.inverse, r)

    def with_fine(self, vertices: np.ndarray, inverse: np.ndarray) -> BlockJacobi:
        """A copy with the inverse blocks at ``vertices`` (k,) replaced by ``inverse``."""
        out = self.inverse.copy()
        out[vertices] = inverse
        return BlockJacobi(out)


def filtered_diagonal(matrix, diagonal, constrained):
    """The implicit step's filtered matrix S A S + (I - S) (:func:`filtered_matrix`) for a
    diagonal S (``diagonal`` (n, 3)): (S_r B S_c)_ij = d_r,i B_ij d_c,j, two passes over the
    matrix."""
    p = matrix.pattern
    blocks = matrix.data.reshape(p.n, 3, p.width, 3) * diagonal[:, :, None, None]
    blocks *= diagonal[p.neighbours][:, None, :, :]
    fixed = np.nonzero(constrained)[0]
    slot = p.diagonal_slot[fixed] % p.width
    for i in range(3):  # + (I - S) on the constrained vertices' diagonal blocks
        blocks[fixed, i, slot, i] += 1.0 - diagonal[fixed, i]
    return BlockMatrix(p, blocks.reshape(matrix.data.shape))


def filtered_one_normal(matrix, free, pressed, n, constrained):
    """:func:`filtered_matrix` when every pressed vertex has the same normal ``n`` (3,): with
    S = f I - p n n^T per vertex (f: free, p: pressed), S_r B S_c = f_r f_c B
    - f_c p_r n (n^T B) - f_r p_c (B n) n^T + p_r p_c (n^T B n) n n^T, a few passes over
    the whole matrix instead of two 3 x 3 products per block (a third of the time)."""
    p = matrix.pattern
    if not len(pressed):  # pins only: S = 0 on them, I elsewhere; only their rows and
        data = matrix.data.copy()  # columns change (to zero, their diagonal blocks to I)
        blocks = data.reshape(p.n, 3, p.width, 3)
        row, col = np.nonzero(constrained[:, None] | constrained[p.neighbours])
        blocks[row, :, col, :] = 0.0
        fixed = np.nonzero(constrained)[0]
        blocks[fixed, :, p.diagonal_slot[fixed] % p.width, :] = np.eye(3)
        return BlockMatrix(p, data)
    f = free.astype(np.float64)
    pr = np.zeros(p.n)
    pr[pressed] = 1.0
    data = matrix.data.copy()
    blocks = data.reshape(p.n, 3, p.width, 3)  # [row, i, slot, j]
    fc, pc = f[p.neighbours], pr[p.neighbours]  # (n, width): each slot's column vertex
    nb = np.einsum("i,risj->rsj", n, blocks)  # n^T B
    bn = np.einsum("risj,j->ris", blocks, n)  # B n
    nbn = np.einsum("rsj,j->rs", nb, n) * (pr[:, None] * pc)
    nb *= (fc * pr[:, None])[:, :, None]
    bn *= (f[:, None] * pc)[:, None, :]
    blocks *= (f[:, None] * fc)[:, None, :, None]
    blocks -= n[None, :, None, None] * nb[:, None, :, :]
    blocks -= bn[:, :, :, None] * n[None, None, None, :]
    blocks += nbn[:, None, :, None] * np.outer(n, n)[None, :, None, :]
    fixed = np.nonzero(constrained)[0]
    s_fixed = f[fixed, None, None] * np.eye(3) - pr[fixed, None, None] * np.outer(n, n)
    blocks[fixed, :, p.diagonal_slot[fixed] % p.width, :] += np.eye(3) - s_fixed
    return BlockMatrix(p, data)


def filter_blocks(free: np.ndarray, pressed: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The filter S per vertex (n, 3, 3): I on a free vertex, 0 on a pinned or stuck one,
    I - n n^T on one pressed (``pressed`` (k,), ``normal`` (k, 3)) and free to slide."""
    s = np.where(free[:, None, None], np.eye(3), 0.0)
    if len(pressed):
        s[pressed] -= normal[:, :, None] * normal[:, None, :]
    return s


def loosened(first: tuple, constraints: VelocityFilter, released: np.ndarray) -> tuple:
    """A step's first linearisation (:attr:`NewtonResult.first`) for solving it again with the
    vertices ``released`` let slide or leave (``constraints``, looser than the filter its
    preconditioner was built for; or a last linearisation, for the friction pass that lets
    slipping vertices go): the preconditioner's finest diagonal blocks at those
    vertices become the looser filter's, S A S + (I - S). The old filter had them constrained
    (the identity there, against the mesh's mass and stiffness along their free directions
    now): re-solves of the Suzanne drape took 52 CG iterations, 43 with these blocks and 42
    with a preconditioner built afresh (a filtered copy of the matrix and a multigrid set-up)."""
    blocks, rhs, matrix, precondition = first
    if matrix is None or precondition is None or not len(released):
        return first
    sliding = constraints.sliding
    s = filter_blocks(constraints.free, constraints.pressed[sliding],
                      constraints.normal[sliding])[released]
    block = s @ matrix.diagonal(released) @ s + (np.eye(3) - s)
    return blocks, rhs, matrix, precondition.with_fine(released, inverse3(block))


def filtered_matrix(matrix, free, pressed, normal, diagonal=None):
    """The matrix CG really solves with: S A S + (I - S), S removing each vertex's
    constrained directions (all three for a pinned vertex, the normal for a pressed one) —
    what the preconditioner must approximate; a hierarchy built on A itself would move
    constrained vertices with their aggregates and lose most of its power when many are
    constrained (cloth landing on a collider). ``diagonal``: S's diagonal when S is one
    (:func:`diagonal_filter`; found here when not given)."""
    constrained = ~free
    constrained[pressed] = True
    if not constrained.any():
        return matrix
    if diagonal is None:
        diagonal = diagonal_filter(free, pressed, normal)
    if diagonal is not None:
        return filtered_diagonal(matrix, diagonal, constrained)
    if not len(pressed) or (normal == normal[0]).all():  # pins only, or a flat ground
        return filtered_one_normal(matrix, free, pressed,
                                   normal[0] if len(pressed) else np.zeros(3), constrained)
    p = matrix.pattern
    s = filter_blocks(free, pressed, normal)
    # only blocks in a constrained vertex's row or column change
    row, col = np.nonzero(constrained[:, None] | constrained[p.neighbours])
    data = matrix.data.copy()
    blocks = data.reshape(p.n, 3, p.width, 3)
    other = p.neighbours[row, col]
    blocks[row, :, col, :] = np.matmul(np.matmul(s[row], blocks[row, :, col, :]), s[other])
    fixed = np.nonzero(constrained)[0]
    blocks[fixed, :, p.diagonal_slot[fixed] % p.width, :] += np.eye(3) - s[fixed]
    return BlockMatrix(p, data)
