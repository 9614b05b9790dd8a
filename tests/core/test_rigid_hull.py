"""Convex-hull rigid shapes and their contacts: polyhedra with merged planar faces, and contact
points against hulls, boxes, spheres and capsules checked against an exact signed distance
(the Minkowski difference's hull, its faces' distance to the origin)."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.collision import convex_hull
from physanim.core.collision.distance import closest_on_triangles
from physanim.core.errors import PhysanimError
from physanim.core.rigid import narrow_hull
from physanim.core.rigid.hull_shape import HullSet, HullShape
from physanim.core.rigid.narrow_hull import (AXIS_TOL_REL, hull_box, hull_capsule, hull_hull,
                                             hull_sphere)

CUBE = [[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)]
I3 = np.eye(3)[None]


def rotation(rng, n):
    """(n, 3, 3) uniformly random rotation matrices."""
    q = rng.normal(size=(n, 4))
    w, x, y, z = (q / np.linalg.norm(q, axis=1)[:, None]).T
    r = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                  2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                  2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1)
    return r.reshape(n, 3, 3)


def signed_distance(pa, pb) -> float:
    """Exact signed distance [m] between the convex hulls of points pa and pb: distance from
    the origin to the hull of their Minkowski difference, negated depth when inside."""
    hull = convex_hull((np.asarray(pb)[None] - np.asarray(pa)[:, None]).reshape(-1, 3))
    t = hull.points[hull.triangles]
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    offset = np.einsum("ij,ij->i", n / np.linalg.norm(n, axis=1)[:, None], t[:, 0])
    if offset.min() > 0.0:
        return -float(offset.min())
    return float(np.sqrt(closest_on_triangles(np.zeros((len(t), 3)), t)[1].min()))


def blob(rng, n=20):
    """A Suzanne-sized random point cloud with a flat bottom (many coplanar points)."""
    p = rng.normal(size=(n, 3)) * rng.uniform(0.3, 1.0, 3)
    p[:, 2] = np.maximum(p[:, 2], -0.4)
    return p


def icosphere(subdivisions=2):
    t = (1.0 + 5 ** 0.5) / 2.0
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t],
         [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    v = np.array(v, dtype=float)
    v /= np.linalg.norm(v, axis=1)[:, None]
    for _ in range(subdivisions):  # midpoints of every edge (of the hull: all point pairs
        tri = convex_hull(v).triangles  # that share a triangle), pushed out to the sphere
        e = np.unique(np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]),
                              axis=1), axis=0)
        m = v[e].mean(axis=1)
        v = np.concatenate([v, m / np.linalg.norm(m, axis=1)[:, None]])
    return v


def by_pair(c, k):
    """Per pair: min separation (inf without points) and point count."""
    smin = np.full(k, np.inf)
    np.minimum.at(smin, c.pair, c.separation)
    return smin, np.bincount(c.pair, minlength=k)


def small_turns(rng, k, angle):
    """(k, 3, 3) rotations by ``angle`` [rad] about random axes (Rodrigues)."""
    axis = rng.normal(size=(k, 3))
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    cross = np.cross(axis[:, None], np.eye(3)[None]).transpose(0, 2, 1)  # column j: a x e_j
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def random_pairs(rng, shapes, k):
    return (rng.integers(0, len(shapes), k), rng.normal(size=(k, 3)), rotation(rng, k),
            rng.integers(0, len(shapes), k), rotation(rng, k))


# --- shapes --------------------------------------------------------------------------------------

def test_a_cube_of_8_points_is_a_box():
    s = HullShape.from_points(CUBE, "Cube")
    assert (len(s.vertex), len(s.edge), len(s.face_normal)) == (8, 12, 6)
    assert (s.face_loop_count == 4).all()
    assert np.allclose(np.abs(s.face_normal).sum(axis=1), 1.0)
    assert np.allclose(s.face_offset, 1.0)
    assert np.allclose(np.abs(s.edge_direction).max(axis=1), 1.0)
    assert s.radius == pytest.approx(3 ** 0.5)


@pytest.mark.parametrize("kind", ["icosphere", "blob", "cube-grid", "cylinder", "box-noise"])
def test_merged_faces_make_a_closed_convex_polyhedron(kind):
    rng = np.random.default_rng(4)
    if kind == "icosphere":
        p = icosphere()
    elif kind == "blob":
        p = blob(rng, 500)
    elif kind == "cube-grid":
        p = np.stack(np.meshgrid(*[np.linspace(0.0, 1.0, 5)] * 3), -1).reshape(-1, 3)
    elif kind == "cylinder":
        a = np.linspace(0.0, 2 * np.pi, 33)[:-1]
        p = np.concatenate([np.stack([np.cos(a), np.sin(a), np.full(32, z)], 1) for z in (0, 2)])
    else:  # float32 noise on a box's corners, face centres and edge midpoints
        p = np.stack(np.meshgrid(*[[-1.0, 0.0, 1.0]] * 3), -1).reshape(-1, 3) * [2.0, 1.0, 0.5]
        p = (p + rng.normal(size=p.shape) * 1e-7).astype(np.float32)
    s = HullShape.from_points(p, kind)
    v, e, f = len(s.vertex), len(s.edge), len(s.face_normal)
    assert v - e + f == 2
    expect = {"icosphere": (162, 480, 320), "cube-grid": (8, 12, 6), "cylinder": (64, 96, 34),
              "box-noise": (8, 12, 6)}
    if kind in expect:
        assert (v, e, f) == expect[kind]
    if kind == "blob":  # the flat bottom is one face
        assert np.isclose(s.face_normal[:, 2], -1.0).sum() == 1
    size = np.ptp(p, axis=0).max()
    assert (np.asarray(p) @ s.face_normal.T - s.face_offset).max() <= 1e-9 * size
    face = np.repeat(np.arange(f), s.face_loop_count)
    corner = s.vertex[s.face_loop]
    height = np.einsum("ij,ij->i", corner, s.face_normal[face]) - s.face_offset[face]
    assert np.abs(height).max() < 1e-5 * size  # planar faces
    ends = s.vertex[s.edge]
    assert np.allclose((ends[:, 1] - ends[:, 0]) / np.linalg.norm(ends[:, 1] - ends[:, 0],
                                                                  axis=1)[:, None],
                       s.edge_direction)
    # each face walks each of its edges once, the neighbour the other way
    assert np.bincount(s.edge_face.ravel(), minlength=f).tolist() == s.face_loop_count.tolist()


@pytest.mark.parametrize("points", [
    [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0.5, 0.5, 0]],  # a plane
    [[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]],  # a line
    [[0, 0, 0], [1, 0, 0], [0, 1, 0]],  # too few
    [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1e-12]],  # thinner than rounding
])
def test_flat_point_sets_name_the_object_and_suggest_a_box(points):
    with pytest.raises(PhysanimError) as info:
        HullShape.from_points(points, "Plane.001")
    assert info.value.obj == "Plane.001" and info.value.kind == "rigid body"
    assert "Plane.001" in str(info.value) and "Box" in str(info.value)


def test_hull_sets_pad_without_changing_results_and_build_from_model_ranges():
    rng = np.random.default_rng(1)
    clouds = [np.array(CUBE), blob(rng, 40), icosphere(1)]
    start = np.cumsum([0] + [len(c) for c in clouds])[:-1]
    hulls = HullSet.from_ranges(np.concatenate(clouds), start, [len(c) for c in clouds],
                                ("Cube", "Blob", "Ball"))
    assert hulls.hull_name == ("Cube", "Blob", "Ball") and hulls.hull_count == 3
    k = 60
    ia, x, r, ib, rb = random_pairs(rng, clouds, k)
    xb = x + rng.normal(size=(k, 3)) * 0.7
    together = hull_hull(hulls, x, r, hulls, xb, rb, 0.1, index_a=ia, index_b=ib)
    for i in range(3):
        for j in range(3):
            sel = np.nonzero((ia == i) & (ib == j))[0]
            alone = hull_hull(HullShape.from_points(clouds[i]), x[sel], r[sel],
                              HullShape.from_points(clouds[j]), xb[sel], rb[sel], 0.1)
            mine = np.isin(together.pair, sel)
            assert np.allclose(together.point[mine], alone.point)
            assert (sel[alone.pair] == together.pair[mine]).all()


# --- hull against hull and box -----------------------------------------------------------------

@pytest.mark.parametrize("turn", [0.0, 0.3])
def test_a_cube_resting_on_a_cube_touches_at_four_corners(turn):
    cube = HullShape.from_points(CUBE, "Cube")
    c, s = np.cos(turn), np.sin(turn)
    rz = np.array([[[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]])
    top = np.array([[0.2, -0.1, 1.99]])
    for got in (hull_hull(cube, np.zeros((1, 3)), I3, cube, top, rz, 0.02),
                hull_box(cube, np.zeros((1, 3)), I3, top, rz, np.ones((1, 3)), 0.02)):
        assert len(got.pair) == 4
        assert np.allclose(got.normal, [0.0, 0.0, 1.0])
        assert np.allclose(got.separation, -0.01)
        assert np.allclose(got.point[:, 2], 0.995)
        assert len(set(got.feature.tolist())) == 4
        assert np.abs(got.point[:, :2]).max() <= 1.0 + 1e-12  # on the lower cube's face
    # speculative: apart by 0.05, points only when the margin reaches
    lifted = np.array([[0.2, -0.1, 2.05]])
    got = hull_hull(cube, np.zeros((1, 3)), I3, cube, lifted, rz, 0.06)
    assert len(got.pair) == 4 and np.allclose(got.separation, 0.05)
    assert len(hull_hull(cube, np.zeros((1, 3)), I3, cube, lifted, rz, 0.049).pair) == 0


def test_a_tetrahedron_point_down_touches_once_and_edge_down_twice():
    cube = HullShape.from_points(CUBE, "Cube")
    point_down = HullShape.from_points([[0, 0, 0], [1, 0, 1], [-0.5, 0.8, 1], [-0.5, -0.8, 1]])
    edge_down = HullShape.from_points([[-0.5, 0, 0], [0.5, 0, 0], [0, -0.5, 1], [0, 0.5, 1]])
    at = np.array([[0.1, 0.2, 0.99]])
    one = hull_hull(cube, np.zeros((1, 3)), I3, point_down, at, I3, 0.02)
    assert len(one.pair) == 1
    assert np.allclose(one.normal, [0, 0, 1]) and np.allclose(one.separation, -0.01)
    assert np.allclose(one.point, [[0.1, 0.2, 0.995]])
    two = hull_hull(cube, np.zeros((1, 3)), I3, edge_down, at, I3, 0.02)
    assert len(two.pair) == 2
    assert np.allclose(two.normal, [0, 0, 1]) and np.allclose(two.separation, -0.01)
    assert np.allclose(np.sort(two.point[:, 0]), [-0.4, 0.6])
    # turned upside down the tetrahedron is A: the normal flips, the points stay
    flip = np.diag([1.0, -1.0, -1.0])[None]
    under = hull_hull(edge_down, at * [1, 1, -1], flip, cube, np.zeros((1, 3)), I3, 0.02)
    assert len(under.pair) == 2 and np.allclose(under.normal, [0, 0, 1])


@pytest.fixture(scope="module")
def scene():
    """Random hulls in random poses, mostly overlapping or close."""
    rng = np.random.default_rng(7)
    clouds = [blob(rng) for _ in range(6)] + [np.array(CUBE) * [0.5, 0.3, 0.8], icosphere(1)]
    shapes = [HullShape.from_points(c, f"H{i}") for i, c in enumerate(clouds)]
    k = 200
    ia, xa, ra, ib, rb = random_pairs(rng, shapes, k)
    xb = xa + rng.normal(size=(k, 3)) * 0.7
    return shapes, HullSet.from_shapes(shapes), ia, xa, ra, ib, xb, rb


def world_vertices(shape, x, r):
    return shape.vertex @ r.T + x


def test_hull_hull_separation_matches_the_exact_signed_distance(scene):
    shapes, hulls, ia, xa, ra, ib, xb, rb = scene
    k, margin = len(ia), 0.3
    got = hull_hull(hulls, xa, ra, hulls, xb, rb, margin, index_a=ia, index_b=ib)
    smin, count = by_pair(got, k)
    exact = np.array([signed_distance(world_vertices(shapes[ia[i]], xa[i], ra[i]),
                                      world_vertices(shapes[ib[i]], xb[i], rb[i]))
                      for i in range(k)])
    tol = AXIS_TOL_REL * np.array([shapes[i].radius + shapes[j].radius for i, j in zip(ia, ib)])
    over = exact < 0.0
    assert over.sum() > 50 and (~over & (exact < margin)).sum() > 10
    # overlapping: the least-penetration axis, to within the face preference
    assert np.all(np.abs(smin[over] - exact[over]) <= tol[over] + 1e-9)
    # apart: never later than the true distance; every pair within the margin is reported
    seen = ~over & (count > 0)
    assert np.all(smin[seen] <= exact[seen] + tol[seen] + 1e-9)
    assert np.all(count[exact < margin] >= 1)
    assert np.all(got.separation < margin) and count.max() <= 4
    assert np.allclose(np.linalg.norm(got.normal, axis=1), 1.0)


def test_swapping_a_and_b_gives_the_same_points_reversed(scene):
    shapes, hulls, ia, xa, ra, ib, xb, rb = scene
    ab = hull_hull(hulls, xa, ra, hulls, xb, rb, 0.2, index_a=ia, index_b=ib)
    ba = hull_hull(hulls, xb, rb, hulls, xa, ra, 0.2, index_a=ib, index_b=ia).swapped()
    assert len(ab.pair) == len(ba.pair) > 100
    o1, o2 = np.lexsort((ab.feature, ab.pair)), np.lexsort((ba.feature, ba.pair))
    assert (ab.pair[o1] == ba.pair[o2]).all() and (ab.feature[o1] == ba.feature[o2]).all()
    assert np.allclose(ab.point[o1], ba.point[o2], atol=1e-9)
    assert np.allclose(ab.normal[o1], ba.normal[o2], atol=1e-9)
    assert np.allclose(ab.separation[o1], ba.separation[o2], atol=1e-9)


def test_feature_ids_are_distinct_in_a_pair_and_stable_under_small_motions(scene):
    shapes, hulls, ia, xa, ra, ib, xb, rb = scene
    k = len(ia)
    before = hull_hull(hulls, xa, ra, hulls, xb, rb, 0.2, index_a=ia, index_b=ib)
    assert ((before.feature >= 0) & (before.feature < 256)).all()
    assert len(set(zip(before.pair.tolist(), before.feature.tolist()))) == len(before.pair)
    nudge = small_turns(np.random.default_rng(3), k, 1e-5)
    after = hull_hull(hulls, xa, ra, hulls, xb + 1e-6, nudge @ rb, 0.2, index_a=ia, index_b=ib)
    same = [set(before.feature[before.pair == i]) == set(after.feature[after.pair == i])
            for i in range(k)]
    assert np.mean(same) >= 0.97
    # a cube sliding on a cube (two corners over the face, two edges crossing its side)
    cube = HullShape.from_points(CUBE, "Cube")
    slide = [hull_hull(cube, np.zeros((1, 3)), I3, cube, np.array([[dx, 0.1, 1.99]]), I3, 0.02)
             for dx in (0.2, 0.2001, 0.21, 0.4)]
    assert all(sorted(s.feature.tolist()) == sorted(slide[0].feature.tolist()) for s in slide)
    # a disc (32 corners level on the cube's face) keeps the same 4 of them under rounding
    a = np.linspace(0.0, 2 * np.pi, 33)[:-1]
    disc = HullShape.from_points(np.concatenate(
        [np.stack([0.8 * np.cos(a), 0.8 * np.sin(a), np.full(32, z)], 1) for z in (0.0, 0.2)]))
    rng = np.random.default_rng(5)
    rest = [hull_hull(cube, np.zeros((1, 3)), I3, disc, np.array([[0.1, 0.0, 0.99 + dz]]),
                      small_turns(rng, 1, 1e-12), 0.02) for dz in (0.0, 1e-12, -1e-12, 1e-6)]
    assert all(len(s.pair) == 4 for s in rest)
    assert all(sorted(s.feature.tolist()) == sorted(rest[0].feature.tolist()) for s in rest)


def test_a_box_is_a_hull_of_its_corners():
    rng = np.random.default_rng(11)
    k = 100
    blobs = [HullShape.from_points(blob(rng), f"B{i}") for i in range(3)]
    hulls = HullSet.from_shapes(blobs)
    ia, xa, ra, _, rb = random_pairs(rng, blobs, k)
    half = rng.uniform(0.2, 1.0, (k, 3))
    xb = xa + rng.normal(size=(k, 3)) * 0.7
    boxes = hull_box(hulls, xa, ra, xb, rb, half, 0.1, index=ia)
    corners = [HullShape.from_points(np.array(CUBE) * h) for h in half]
    for i in range(k):
        one = hull_hull(blobs[ia[i]], xa[i:i + 1], ra[i:i + 1], corners[i], xb[i:i + 1],
                        rb[i:i + 1], 0.1)
        mine = boxes.pair == i
        assert np.allclose(np.sort(one.separation), np.sort(boxes.separation[mine]))


def test_batches_grouped_by_size_give_the_same_contacts(scene, monkeypatch):
    shapes, _, ia, xa, ra, ib, xb, rb = scene
    big = HullShape.from_points(np.random.default_rng(2).normal(size=(300, 3)), "Big")
    hulls = HullSet.from_shapes(shapes + [big])
    ia = np.where(np.arange(len(ia)) % 7 == 0, len(shapes), ia)  # some pairs with a big hull
    whole = hull_hull(hulls, xa, ra, hulls, xb, rb, 0.2, index_a=ia, index_b=ib)
    monkeypatch.setattr(narrow_hull, "BATCH_TESTS", 5000)
    parts = hull_hull(hulls, xa, ra, hulls, xb, rb, 0.2, index_a=ia, index_b=ib)
    assert (whole.pair == parts.pair).all() and (whole.feature == parts.feature).all()
    assert np.allclose(whole.point, parts.point) and np.allclose(whole.separation,
                                                                parts.separation)


# --- spheres and capsules ----------------------------------------------------------------------

def test_hull_sphere_is_exact(scene):
    shapes, hulls, ia, xa, ra, _, xb, _ = scene
    radius = np.linspace(0.05, 0.5, len(ia))
    got = hull_sphere(hulls, xa, ra, xb, radius, 0.3, index=ia)
    smin, count = by_pair(got, len(ia))
    exact = np.array([signed_distance(world_vertices(shapes[ia[i]], xa[i], ra[i]), xb[i:i + 1])
                      for i in range(len(ia))]) - radius
    near = exact < 0.3
    assert near.sum() > 100 and count.max() == 1 and (count[near] == 1).all()
    assert np.allclose(smin[near], exact[near], atol=1e-9)
    # the point lies midway: the sphere's surface point is half a separation along the normal
    centre = xb[got.pair] - radius[got.pair, None] * got.normal
    assert np.allclose(got.point + 0.5 * got.separation[:, None] * got.normal, centre)


def test_hull_capsule_matches_the_exact_signed_distance(scene):
    shapes, hulls, ia, xa, ra, _, xb, rb = scene
    k = len(ia)
    radius, half = np.linspace(0.05, 0.3, k), np.linspace(0.01, 0.8, k)[::-1]
    got = hull_capsule(hulls, xa, ra, xb, rb, radius, half, 0.3, index=ia)
    smin, count = by_pair(got, k)
    axis = rb[:, :, 2] * half[:, None]
    exact = np.array([signed_distance(world_vertices(shapes[ia[i]], xa[i], ra[i]),
                                      [xb[i] - axis[i], xb[i] + axis[i]])
                      for i in range(k)]) - radius
    tol = AXIS_TOL_REL * (np.array([shapes[i].radius for i in ia]) + half + radius)
    near = exact < 0.3
    assert near.sum() > 100 and (exact < -radius).sum() > 10  # some cores pierce their hull
    assert (count[near] >= 1).all() and count.max() <= 2
    assert np.all(np.abs(smin[near] - exact[near]) <= tol[near] + 1e-9)
    # the capsule's side of each point lies within its radius of the core (points clipped to
    # a face are the face's points of spheres about the core, deeper in a tilted capsule)
    surface = got.point + 0.5 * got.separation[:, None] * got.normal
    p0, u = (xb - axis)[got.pair], 2.0 * axis[got.pair]
    t = np.clip(np.einsum("ij,ij->i", surface - p0, u) / np.einsum("ij,ij->i", u, u), 0, 1)
    off = np.linalg.norm(surface - p0 - t[:, None] * u, axis=1) - radius[got.pair]
    assert off.max() < 1e-5 and (off > -1e-9).mean() > 0.5


def test_a_capsule_lying_on_a_face_touches_at_both_ends():
    cube = HullShape.from_points(CUBE, "Cube")
    along_x = np.array([[[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]])  # local Z -> X
    lying = hull_capsule(cube, np.zeros((1, 3)), I3, np.array([[0.2, 0.3, 1.19]]), along_x,
                         0.2, 0.5, 0.02)
    assert len(lying.pair) == 2 and np.allclose(lying.separation, -0.01)
    assert np.allclose(lying.normal, [0, 0, 1]) and np.allclose(lying.point[:, 2], 0.995)
    assert np.allclose(np.sort(lying.point[:, 0]), [-0.3, 0.7])
    assert lying.feature[0] != lying.feature[1]
    # hanging over the edge: the clip keeps the part above the face
    over = hull_capsule(cube, np.zeros((1, 3)), I3, np.array([[0.8, 0.3, 1.19]]), along_x,
                        0.2, 0.5, 0.02)
    assert np.allclose(np.sort(over.point[:, 0]), [0.3, 1.0])
    standing = hull_capsule(cube, np.zeros((1, 3)), I3, np.array([[0.2, 0.3, 1.69]]), I3,
                            0.2, 0.5, 0.02)
    assert len(standing.pair) == 1 and np.allclose(standing.separation, -0.01)
    assert np.allclose(standing.point, [[0.2, 0.3, 0.995]])
    assert len(hull_capsule(cube, np.zeros((1, 3)), I3, np.array([[0.2, 0.3, 1.75]]), I3, 0.2,
                            0.5, 0.02).pair) == 0
