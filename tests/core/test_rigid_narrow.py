"""Rigid narrow phase: closed-form contacts (resting, tilted, corner-down and crossed boxes;
spheres and capsules), every separation against brute force on random configurations (exact
distances from vertex-box, point-segment and segment-segment distances; penetration depths from
projections), A/B symmetry, invariance under rigid motions of the whole scene, feature ids that
persist while a box rests, and one call over 10,000 box pairs."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.collision.distance import closest_on_triangles
from physanim.core.collision.sat import obb_overlap
from physanim.core.rigid.narrow import (PairContacts, box_box, capsule_box, capsule_capsule,
                                        capsule_sphere, sphere_box, sphere_sphere)

TOL = 1e-9
SIGNS = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], float)
EDGES = np.array([(v, v | 1 << k) for k in range(3) for v in range(8) if not v >> k & 1])


def _rotations_about(axis, angle):
    """Rotation matrices (n, 3, 3) by ``angle`` (n,) [rad] about ``axis`` (n, 3) (Rodrigues)."""
    axis = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    k = np.zeros((len(axis), 3, 3))
    k[:, [2, 0, 1], [1, 2, 0]] = axis
    k -= np.swapaxes(k, 1, 2)
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * k + (1 - c) * k @ k


def _rotations(rng, n, angle=None):
    """n random rotations: about random axes by up to ``angle`` [rad] (any angle if None)."""
    theta = rng.uniform(0, np.pi, n) if angle is None else angle * rng.uniform(-1, 1, n)
    return _rotations_about(rng.normal(size=(n, 3)), theta)


def _rot(axis, angle):
    """One rotation matrix by ``angle`` [rad] about ``axis``."""
    return _rotations_about(np.asarray(axis, float)[None], np.array([angle]))[0]


def _one(*xs):
    return [np.asarray(x, float)[None] for x in xs]


def _per_pair(c: PairContacts, m: int, values):
    """Minimum of ``values`` (k,) per pair (inf where a pair has no point)."""
    out = np.full(m, np.inf)
    np.minimum.at(out, c.pair, values)
    return out


def _check_contacts(c: PairContacts, most: int):
    """Unit normals, ids in [0, 256) and distinct within each pair, at most ``most`` points."""
    assert np.allclose(np.linalg.norm(c.normal, axis=1), 1.0)
    assert ((c.feature >= 0) & (c.feature < 256)).all()
    key = c.pair * 256 + c.feature
    assert len(np.unique(key)) == len(key)
    assert np.bincount(c.pair).max(initial=0) <= most
    assert (np.diff(c.pair) >= 0).all()


# --- brute force ------------------------------------------------------------------------------

def _box_sdf(p, c, rot, h):
    """Signed distance of points p (n, 3) to boxes, and the number of axes they lie beyond."""
    q = np.abs(np.einsum("nji,nj->ni", rot, p - c)) - h
    return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0), (q > 0).sum(1)


def _point_segment(p, a, b):
    return np.sqrt(closest_on_triangles(p, np.stack([a, b, b], axis=1))[1])


def _segment_segment(p0, p1, q0, q1):
    """Distance between segments (n, 3 endpoints each): endpoints against the other segment,
    and the interior stationary point of the two lines where it lies inside both."""
    best = np.min([_point_segment(p0, q0, q1), _point_segment(p1, q0, q1),
                   _point_segment(q0, p0, p1), _point_segment(q1, p0, p1)], axis=0)
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, b, e = (d1 * d1).sum(1), (d1 * d2).sum(1), (d2 * d2).sum(1)
    c, f = (d1 * r).sum(1), (d2 * r).sum(1)
    det = b * b - a * e
    ok = np.abs(det) > 1e-12
    s = np.where(ok, (c * e - b * f) / np.where(ok, det, 1), -1)
    t = np.where(ok, (b * c - a * f) / np.where(ok, det, 1), -1)
    inner = ok & (s > 0) & (s < 1) & (t > 0) & (t < 1)
    gap = np.linalg.norm(r + s[:, None] * d1 - t[:, None] * d2, axis=1)
    return np.where(inner, np.minimum(best, gap), best)


def _corners(c, rot, h):
    return c[:, None] + np.einsum("nij,nkj->nki", rot, SIGNS[None] * h[:, None])


def _box_distance(ca, ra, ha, cb, rb, hb):
    """Exact distance of disjoint boxes; whether a vertex over a face attains it; whether only
    two edges do."""
    n = len(ca)
    va, vb = _corners(ca, ra, ha), _corners(cb, rb, hb)
    (da, ka), (db, kb) = (_box_sdf(v.reshape(-1, 3), *(np.repeat(x, 8, 0) for x in box))
                          for v, box in ((va, (cb, rb, hb)), (vb, (ca, ra, ha))))
    vert = np.concatenate([da.reshape(n, 8), db.reshape(n, 8)], axis=1)
    face = np.concatenate([ka.reshape(n, 8), kb.reshape(n, 8)], axis=1) == 1
    i, j = np.repeat(np.arange(12), 12), np.tile(np.arange(12), 12)
    edge = _segment_segment(*(x.reshape(-1, 3) for x in (
        va[:, EDGES[i, 0]], va[:, EDGES[i, 1]], vb[:, EDGES[j, 0]], vb[:, EDGES[j, 1]])))
    edge = edge.reshape(n, 144).min(1)
    dist = np.minimum(vert.min(1), edge)
    by_face = np.where(face, vert, np.inf).min(1) <= dist + 1e-12
    return dist, by_face, edge < vert.min(1) - 1e-6


# --- boxes: closed forms -------------------------------------------------------------------------

GROUND = ([0.0, 0.0, 0.0], np.eye(3), [2.0, 2.0, 0.5])
EDGE_DOWN = _rot([1, 0, 0], np.pi / 4)
CORNER_DOWN = _rot([1, -1, 0], np.arctan(np.sqrt(2)))  # the diagonal (1, 1, 1) up


def _resting(rot=None, centre=(0.3, 0.2), depth=1e-3, h=0.5):
    """A cube of half size h turned by ``rot`` whose lowest point is ``depth`` into the ground."""
    rot = np.eye(3) if rot is None else rot
    low = np.abs(rot).sum(axis=1)[2] * h
    return [centre[0], centre[1], 0.5 + low - depth], rot, [h, h, h]


@pytest.mark.parametrize("cube_first", [False, True])
def test_cube_resting_on_a_box_touches_at_its_four_bottom_corners(cube_first):
    ground, cube = _one(*GROUND), _one(*_resting())
    c = box_box(*cube, *ground, 0.01) if cube_first else box_box(*ground, *cube, 0.01)
    _check_contacts(c, 4)
    assert len(c) == 4
    corners = np.array([[0.3 + x, 0.2 + y] for x in (-0.5, 0.5) for y in (-0.5, 0.5)])
    assert np.allclose(np.sort(c.point[:, :2], axis=0), np.sort(corners, axis=0), atol=TOL)
    assert np.allclose(c.point[:, 2], 0.4995, atol=TOL)
    assert np.allclose(c.separation, -1e-3, atol=TOL)
    assert np.allclose(c.normal, [0, 0, -1 if cube_first else 1], atol=TOL)


def test_contacts_move_with_the_whole_configuration():
    rng = np.random.default_rng(0)
    scenes = [(_resting(), 4), (_resting(EDGE_DOWN), 2), (_resting(CORNER_DOWN), 1),
              (_resting(_rot([1, 2, 0], 0.05)), 1)]
    for (cube, count) in scenes:
        base = box_box(*_one(*GROUND), *_one(*cube), 0.01)
        assert len(base) == count
        for rot, shift in zip(_rotations(rng, 5), rng.normal(size=(5, 3)) * 10):
            moved = [(rot @ c + shift, rot @ r, h) for c, r, h in (GROUND, cube)]
            c = box_box(*_one(*moved[0]), *_one(*moved[1]), 0.01)
            assert len(c) == count
            o, p = np.argsort(base.feature), np.argsort(c.feature)
            assert (base.feature[o] == c.feature[p]).all()
            assert np.allclose(c.point[p], base.point[o] @ rot.T + shift, atol=TOL)
            assert np.allclose(c.normal[p], base.normal[o] @ rot.T, atol=TOL)
            assert np.allclose(c.separation[p], base.separation[o], atol=TOL)


def test_tilted_cube_on_an_edge_gives_two_points_and_corner_down_one():
    edge = box_box(*_one(*GROUND), *_one(*_resting(EDGE_DOWN)), 0.01)
    assert len(edge) == 2
    assert np.allclose(np.sort(edge.point[:, 0]), [-0.2, 0.8], atol=TOL)
    assert np.allclose(edge.point[:, 1:], [0.2, 0.4995], atol=TOL)
    assert np.allclose(edge.separation, -1e-3, atol=TOL)
    corner = box_box(*_one(*GROUND), *_one(*_resting(CORNER_DOWN)), 0.01)
    assert len(corner) == 1
    assert np.allclose(corner.point, [0.3, 0.2, 0.4995], atol=TOL)
    assert np.allclose(corner.separation, -1e-3, atol=TOL)
    assert np.allclose(corner.normal, [0, 0, 1], atol=TOL)


def test_crossed_edges_touch_at_their_closest_points():
    ridge = np.sqrt(0.5)
    a = _one([0, 0, 0], _rot([1, 0, 0], np.pi / 4), [0.5, 0.5, 0.5])
    b = _one([0.1, 0.05, 2 * ridge - 0.002], _rot([0, 1, 0], np.pi / 4), [0.5, 0.5, 0.5])
    c = box_box(*a, *b, 0.01)
    assert len(c) == 1
    assert np.allclose(c.point, [0.1, 0.0, ridge - 0.001], atol=TOL)
    assert np.allclose(c.separation, -0.002, atol=TOL)
    assert np.allclose(c.normal, [0, 0, 1], atol=TOL)
    assert c.feature[0] >= 96  # an edge of A against an edge of B


def test_speculative_points_within_the_margin_only():
    cube = _resting(depth=-0.005)
    c = box_box(*_one(*GROUND), *_one(*cube), 0.01)
    assert len(c) == 4 and np.allclose(c.separation, 0.005, atol=TOL)
    assert len(box_box(*_one(*GROUND), *_one(*cube), 0.004)) == 0
    both = [np.repeat(x, 2, axis=0) for x in (*_one(*GROUND), *_one(*cube))]
    c = box_box(*both, np.array([0.004, 0.006]))
    assert (c.pair == 1).all() and len(c) == 4


def test_twisted_stack_keeps_the_four_widest_of_eight_points():
    cube = _one(*_resting(_rot([0, 0, 1], np.pi / 4), (0.0, 0.0)))
    base = _one([0, 0, 0], np.eye(3), [0.5, 0.5, 0.5])
    c = box_box(*base, *cube, 0.01)
    assert len(c) == 4 and np.allclose(c.separation, -1e-3, atol=TOL)
    xy = c.point[np.argsort(np.arctan2(c.point[:, 1], c.point[:, 0])), :2]
    area = 0.5 * np.abs(np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1]))
    assert area > 0.55  # of the octagon's 0.83: no three of the points bunch together


def test_empty_batches_give_no_points():
    z3, z33, z = np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0)
    for c in (sphere_sphere(z3, z, z3, z, 0.1), sphere_box(z3, z, z3, z33, z3, 0.1),
              box_box(z3, z33, z3, z3, z33, z3, 0.1), capsule_sphere(z3, z33, z, z, z3, z, 0.1),
              capsule_capsule(z3, z33, z, z, z3, z33, z, z, 0.1),
              capsule_box(z3, z33, z, z, z3, z33, z3, 0.1), PairContacts.empty().swapped()):
        assert len(c) == 0 and c.point.shape == (0, 3) and c.feature.dtype == np.int64


# --- boxes: brute force, symmetry, persistence, size ---------------------------------------------

def _random_boxes(rng, n, spread):
    return (rng.normal(size=(n, 3)) * spread, _rotations(rng, n), rng.uniform(0.1, 1.0, (n, 3)),
            rng.normal(size=(n, 3)) * spread, _rotations(rng, n), rng.uniform(0.1, 1.0, (n, 3)))


def _normal_gap(boxes, c: PairContacts):
    """(k,) gap between the boxes' projections on each point's normal (none separates less)."""
    va, vb = (_corners(*(b[c.pair] for b in bs)) for bs in (boxes[:3], boxes[3:]))
    return (np.einsum("kvi,ki->kv", vb, c.normal).min(1)
            - np.einsum("kvi,ki->kv", va, c.normal).max(1))


def test_separated_boxes_against_exact_distances():
    rng = np.random.default_rng(1)
    boxes = _random_boxes(rng, 3000, 1.5)
    apart = ~obb_overlap(*(np.swapaxes(b, 1, 2) if b.ndim == 3 else b for b in boxes))  # rows
    boxes = [b[apart] for b in boxes]
    n = len(boxes[0])
    dist, by_face, by_edges = _box_distance(*boxes)
    c = box_box(*boxes, 100.0)
    _check_contacts(c, 4)
    low = _per_pair(c, n, c.separation)
    assert np.isfinite(low).all()  # every pair within the margin has a point
    assert np.abs(low - dist)[by_face].max() < TOL  # exact when a vertex over a face is closest
    assert by_face.sum() > 300
    # an edge axis (normal along no box axis) is exact when two edges are closest
    face_normal = [np.abs(np.einsum("kji,kj->ki", r[c.pair], c.normal)).max(1) > 1 - TOL
                   for r in (boxes[1], boxes[4])]
    edge_axis = _per_pair(c, n, np.where(face_normal[0] | face_normal[1], 1.0, 0.0)) == 0.0
    assert np.abs(low - dist)[by_edges & edge_axis].max() < TOL
    assert (by_edges & edge_axis).sum() > 100
    assert (c.separation >= _normal_gap(boxes, c) - TOL).all()


def test_resting_boxes_penetration_depth_along_the_normal():
    rng = np.random.default_rng(2)
    n = 2000
    rot = _rotations(rng, n, 0.3)
    h = rng.uniform(0.2, 0.6, (n, 3))
    depth = rng.uniform(-0.02, 0.02, n)
    low = np.abs(rot * h[:, None]).sum(axis=2)[:, 2]
    small = (np.column_stack([rng.uniform(-1, 1, (n, 2)), 0.5 + low - depth]), rot, h)
    ground = (np.zeros((n, 3)), np.repeat(np.eye(3)[None], n, 0), np.tile([3.0, 3.0, 0.5], (n, 1)))
    for first, second, up in ((ground, small, 1), (small, ground, -1)):
        c = box_box(*first, *second, 0.05)
        _check_contacts(c, 4)
        assert np.allclose(c.normal, [0, 0, up], atol=TOL)
        assert np.abs(_per_pair(c, n, c.separation) + depth).max() < TOL


def test_swapping_boxes_negates_normals_and_keeps_points():
    rng = np.random.default_rng(3)
    a = _random_boxes(rng, 3000, 0.6)
    b = a[3:] + a[:3]
    ab, ba = box_box(*a, 0.05), box_box(*b, 0.05)
    assert len(ab) > 2000 and (ab.pair == ba.pair).all()
    key = lambda c: np.lexsort((c.point[:, 2], c.point[:, 1], c.point[:, 0], c.pair))  # noqa: E731
    o, p = key(ab), key(ba.swapped())
    assert np.allclose(ab.point[o], ba.point[p], atol=TOL)
    assert np.allclose(ab.normal[o], -ba.normal[p], atol=TOL)
    assert np.allclose(ab.separation[o], ba.separation[p], atol=TOL)
    assert (ab.separation >= _normal_gap(a, ab) - TOL).all()


@pytest.mark.parametrize("cube_first", [False, True])
def test_feature_ids_persist_while_a_box_rests(cube_first):
    rng = np.random.default_rng(4)
    ids = None
    for rot, shift, depth in zip(_rotations(rng, 40, 2e-4), rng.normal(size=(40, 2)) * 1e-3,
                                 rng.uniform(0, 2e-3, 40)):
        cube = _one(*_resting(rot, (0.3 + shift[0], 0.2 + shift[1]), depth))
        c = box_box(*cube, *_one(*GROUND), 0.01) if cube_first else \
            box_box(*_one(*GROUND), *cube, 0.01)
        assert len(c) == 4
        ids = set(c.feature) if ids is None else ids
        assert set(c.feature) == ids


def test_ten_thousand_box_pairs_in_one_call():
    rng = np.random.default_rng(5)
    c = box_box(*_random_boxes(rng, 10_000, 0.8), 0.02)
    _check_contacts(c, 4)
    assert len(np.unique(c.pair)) > 3000


# --- spheres and capsules --------------------------------------------------------------------------

def test_sphere_closed_forms():
    assert len(sphere_sphere(*_one([0, 0, 0], 1.0, [0, 0, 2.5], 1.0), 0.01)) == 0
    c = sphere_sphere(*_one([0, 0, 0], 1.0, [0, 3, 0], 2.5), 0.01)
    assert np.allclose(c.normal, [0, 1, 0]) and np.allclose(c.separation, -0.5)
    assert np.allclose(c.point, [0, 0.75, 0])
    box = ([0, 0, 0], np.eye(3), [1.0, 2.0, 3.0])
    for centre, sep, normal in (([0, 0, 3.4], -0.1, [0, 0, -1]), ([1.3, 2.4, 0], 0.0, [-0.6, -0.8, 0]),
                                ([1.2, 2.2, 3.2], np.sqrt(0.12) - 0.5, -np.ones(3) / np.sqrt(3)),
                                ([0.8, 0, 0], -0.7, [-1, 0, 0])):
        c = sphere_box(*_one(centre, 0.5), *_one(*box), 0.01)
        assert np.allclose(c.separation, sep) and np.allclose(c.normal, normal)
    axis_x = _rot([0, 1, 0], np.pi / 2)
    c = capsule_sphere(*_one([0, 0, 0], axis_x, 0.2, 1.0, [0.5, 0, 0.45], 0.3), 0.01)
    assert np.allclose(c.separation, -0.05) and np.allclose(c.normal, [0, 0, 1])
    assert np.allclose(c.point, [0.5, 0, 0.175]) and c.feature[0] == 1
    c = capsule_sphere(*_one([0, 0, 0], axis_x, 0.2, 1.0, [1.6, 0, 0], 0.3), 0.2)
    assert np.allclose(c.separation, 0.1) and np.allclose(c.normal, [1, 0, 0]) and c.feature == 2


def test_capsule_closed_forms():
    axis_x, axis_y = _rot([0, 1, 0], np.pi / 2), _rot([1, 0, 0], np.pi / 2)
    crossed = capsule_capsule(*_one([0, 0, 0], axis_x, 0.2, 1.0, [0.3, 0.4, 0.499], axis_y, 0.3,
                                    1.0), 0.01)
    assert len(crossed) == 1 and np.allclose(crossed.separation, -0.001)
    assert np.allclose(crossed.point, [0.3, 0.0, 0.1995]) and np.allclose(crossed.normal, [0, 0, 1])
    lying = capsule_capsule(*_one([0, 0, 0], axis_x, 0.2, 1.0, [0.5, 0, 0.498], axis_x, 0.3,
                                  1.0), 0.01)
    assert len(lying) == 2 and np.allclose(lying.separation, -0.002)
    assert np.allclose(np.sort(lying.point[:, 0]), [-0.5, 1.0])
    ground = _one([0, 0, 0], np.eye(3), [2.0, 2.0, 0.5])
    flat = capsule_box(*_one([1.5, 0, 0.599], axis_x, 0.1, 1.0), *ground, 0.01)
    assert len(flat) == 2 and np.allclose(flat.separation, -0.001)
    assert np.allclose(np.sort(flat.point[:, 0]), [0.5, 2.0]) and np.allclose(flat.normal, [0, 0, -1])
    upright = capsule_box(*_one([0.2, 0.1, 1.599], np.eye(3), 0.1, 1.0), *ground, 0.01)
    assert len(upright) == 1 and np.allclose(upright.point, [0.2, 0.1, 0.4995])
    a = (0.1 - 0.001) / np.sqrt(2)
    on_edge = capsule_box(*_one([2 + a, 0.3, 0.5 + a], axis_y, 0.1, 1.0), *ground, 0.01)
    assert len(on_edge) == 1 and np.allclose(on_edge.separation, -0.001)
    assert np.allclose(on_edge.normal, [-np.sqrt(0.5), 0, -np.sqrt(0.5)])
    tilted = capsule_box(*_one([0, 0, 0.599 + np.sin(0.01)], _rot([0, 1, 0], np.pi / 2 - 0.01),
                               0.1, 1.0), *ground, 0.03)
    assert len(tilted) == 2 and np.allclose(np.sort(tilted.separation), [-0.001, 2 * np.sin(0.01) - 0.001])
    deep = capsule_box(*_one([0, 0, 0.45], axis_x, 0.1, 0.3), *ground, 0.01)
    assert len(deep) == 2 and np.allclose(deep.separation, -0.15)
    assert np.allclose(deep.normal, [0, 0, -1])


def _random_capsules(rng, n, spread, parallel=0.0):
    rot = _rotations(rng, n)
    tilt = _rotations(rng, n, parallel) if parallel else _rotations(rng, n)
    return (rng.normal(size=(n, 3)) * spread, rot, rng.uniform(0.05, 0.4, n),
            rng.uniform(0, 1.0, n), rng.normal(size=(n, 3)) * spread,
            rot @ tilt if parallel else tilt, rng.uniform(0.05, 0.4, n), rng.uniform(0, 1.0, n))


def _ends(c, rot, half):
    return c - half[:, None] * rot[:, :, 2], c + half[:, None] * rot[:, :, 2]


@pytest.mark.parametrize("parallel", [0.0, 0.02, 1e-12])
def test_capsules_against_exact_distances(parallel):
    rng = np.random.default_rng(6)
    n = 4000
    ca, ra_, r_a, la, cb, rb_, r_b, lb = caps = _random_capsules(rng, n, 0.5, parallel)
    truth = _segment_segment(*_ends(ca, ra_, la), *_ends(cb, rb_, lb)) - r_a - r_b
    c = capsule_capsule(*caps, 10.0)
    _check_contacts(c, 2)
    core_apart = truth + r_a + r_b > 1e-6
    assert np.abs(_per_pair(c, n, c.separation) - truth)[core_apart].max() < TOL
    swapped = capsule_capsule(*caps[4:], *caps[:4], 10.0).swapped()
    assert np.allclose(np.sort(c.separation), np.sort(swapped.separation), atol=TOL)
    sphere = capsule_sphere(ca, ra_, r_a, la, cb, r_b, 10.0)
    near = _point_segment(cb, *_ends(ca, ra_, la)) - r_a - r_b
    assert np.abs(sphere.separation - near).max() < TOL
    pair = sphere_sphere(ca, r_a, cb, r_b, 10.0)
    assert np.abs(pair.separation - (np.linalg.norm(cb - ca, axis=1) - r_a - r_b)).max() < TOL
    assert np.allclose(sphere_sphere(cb, r_b, ca, r_a, 10.0).point, pair.point)


def test_spheres_and_capsules_against_boxes_match_exact_distances():
    rng = np.random.default_rng(7)
    n = 4000
    cc, rc_, r, half, cb, rb_, _, _ = _random_capsules(rng, n, 0.8)
    hb = rng.uniform(0.1, 1.0, (n, 3))
    ends = _ends(cc, rc_, half)
    segment = np.column_stack([np.zeros((n, 2)), half])  # a box of zero width: exact SAT
    apart = ~obb_overlap(cc, np.swapaxes(rc_, 1, 2), segment, cb, np.swapaxes(rb_, 1, 2), hb)
    corners = _corners(cb, rb_, hb)
    edge = [np.repeat(x, 12, 0) for x in ends] + [corners[:, EDGES[:, k]].reshape(-1, 3)
                                                  for k in (0, 1)]
    truth = np.minimum(np.minimum(*(_box_sdf(e, cb, rb_, hb)[0] for e in ends)),
                       _segment_segment(*edge).reshape(n, 12).min(1)) - r
    c = capsule_box(cc, rc_, r, half, cb, rb_, hb, 10.0)
    _check_contacts(c, 2)
    assert np.abs(_per_pair(c, n, c.separation) - truth)[apart].max() < TOL
    assert apart.mean() > 0.5
    s = sphere_box(cc, r, cb, rb_, hb, 10.0)
    assert np.abs(s.separation - (_box_sdf(cc, cb, rb_, hb)[0] - r)).max() < TOL
    assert np.allclose(np.linalg.norm(s.normal, axis=1), 1.0)


def test_clipping_skips_only_the_faces_a_side_plane_does_not_cut():
    # clip_face clips each side plane only where a corner lies beyond it; every face it skips
    # is one that plane leaves as it is: the same polygons, counts and labels as clipping all
    from physanim.core.rigid.narrow_clip import (CAPACITY, PLANE_AXIS, PLANE_SIGN, _clip_plane,
                                                 clip_face)

    rng = np.random.default_rng(4)
    m = 500
    half = rng.uniform(0.2, 0.6, (m, 3))
    ref_face = rng.integers(0, 6, m)
    centre = rng.uniform(-0.5, 0.5, (m, 3))
    spin = rng.uniform(0.0, 2.0 * np.pi, m)
    square = np.stack([np.cos(spin + k * np.pi / 2) for k in range(4)], 1)[..., None] * \
        np.array([1.0, 0.0, 0.0]) + np.stack([np.sin(spin + k * np.pi / 2)
                                              for k in range(4)], 1)[..., None] * \
        np.array([0.0, 1.0, 0.0])
    corners = centre[:, None] + rng.uniform(0.05, 0.7, (m, 1, 1)) * square
    corners[: m // 4] = 0.3 * half[: m // 4, None] * np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0],
                                                               [-1, 1, 0]])  # inside: no cut
    poly, count, labels = clip_face(corners, half, ref_face)
    want = np.zeros((m, CAPACITY, 3))
    want[:, :4] = corners
    w_count, w_labels = np.full(m, 4), np.zeros((m, CAPACITY), np.int64)
    w_labels[:, :4] = np.arange(4)
    edges = w_labels.copy()
    for k in range(4):
        axis = PLANE_AXIS[ref_face, k]
        want, w_count, w_labels, edges = _clip_plane(want, w_count, w_labels, edges, axis,
                                                     PLANE_SIGN[ref_face, k],
                                                     half[np.arange(m), axis], k)
    assert (count != 4).sum() > m // 4  # many were cut
    np.testing.assert_array_equal(count, w_count)
    live = np.arange(CAPACITY) < count[:, None]
    np.testing.assert_array_equal(poly[live], want[live])
    np.testing.assert_array_equal(labels[live], w_labels[live])
