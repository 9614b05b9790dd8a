"""Exact mass properties of rigid bodies: mass, centre of mass, inertia tensor and volume.

Closed polyhedra are integrated exactly by the divergence theorem: the solid is the signed sum
of the tetrahedra joining a reference point ``p`` to each triangle (the surface winding gives the
signs), and each tetrahedron's volume, first moment and second moment (covariance) are closed
forms of its corners. For a tetrahedron with corners p, p + a, p + b, p + c and d = a . (b x c):

    volume = d / 6,   first moment = d / 24 (a + b + c),
    covariance C = integral of x x^T dV = d / 120 (a a^T + b b^T + c c^T + s s^T),  s = a + b + c

(the covariance of the canonical tetrahedron mapped linearly; cf. Mirtich 1996, Eberly
"Polyhedral Mass Properties"). ``p`` is the centre of the mesh's bounding box, so the terms are
of the mesh's size whatever its placement: the sums then carry a relative rounding error of a few
ulps. The covariance is shifted to the centre of mass (parallel axis theorem) and turned into the
inertia tensor I = tr(C) E - C.

Primitives (sphere, box, capsule) use their textbook closed forms. Every result is a frozen,
validated :class:`MassProperties`; :func:`with_override` applies a user's centre of mass or
inertia, validated with messages that name the object and the value.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..collision.mesh import check_points
from ..errors import PhysanimError
from ..validate import frozen

KIND = "rigid body"
MESH_ADVICE = "use a Convex Hull, Box, Sphere or Capsule shape, or close the mesh"
FLAT_VOLUME_REL = 1e-9  # |volume| below this share of the unsigned tetrahedra volume is flat
# Overrides may come from single-precision UI fields: a tensor off by a few float32 ulps passes.
SYMMETRY_TOL = 1e-6  # |I - I^T| relative to the largest entry
TRIANGLE_TOL = 1e-6  # I1 + I2 >= I3 relative to the largest principal moment


@dataclass(frozen=True, eq=False)
class MassProperties:
    """Mass properties of one rigid body, validated and read-only.

    Attributes:
        mass: [kg], finite and > 0.
        com: (3,) centre of mass in the shape's local frame [m] (read-only array).
        inertia: (3, 3) inertia tensor about the centre of mass in local axes [kg m^2]
            (read-only): finite, symmetric, positive definite, and its principal moments
            satisfy the triangle inequalities (I1 + I2 >= I3 for every ordering).
        volume: [m^3], finite and > 0.
    """

    mass: float
    com: np.ndarray
    inertia: np.ndarray
    volume: float

    def __post_init__(self):
        mass, com, inertia, volume = _validated(self.mass, self.com, self.inertia, self.volume)
        object.__setattr__(self, "mass", mass)
        object.__setattr__(self, "com", com)
        object.__setattr__(self, "inertia", inertia)
        object.__setattr__(self, "volume", volume)

    @property
    def density(self) -> float:
        """Mean density [kg/m^3]."""
        return self.mass / self.volume

    @property
    def principal_moments(self) -> np.ndarray:
        """(3,) eigenvalues of the inertia tensor, ascending [kg m^2]."""
        return np.linalg.eigvalsh(self.inertia)


def _validated(mass, com, inertia, volume, name: str | None = None) -> tuple:
    """(mass, com, inertia, volume) as float, read-only arrays; raises naming the bad value."""
    def fail(message: str):
        raise PhysanimError(message, obj=name, kind=KIND)

    mass, volume = float(mass), float(volume)
    if not (math.isfinite(mass) and mass > 0.0):
        fail(f"mass must be finite and > 0 (got {mass})")
    if not (math.isfinite(volume) and volume > 0.0):
        fail(f"volume must be finite and > 0 (got {volume})")
    c = np.asarray(com, dtype=np.float64)
    if c.shape != (3,) or not np.isfinite(c).all():
        fail(f"centre of mass must be 3 finite numbers (got {np.asarray(com).tolist()})")
    return mass, frozen(c), frozen(_checked_inertia(inertia, fail)), volume


def _checked_inertia(inertia, fail) -> np.ndarray:
    """(3, 3) symmetrised tensor; (3,) principal moments are taken as a diagonal."""
    t = np.asarray(inertia, dtype=np.float64)
    if t.shape == (3,):
        t = np.diag(t)
    if t.shape != (3, 3) or not np.isfinite(t).all():
        fail(f"inertia must be a finite 3 x 3 tensor or 3 principal moments "
             f"(got {np.asarray(inertia).tolist()})")
    scale = float(np.abs(t).max())
    if float(np.abs(t - t.T).max()) > SYMMETRY_TOL * scale:
        fail(f"inertia tensor must be symmetric (got {t.tolist()})")
    t = 0.5 * (t + t.T)
    lam = np.linalg.eigvalsh(t)
    if not lam[0] > 0.0:
        fail(f"inertia tensor must be positive definite: its principal moments are "
             f"{lam.tolist()} [kg m^2]; every moment must be > 0")
    if lam[0] + lam[1] < lam[2] * (1.0 - TRIANGLE_TOL):
        fail(f"principal moments of inertia {lam.tolist()} [kg m^2] break the triangle "
             f"inequality I1 + I2 >= I3 ({lam[0]:.6g} + {lam[1]:.6g} < {lam[2]:.6g}): no mass "
             f"distribution has them")
    return t


def _density(volume: float, density, mass, name: str) -> float:
    """Density [kg/m^3] from exactly one of ``density`` [kg/m^3] or ``mass`` [kg]."""
    if (density is None) == (mass is None):
        raise PhysanimError(f"give exactly one of density [kg/m^3] or mass [kg] "
                            f"(got density={density}, mass={mass})", obj=name, kind=KIND)
    key, value = ("density", density) if mass is None else ("mass", mass)
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise PhysanimError(f"{key} must be finite and > 0 (got {value})", obj=name, kind=KIND)
    return value if mass is None else value / volume


def _solid(volume: float, second: np.ndarray, density, mass, name: str) -> MassProperties:
    """A body centred on its origin from its volume [m^3] and (3,) diagonal of the
    unit-density covariance about the centre [m^5]."""
    rho = _density(volume, density, mass, name)
    cov = rho * np.asarray(second, dtype=np.float64)
    return MassProperties(rho * volume, (0.0, 0.0, 0.0), np.diag(cov.sum() - cov), volume)


def _positive(name: str, **values) -> list[float]:
    out = []
    for key, v in values.items():
        v = float(v)
        if not (math.isfinite(v) and v > 0.0):
            raise PhysanimError(f"{key} must be finite and > 0 (got {v})", obj=name, kind=KIND)
        out.append(v)
    return out


def sphere_mass(radius, *, density=None, mass=None, name: str = "body") -> MassProperties:
    """Solid sphere centred on the origin: I = 2/5 m r^2.

    Args:
        radius: [m], > 0.
        density: [kg/m^3], or mass: [kg] (exactly one).
        name: the object's name (messages).
    """
    (r,) = _positive(name, radius=radius)
    volume = 4.0 / 3.0 * math.pi * r ** 3
    return _solid(volume, np.full(3, volume * r * r / 5.0), density, mass, name)


def box_mass(half_extents, *, density=None, mass=None, name: str = "body") -> MassProperties:
    """Solid box centred on the origin, axis-aligned: I_xx = m / 3 (hy^2 + hz^2), ...

    Args:
        half_extents: (3,) half sizes [m], each > 0.
        density: [kg/m^3], or mass: [kg] (exactly one).
        name: the object's name (messages).
    """
    h = np.asarray(half_extents, dtype=np.float64)
    if h.shape != (3,):
        raise PhysanimError(f"half_extents must be 3 numbers (got {np.asarray(half_extents)})",
                            obj=name, kind=KIND)
    h = np.array(_positive(name, **{f"half_extents[{i}]": h[i] for i in range(3)}))
    volume = 8.0 * float(np.prod(h))
    return _solid(volume, volume * h * h / 3.0, density, mass, name)


def capsule_mass(radius, half_length, *, density=None, mass=None,
                 name: str = "body") -> MassProperties:
    """Solid capsule centred on the origin, axis local Z: a cylinder of radius r and length
    2 h capped by two hemispheres (h = ``half_length``, the half distance between the caps'
    centres; h = 0 gives a sphere).

    Args:
        radius: [m], > 0.
        half_length: [m], >= 0.
        density: [kg/m^3], or mass: [kg] (exactly one).
        name: the object's name (messages).
    """
    (r,) = _positive(name, radius=radius)
    h = float(half_length)
    if not (math.isfinite(h) and h >= 0.0):
        raise PhysanimError(f"half_length must be finite and >= 0 (got {h})", obj=name, kind=KIND)
    cyl = 2.0 * math.pi * r * r * h  # cylinder volume
    ball = 4.0 / 3.0 * math.pi * r ** 3  # both caps together
    # Unit-density covariance. A cap (volume ball / 2, first moment 3 r / 8 of it about its flat
    # face) shifted by h along z: integral (z + h)^2 = ball / 2 (r^2 / 5 + 2 h 3 r / 8 + h^2).
    zz = cyl * h * h / 3.0 + ball * (r * r / 5.0 + 3.0 * r * h / 4.0 + h * h)
    xx = cyl * r * r / 4.0 + ball * r * r / 5.0
    return _solid(cyl + ball, np.array([xx, xx, zz]), density, mass, name)


def polyhedron_mass(vertices, triangles, *, density=None, mass=None,
                    name: str = "body") -> MassProperties:
    """Exact mass properties of the solid bounded by a closed, outward-wound triangle mesh.

    Args:
        vertices: (n, 3) positions in the shape's local frame [m].
        triangles: (t, 3) vertex indices, counter-clockwise seen from outside.
        density: [kg/m^3], or mass: [kg] (exactly one).
        name: the object's name (messages).

    Raises:
        PhysanimError: non-finite vertices, bad indices, an open or non-manifold mesh, faces
            wound inconsistently, zero volume (flat) or negative volume (inside out).
    """
    v, tri = _checked_mesh(vertices, triangles, name)
    _check_not_flat(v[np.unique(tri)], name)
    _check_closed(v, tri, name)
    volume, centroid, cov, unsigned = _moments(v, tri)
    _check_volume(volume, unsigned, name)
    rho = _density(volume, density, mass, name)
    inertia = rho * (np.trace(cov) * np.eye(3) - cov)
    return MassProperties(rho * volume, centroid, inertia, volume)


def _checked_mesh(vertices, triangles, name: str) -> tuple[np.ndarray, np.ndarray]:
    v = check_points(name, "vertex", vertices, kind=KIND)
    t = np.asarray(triangles)
    if t.ndim != 2 or t.shape[1] != 3 or len(t) == 0:
        raise PhysanimError(f"triangles must be a non-empty (t, 3) array of vertex indices "
                            f"(got shape {t.shape})", obj=name, kind=KIND)
    if t.dtype.kind not in "iu" and not np.all(np.isfinite(t) & (t == np.round(t))):
        raise PhysanimError("triangle vertex indices must be integers", obj=name, kind=KIND)
    t = t.astype(np.int64)
    out = (t < 0) | (t >= len(v))
    if out.any():
        i = int(np.argmax(out.any(axis=1)))
        raise PhysanimError(f"triangle {i} refers to vertex {t[i].tolist()} but the mesh has "
                            f"{len(v)} vertices", obj=name, kind=KIND)
    return v, t


def _check_not_flat(used: np.ndarray, name: str) -> None:
    """Refuse vertices in one plane (or on a line, or a point) before the topology: welded
    together, such a mesh is often non-manifold, and "flat" is the message that helps."""
    spread = np.linalg.svd(used - used.mean(axis=0), compute_uv=False)
    if spread[2] <= FLAT_VOLUME_REL * spread[0]:
        raise PhysanimError(f"the mesh encloses no volume (0 m^3): its vertices lie in one "
                            f"plane; {MESH_ADVICE}", obj=name, kind=KIND)


def _check_closed(v: np.ndarray, tri: np.ndarray, name: str) -> None:
    """Every edge must join exactly two faces wound opposite ways along it. Vertices at equal
    positions count as one, so meshes split along seams (for normals or UVs) still close."""
    _, weld = np.unique(v + 0.0, axis=0, return_inverse=True)  # + 0.0: -0.0 becomes 0.0
    t = weld.reshape(-1)[tri]
    # A face collapsed onto a segment or a point adds no volume and would count its edge twice.
    t = t[(t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 2] != t[:, 0])]
    if len(t) == 0:
        return  # every face collapsed: the volume check reports it
    a = t.reshape(-1)
    b = t[:, [1, 2, 0]].reshape(-1)
    key = np.minimum(a, b) * (int(weld.max()) + 1) + np.maximum(a, b)
    _, inverse, count = np.unique(key, return_inverse=True, return_counts=True)
    open_, shared = int((count == 1).sum()), int((count > 2).sum())
    if open_ or shared:
        detail = " and ".join(([f"{_edges(open_)} open (used by one face only)"] if open_ else [])
                              + ([f"{_edges(shared)} shared by more than two faces"]
                                 if shared else []))
        raise PhysanimError(f"a mesh shape needs a closed mesh, but this one has {detail}; "
                            f"{MESH_ADVICE}", obj=name, kind=KIND)
    direction = np.bincount(inverse.reshape(-1), weights=np.where(a < b, 1.0, -1.0))
    flipped = int(np.count_nonzero(direction))
    if flipped:
        raise PhysanimError(f"{_edges(flipped)} join faces wound in opposite directions (some "
                            f"normals point in, some out); recalculate normals (Mesh > Normals > "
                            f"Recalculate Outside), or {MESH_ADVICE}", obj=name, kind=KIND)


def _edges(count: int) -> str:
    return f"{count} edge" if count == 1 else f"{count} edges"


def _moments(v: np.ndarray, tri: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, float]:
    """Unit-density volume [m^3], centroid (3,) [m], covariance (3, 3) about the centroid
    [m^5] and the unsigned volume of the tetrahedra [m^3] (the scale of rounding errors).

    Per-triangle terms are laid out (k, t) so that every sum runs along a contiguous axis,
    where numpy sums pairwise: the rounding error grows like log(t), not t."""
    used = v[np.unique(tri)]
    p = 0.5 * (used.min(axis=0) + used.max(axis=0))
    vt = np.ascontiguousarray((v - p).T)  # (3, n): coordinates from p
    a, b, c = (vt[:, tri[:, k]] for k in range(3))  # (3, t) each
    d = (a[0] * (b[1] * c[2] - b[2] * c[1]) + a[1] * (b[2] * c[0] - b[0] * c[2])
         + a[2] * (b[0] * c[1] - b[1] * c[0]))  # (t,) 6 x the signed tetrahedra volumes
    s = a + b + c
    volume = float(d.sum()) / 6.0
    first = (s * d).sum(axis=1) / 24.0
    rows, cols = np.triu_indices(3)
    products = sum(x[rows] * x[cols] for x in (a, b, c, s))  # (6, t) upper triangle of x x^T
    second = np.zeros((3, 3))
    second[rows, cols] = (products * d).sum(axis=1) / 120.0
    second[cols, rows] = second[rows, cols]
    unsigned = float(np.abs(d).sum()) / 6.0
    if volume == 0.0:
        return volume, p, second, unsigned
    r = first / volume  # centroid from p
    return volume, p + r, second - volume * np.outer(r, r), unsigned  # parallel axis theorem


def _check_volume(volume: float, unsigned: float, name: str) -> None:
    if abs(volume) <= FLAT_VOLUME_REL * unsigned:
        raise PhysanimError(f"the mesh encloses no volume ({volume:.6g} m^3): it is flat or "
                            f"its faces cancel out; {MESH_ADVICE}", obj=name, kind=KIND)
    if volume < 0.0:
        raise PhysanimError(f"the mesh is inside out (volume {volume:.6g} m^3 < 0: its normals "
                            f"point inward); recalculate normals (Mesh > Normals > Recalculate "
                            f"Outside), or {MESH_ADVICE}", obj=name, kind=KIND)


def with_override(props: MassProperties, *, com=None, inertia=None,
                  name: str = "body") -> MassProperties:
    """``props`` with the user's centre of mass and/or inertia tensor in place of the computed.

    A new centre of mass moves the balance point only: the inertia about it stays the shape's
    inertia about its own centre of mass unless ``inertia`` is given too.

    Args:
        props: computed mass properties.
        com: (3,) centre of mass in the shape's local frame [m], or None to keep.
        inertia: (3, 3) tensor about the centre of mass in local axes, or (3,) principal
            moments along the local axes [kg m^2], or None to keep.
        name: the object's name (messages).

    Raises:
        PhysanimError: a non-finite centre, or an inertia that is not symmetric, not positive
            definite or breaks the triangle inequality of principal moments.
    """
    new_com = props.com if com is None else com
    new_inertia = props.inertia if inertia is None else inertia
    _, c, t, _ = _validated(props.mass, new_com, new_inertia, props.volume, name)
    return MassProperties(props.mass, c, t, props.volume)
