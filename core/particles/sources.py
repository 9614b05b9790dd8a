"""Where particles are born: points on an emitter's origin, vertices, faces or volume.

All sampling is vectorised and driven by the emitter's own ``numpy.random.Generator``.
"""
from __future__ import annotations

import numpy as np

from ..transforms import cross

WINDING_CHUNK = 2_000_000  # max points x triangles per winding-number batch (memory bound)


def triangle_areas_normals(verts: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Areas (m,) [m^2] and unit normals (m, 3) of triangles (m, 3) over vertices (n, 3)."""
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    doubled = cross(b - a, c - a)
    norm = np.linalg.norm(doubled, axis=1)
    normals = doubled / np.where(norm > 0.0, norm, 1.0)[:, None]
    return 0.5 * norm, normals


def vertex_normals(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (n, 3); vertices in no triangle get (0, 0, 1)."""
    n = np.zeros_like(verts)
    if len(tris):
        a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
        doubled = cross(b - a, c - a)
        for k in range(3):
            np.add.at(n, tris[:, k], doubled)
    length = np.linalg.norm(n, axis=1)
    n[length == 0.0] = (0.0, 0.0, 1.0)
    length[length == 0.0] = 1.0
    return n / length[:, None]


def open_edge_count(tris: np.ndarray) -> int:
    """Number of edges not shared by exactly two triangles (0 for a closed 2-manifold)."""
    if len(tris) == 0:
        return 0
    edges = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    edges.sort(axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return int(np.count_nonzero(counts != 2))


def enclosed_volume(verts: np.ndarray, tris: np.ndarray) -> float:
    """Signed volume [m^3] of a closed triangle mesh (divergence theorem); negative if the mesh
    is inside-out (normals pointing inwards)."""
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    return float(np.einsum("ij,ij->", a, cross(b, c)) / 6.0)


def winding_number(points: np.ndarray, verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Generalised winding number (k,) of points w.r.t. a closed triangle mesh (1 inside, 0 out;
    -1 inside an inside-out mesh).

    Sums the signed solid angle of every triangle (Van Oosterom & Strackee), batched to bound
    memory at :data:`WINDING_CHUNK` point-triangle pairs.
    """
    out = np.empty(len(points))
    tri = verts[tris]  # (m, 3, 3)
    step = max(1, WINDING_CHUNK // max(len(tris), 1))
    for lo in range(0, len(points), step):
        p = points[lo:lo + step]
        a = tri[None, :, 0, :] - p[:, None, :]
        b = tri[None, :, 1, :] - p[:, None, :]
        c = tri[None, :, 2, :] - p[:, None, :]
        la, lb, lc = (np.linalg.norm(q, axis=2) for q in (a, b, c))
        num = np.einsum("kmi,kmi->km", a, cross(b, c))
        den = (la * lb * lc + np.einsum("kmi,kmi->km", a, b) * lc
               + np.einsum("kmi,kmi->km", b, c) * la + np.einsum("kmi,kmi->km", c, a) * lb)
        out[lo:lo + step] = np.arctan2(num, den).sum(axis=1) / (2.0 * np.pi)
    return out


def sample_vertices(rng: np.random.Generator, count: int, vertex_count: int) -> np.ndarray:
    return rng.integers(0, vertex_count, size=count)


def sample_faces(rng: np.random.Generator, count: int, verts: np.ndarray, tris: np.ndarray):
    """Area-weighted triangle choice and uniform barycentric coordinates.

    Returns: (triangle index (count,), barycentric weights (count, 3)).
    """
    areas, _ = triangle_areas_normals(verts, tris)
    total = areas.sum()
    cdf = np.cumsum(areas) / total
    tri = np.minimum(np.searchsorted(cdf, rng.random(count), side="right"), len(tris) - 1)
    r1 = np.sqrt(rng.random(count))
    r2 = rng.random(count)
    bary = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
    return tri, bary


def sample_volume(rng: np.random.Generator, count: int, verts: np.ndarray, tris: np.ndarray,
                  max_rounds: int = 64) -> np.ndarray:
    """``count`` points uniformly inside a closed mesh, by rejection in its bounding box.

    Either winding works: an inside-out mesh (flipped normals) has winding number -1 inside.

    Raises:
        ValueError: the mesh encloses (almost) no volume, e.g. it is flat.
    """
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    # A mesh flat in an axis plane gives a box of zero thickness: every candidate would lie on
    # the surface, where the winding number is undefined — so say so before sampling.
    if np.min(hi - lo) <= 1e-12 * max(float(np.max(hi - lo)), 1e-300):
        raise ValueError(_no_volume(verts, tris))
    found: list[np.ndarray] = []
    have = 0
    for _ in range(max_rounds):
        if have >= count:
            break
        batch = max(64, 2 * (count - have))
        cand = lo + rng.random((batch, 3)) * (hi - lo)
        inside = cand[np.abs(winding_number(cand, verts, tris)) > 0.5]
        found.append(inside)
        have += len(inside)
    if have < count:
        raise ValueError(_no_volume(verts, tris, f"only {have} of {count} particles could be "
                                                 f"placed inside it in {max_rounds} tries"))
    return np.concatenate(found)[:count]


def _no_volume(verts: np.ndarray, tris: np.ndarray, detail: str = "") -> str:
    extent = float(np.max(verts.max(axis=0) - verts.min(axis=0)))
    volume = abs(enclosed_volume(verts, tris))
    what = "it is flat" if volume <= 1e-9 * extent ** 3 else "it fills almost none of its bounds"
    return (f"source is VOLUME but the mesh encloses no volume ({what}: volume {volume:.3g} "
            f"in a bounding box {extent:.3g} across, object space{'; ' + detail if detail else ''})"
            " — give the mesh thickness or emit from FACES")


def cone_directions(rng: np.random.Generator, axis: np.ndarray, half_angle: float) -> np.ndarray:
    """Unit vectors (n, 3) uniform on the spherical cap of ``half_angle`` [rad] around each
    row of ``axis`` (n, 3) (unit). half_angle >= pi gives the whole sphere."""
    n = len(axis)
    cos_max = np.cos(min(half_angle, np.pi))
    cos_t = 1.0 - rng.random(n) * (1.0 - cos_max)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    phi = rng.random(n) * 2.0 * np.pi
    # orthonormal basis per axis: pick the helper least parallel to it
    helper = np.where(np.abs(axis[:, 0:1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = cross(axis, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = cross(axis, e1)
    return (cos_t[:, None] * axis + (sin_t * np.cos(phi))[:, None] * e1
            + (sin_t * np.sin(phi))[:, None] * e2)


def random_directions(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    return v / np.where(norm > 0.0, norm, 1.0)
