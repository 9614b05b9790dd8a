"""``ColliderPath.apart``: one bound over a set of points that tells the colliders' questions
(near the surface, first hits of segments, inside) will find nothing — exactly where they find
nothing, for a ground or bounded plane standing still, and never for what it cannot bound."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.contact import ColliderFrame, ColliderPaths
from physanim.core.contact.path import CONTACT_DISTANCE, SKIN

DT = 1.0 / 24.0


def _turn(axis: int, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    i, j = [k for k in range(3) if k != axis]
    m = np.eye(4)
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


MATRICES = {
    "identity": np.eye(4),
    "moved and scaled": np.diag([3.0, 2.0, 0.5, 1.0]) + np.array(
        [[0, 0, 0, 1.5], [0, 0, 0, -2.0], [0, 0, 0, 0.25], [0, 0, 0, 0]]),
    "upside down": np.diag([1.0, -1.0, -2.0, 1.0]),  # turned over exactly (one axis)
    "turned": _turn(0, 0.3) @ _turn(1, -0.2),
}


def _path(shape: str, m: np.ndarray, m1: np.ndarray | None = None, thickness: float = 0.0):
    frame = ColliderFrame("Ground", shape, m, m if m1 is None else m1, 0.5, 0.3,
                          thickness=thickness)
    return ColliderPaths().of([frame], DT)[0]


def _clouds(rng, path) -> list[np.ndarray]:
    """Point clouds about the collider's surface, from touching it to a metre off it, on both
    sides, some with one point placed within a rounding of the contact distance."""
    m = path.path.m0
    normal = np.linalg.inv(m)[2, :3]
    normal = normal / np.linalg.norm(normal)
    origin = m[:3, 3]
    out = []
    for offset in (-1.0, -0.01, -CONTACT_DISTANCE, 0.0, 2e-4, CONTACT_DISTANCE, 0.0011, 0.01,
                   0.5, 1.0):
        spread = rng.uniform(0.0, 0.2, (50, 1)) if offset else np.zeros((50, 1))
        spread[0] = 0.0  # the nearest point right at the offset, the others up to 0.2 m off
        side = np.sign(offset) or 1.0
        x = origin + rng.uniform(-1.0, 1.0, (50, 3)) @ np.diag([0.8, 0.8, 0.0]) @ m[:3, :3].T
        x = x - (x - origin) @ np.outer(normal, normal) + (offset + side * spread) * normal
        out.append(x)
    return out


@pytest.mark.parametrize("shape", ["HALF_SPACE", "PLANE"])
@pytest.mark.parametrize("name", list(MATRICES))
@pytest.mark.parametrize("thickness", [0.0, 0.02])
def test_apart_means_the_questions_find_nothing(shape, name, thickness):
    rng = np.random.default_rng(7)
    path = _path(shape, MATRICES[name], thickness=thickness)
    said_apart = {"near": 0, "segments": 0}
    for x0 in _clouds(rng, path):
        near = path.near_surface(x0, 0.0)
        if path.apart((x0,), 0.0, CONTACT_DISTANCE):
            said_apart["near"] += 1
            assert len(near.index) == 0
        for step in (np.zeros(3), np.array([0.0, 0.0, -0.05]), np.array([0.1, 0.0, 0.3])):
            x1 = x0 + step
            n = len(x0)
            hits = path.first_hits(x0, x1, np.zeros(n), np.ones(n))
            inside = path.push_out(x1, np.ones(n), x0, np.zeros(n))
            if path.apart((x0, x1), 0.0, SKIN):
                said_apart["segments"] += 1
                assert len(hits.index) == 0 and len(inside.index) == 0
    # and it does say so for the clouds well away (else nothing would be skipped)
    assert said_apart["near"] >= 2 and said_apart["segments"] >= 4, said_apart


def test_apart_is_exact_at_the_contact_distance():
    """A point exactly at the contact distance is not near (the test is strict), and apart;
    one a rounding closer is near, and not apart."""
    path = _path("HALF_SPACE", np.eye(4))
    far = np.array([[0.0, 0.0, 5.0]])
    for z, near in ((CONTACT_DISTANCE, False), (np.nextafter(CONTACT_DISTANCE, 0.0), True)):
        x = np.vstack([far, [[0.3, -0.2, z]]])
        assert (len(path.near_surface(x, 0.0).index) == 1) == near
        assert path.apart((x,), 0.0, CONTACT_DISTANCE) == (not near)


def test_apart_answers_false_where_it_cannot_bound():
    x = np.array([[0.0, 0.0, 5.0], [1.0, 1.0, 6.0]])
    assert not _path("SPHERE", np.eye(4)).apart((x,), 0.0, CONTACT_DISTANCE)
    assert not _path("BOX", np.eye(4)).apart((x,), 0.0, CONTACT_DISTANCE)
    moving = np.eye(4)
    moving[2, 3] = 0.1
    assert not _path("HALF_SPACE", np.eye(4), moving).apart((x,), 0.0, CONTACT_DISTANCE)
    ground = _path("HALF_SPACE", np.eye(4))
    assert ground.apart((x,), 0.0, CONTACT_DISTANCE)
    assert ground.apart((np.zeros((0, 3)),), 0.0, CONTACT_DISTANCE)
    for bad in (np.nan, np.inf, -np.inf):
        y = x.copy()
        y[1, 2] = bad
        assert not ground.apart((y,), 0.0, CONTACT_DISTANCE) or bad == np.inf
    # a plane is apart only when every point is on one side
    plane = _path("PLANE", np.eye(4))
    assert plane.apart((x,), 0.0, CONTACT_DISTANCE)
    assert plane.apart((-x,), 0.0, CONTACT_DISTANCE)
    assert not plane.apart((x, -x), 0.0, CONTACT_DISTANCE)


# -- spheres and boxes standing still: only the points near their world box are tested ------

SOLIDS = {
    "unit": np.eye(4),
    "moved and scaled": MATRICES["moved and scaled"],
    "turned and stretched": _turn(2, 0.785) @ _turn(0, 0.4) @ np.diag([8.0, 0.1, 1.0, 1.0]),
    "turned": _turn(2, 0.785) @ _turn(1, 0.3) @ np.diag([1.5, 1.0, 0.7, 1.0]),
}


def _around(rng, path, count: int = 3000) -> np.ndarray:
    """Points about the shape: on its world surface pushed out or in by up to a few contact
    distances (those are the ones judged near), and a third as many several sizes away."""
    m = path.path.m0
    u = rng.normal(size=(count, 3))
    if path.frame.shape == "SPHERE":
        u = u / np.linalg.norm(u, axis=1, keepdims=True) * path.extent[0]
    else:  # on the box's faces, edges and corners
        u = np.clip(u, -1.0, 1.0) * path.extent
        face = rng.integers(0, 3, count)
        u[np.arange(count), face] = np.sign(u[np.arange(count), face] + 1e-12) * path.extent[face]
    world = u @ m[:3, :3].T + m[:3, 3]
    push = rng.normal(size=(count, 3))
    push *= rng.uniform(0.0, 4.0 * CONTACT_DISTANCE, (count, 1)) / np.linalg.norm(push, axis=1,
                                                                                 keepdims=True)
    far = world[:count // 2] - m[:3, 3]
    far = far * rng.uniform(3.0, 6.0, (len(far), 1)) + m[:3, 3]  # well outside its world box
    return np.vstack([world + push, far])


def _questions(path, x0: np.ndarray, x1: np.ndarray) -> tuple:
    """The path's three answers for points x0 (near the surface) and paths x0 -> x1 over the
    interval (first hits, then x1 pushed out)."""
    n = len(x0)
    ones, zeros = np.ones(n), np.zeros(n)
    return (path.near_surface(x0, 0.0), path.first_hits(x0, x1, zeros, ones),
            path.push_out(x1, ones, x0, zeros))


def _assert_same(got: tuple, want: tuple) -> None:
    for a, b in zip(got, want):
        for key, value in vars(b).items():
            if isinstance(value, np.ndarray):
                assert np.array_equal(getattr(a, key), value), key


def _unbounded(path, monkeypatch):
    """The same path answering without its world box (every point tested)."""
    monkeypatch.setattr(type(path), "_bounds", lambda self: None)


@pytest.mark.parametrize("shape", ["SPHERE", "BOX"])
@pytest.mark.parametrize("name", list(SOLIDS))
@pytest.mark.parametrize("thickness", [0.0, 0.03])
def test_a_still_solid_answers_as_if_every_point_were_tested(shape, name, thickness,
                                                             monkeypatch):
    rng = np.random.default_rng(11)
    path = _path(shape, SOLIDS[name], thickness=thickness)
    x0 = _around(rng, path)
    x1 = x0 + rng.normal(scale=0.05, size=x0.shape)
    n = len(x0)
    near, hits, inside = answers = _questions(path, x0, x1)
    assert len(path._within(CONTACT_DISTANCE, x0)) <= n - n // 4  # the far ones skipped ...
    assert len(near.index) > 100 and len(hits.index) > 10 and len(inside.index) > 100  # ... not all
    _unbounded(path, monkeypatch)
    _assert_same(answers, _questions(path, x0, x1))


def _moving(m: np.ndarray) -> tuple:
    """A motion from ``m``: moved 5 cm, turned 0.2 rad and stretched by a tenth along one axis
    over the interval, with a sub-frame sample off the straight line."""
    m1 = np.eye(4)
    m1[:3, 3] = (0.05, -0.02, 0.03)
    m1 = m1 @ m @ _turn(1, 0.2) @ np.diag([1.0, 1.1, 1.0, 1.0])
    mid = 0.5 * (m + m1)
    mid[:3, 3] += (0.0, 0.03, 0.0)
    return m1, np.stack([m, mid, m1])


@pytest.mark.parametrize("shape", ["SPHERE", "BOX"])
@pytest.mark.parametrize("name", list(SOLIDS))
@pytest.mark.parametrize("thickness", [0.0, 0.03])
def test_a_moving_solid_answers_as_if_every_point_were_tested(shape, name, thickness,
                                                              monkeypatch):
    """A moving sphere or box tests only the points whose local box meets its own (grown by
    the contact distance where near is asked): the same answers as every point tested, at one
    time for all points and at times of their own."""
    rng = np.random.default_rng(12)
    m1, samples = _moving(SOLIDS[name])
    frame = ColliderFrame("Solid", shape, SOLIDS[name], m1, 0.5, 0.3, thickness=thickness,
                          matrices=samples)
    path = ColliderPaths().of([frame], DT)[0]
    assert not path.path.static
    x0 = _around(rng, path)
    x1 = x0 + rng.normal(scale=0.05, size=x0.shape)
    n = len(x0)
    mid = rng.uniform(0.3, 0.7, n)
    asked = []
    cuts = {"_local_rows": type(path)._local_rows, "_moving_rows": type(path)._moving_rows}

    def counted(cut):
        def count(self, *args):
            rows = cuts[cut](self, *args)
            given = next(len(a) for a in args if np.ndim(a) == 2)  # (after an earlier cut)
            asked.append(given if rows is None else len(rows))
            return rows
        return count
    for cut in cuts:
        monkeypatch.setattr(type(path), cut, counted(cut))
    answers = _questions(path, x0, x1) + (
        path.near_surface(x1, 0.6), path.first_hits(x0, x1, mid - 0.3, mid + 0.3))
    near, hits, inside, near_later, hits_own = answers
    assert max(asked) <= n - n // 4  # the far ones skipped ...
    assert len(near.index) > 100 and len(hits.index) > 10 and len(inside.index) > 100
    assert len(near_later.index) > 3 and len(hits_own.index) > 10  # ... not all
    for cut in cuts:
        monkeypatch.setattr(type(path), cut, lambda self, *args: None)
    _assert_same(answers, _questions(path, x0, x1) + (
        path.near_surface(x1, 0.6), path.first_hits(x0, x1, mid - 0.3, mid + 0.3)))


@pytest.mark.parametrize("shape", ["SPHERE", "BOX"])
@pytest.mark.parametrize("moving", [False, True])
def test_long_segments_grazing_a_small_solid_are_answered_as_every_segment_tested(
        shape, moving, monkeypatch):
    """Segments many radii long passing a hair's breadth off a 1 mm sphere or box, where the
    shape's own test rounds (a sphere's discriminant by about eps |l|^2): the cut lets every
    one the test would find through (a pad of a billionth of the shape fell short)."""
    r = 1e-3
    m0 = np.diag([r, r, r, 1.0])
    m1 = m0.copy()
    m1[2, 3] = 1e-6 if moving else 0.0
    path = ColliderPaths().of([ColliderFrame("Small", shape, m0, m1)], DT)[0]
    offsets = np.geomspace(1e-12, 1e-6, 40) * r
    starts, ends = [], []
    for length in (0.05, 1.0, 10.0, 30.0):
        for side in (1.0, -1.0):
            x = side * (r + offsets)
            starts.append(np.column_stack([x, np.full_like(x, -length), np.zeros_like(x)]))
            ends.append(np.column_stack([x, np.full_like(x, length), np.zeros_like(x)]))
    start, end = np.vstack(starts), np.vstack(ends)
    far = np.array([[0.0, 5.0, 5.0]])  # and one segment far off: a cut is made
    start, end = np.vstack([start, far]), np.vstack([end, far + 1.0])
    s = np.zeros(len(start))
    got = path.first_hits(start, end, s, s)
    monkeypatch.setattr(type(path), "_local_rows", lambda self, *args: None)
    monkeypatch.setattr(type(path), "_bounds", lambda self: None)
    _assert_same((got,), (path.first_hits(start, end, s, s),))


def _sweeps(m: np.ndarray) -> dict:
    """Motions from ``m`` over one sub-step, about the shape's origin, as a rigid body's or an
    animated object's: slow (moved 5 cm, turned 0.05 rad), a fast move (more than its own
    size), a fast turn (0.4 rad) and a growth by a third."""
    def about(k):
        out = np.eye(4)
        out[:3, 3] = m[:3, 3]
        return out @ k @ np.linalg.inv(out) @ m
    slow = about(_turn(1, 0.05))
    slow[:3, 3] += (0.05, -0.02, 0.03)
    fast = m.copy()
    fast[:3, 3] += (2.5, -1.0, 0.5)
    return {"slow": slow, "fast move": fast, "fast turn": about(_turn(2, 0.4) @ _turn(0, 0.1)),
            "growing": about(np.diag([1.3, 1.3, 1.3, 1.0]))}


def _far_from(rng, m0: np.ndarray, m1: np.ndarray, count: int = 600) -> np.ndarray:
    """Points far from everywhere a collider moving from m0 to m1 goes (4 to 10 times its size
    and its move away from its start)."""
    size = float(np.abs(m0[:3, :3]).sum()) + float(np.linalg.norm(m1[:3, 3] - m0[:3, 3]))
    way = rng.normal(size=(count, 3))
    return m0[:3, 3] + way / np.linalg.norm(way, axis=1, keepdims=True) * rng.uniform(
        4.0 * size, 10.0 * size, (count, 1))


def _counted_sweeps(monkeypatch, path, n: int) -> list:
    """How many of ``n`` rows each of the path's segment cuts keeps (appended as it cuts)."""
    kept = []
    sweep_rows = type(path).sweep_rows

    def counted(self, *args):
        rows = sweep_rows(self, *args)
        kept.append(n if rows is None else len(rows))
        return rows
    monkeypatch.setattr(type(path), "sweep_rows", counted)
    return kept


@pytest.mark.parametrize("shape", ["SPHERE", "BOX"])
@pytest.mark.parametrize("name", list(SOLIDS))
@pytest.mark.parametrize("motion", ["slow", "fast move", "fast turn", "growing"])
def test_a_moving_solid_cuts_segments_over_their_time_as_if_every_one_were_tested(
        shape, name, motion, monkeypatch):
    """Segments over one time span (the first pass of every sub-step) meet a moving sphere or
    box only within a world box about it (:meth:`AnalyticPath._sweep_box`): every hit, and
    every point the shape moved onto, as when every segment is mapped into its frame. Points
    lying still where it sweeps over them (which only its move brings it to), segments about
    its surface, and far ones, which the cut skips."""
    rng = np.random.default_rng(21)
    m0 = SOLIDS[name]
    m1 = _sweeps(m0)[motion]
    path = _path(shape, m0, m1, thickness=0.02)
    x0 = _around(rng, path, 2000)
    x1 = x0 + rng.normal(scale=0.05, size=x0.shape)
    swept = np.linspace(0.0, 1.0, 400)[:, None] * (m1[:3, 3] - m0[:3, 3]) + m0[:3, 3] + \
        rng.normal(scale=0.3, size=(400, 3)) * np.abs(np.diag(m0)[:3])
    far = _far_from(rng, m0, m1)
    x0 = np.vstack([x0, swept, far])
    x1 = np.vstack([x1, swept, far + rng.normal(scale=0.05, size=far.shape)])
    n = len(x0)
    kept = _counted_sweeps(monkeypatch, path, n)
    for times in ((np.zeros(n), np.ones(n)), (np.full(n, 0.25), np.full(n, 0.75))):
        times = times if times[0][0] else tuple(np.broadcast_to(t[:1], (n,)) for t in times)
        got = path.first_hits(x0, x1, *times)
        assert kept[-1] <= n - len(far)  # the far ones skipped ...
        assert len(got.index) > 20  # ... not the hits
        with monkeypatch.context() as every:
            every.setattr(type(path), "sweep_rows", lambda self, *args: None)
            _assert_same((got,), (path.first_hits(x0, x1, *times),))


def test_a_solid_moving_over_still_points_finds_them_all():
    """A box moving ten times its size in one sub-step over points lying still along its way:
    each one it reaches is found (its hit, or inside at the end), however far from where the
    box started — the cut's box about its start is grown by how far it moves."""
    m0, m1 = np.diag([0.2, 0.2, 0.2, 1.0]), np.diag([0.2, 0.2, 0.2, 1.0])
    m1[0, 3] = 4.0
    path = _path("BOX", m0, m1)
    x = np.column_stack([np.linspace(0.5, 3.9, 50), np.zeros(50), np.zeros(50)])
    times = (np.broadcast_to(0.0, (50,)), np.broadcast_to(1.0, (50,)))
    assert path.first_hits(x, x, *times).index.tolist() == list(range(50))


def test_a_turning_box_finds_what_its_turn_reaches(monkeypatch):
    """A box turning 0.4 rad in one sub-step: long segments crossing where it turns to (its
    local segment bends with the turn: some pass more than 2 m off its box at the start and
    still hit), and points lying still that its corners sweep over. Every one is found, as
    when every segment is tested."""
    m1 = _turn(2, 0.4)
    path = _path("BOX", np.eye(4), m1)
    rng = np.random.default_rng(5)
    n = 3000
    length, angle = rng.uniform(5.0, 40.0, n), rng.uniform(0.0, 2.0 * np.pi, n)
    along = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(n)])
    across = np.column_stack([-np.sin(angle), np.cos(angle), np.zeros(n)])
    centre = across * rng.uniform(-6.0, 6.0, (n, 1)) + along * rng.uniform(-3.0, 3.0, (n, 1))
    long0, long1 = centre - along * length[:, None] / 2, centre + along * length[:, None] / 2
    ring = rng.uniform(-1.0, 1.0, (n, 2)) * 1.45
    still = np.column_stack([ring, rng.uniform(-0.9, 0.9, n)])
    still = still[np.abs(still[:, :2]).max(axis=1) > 1.0]  # outside it at the start
    times = (np.broadcast_to(0.0, (n,)), np.broadcast_to(1.0, (n,)))
    got = [path.first_hits(long0, long1, *times),
           path.first_hits(still, still, *(t[:len(still)] for t in times))]
    lo, hi = np.minimum(long0, long1)[got[0].index], np.maximum(long0, long1)[got[0].index]
    assert np.maximum(lo - 1.0, -1.0 - hi).max() > 2.0  # hits far off its box at the start
    assert len(got[1].index) > 100
    monkeypatch.setattr(type(path), "sweep_rows", lambda self, *args: None)
    _assert_same(got, [path.first_hits(long0, long1, *times),
                       path.first_hits(still, still, *(t[:len(still)] for t in times))])


def test_a_moving_solid_tests_every_point():
    moving = np.eye(4)
    moving[0, 3] = 0.2
    x = np.array([[5.0, 5.0, 5.0]])
    assert _path("SPHERE", np.eye(4), moving)._within(0.0, x) is None
    assert _path("HALF_SPACE", np.eye(4))._within(0.0, x) is None
    assert len(_path("BOX", np.eye(4))._within(0.0, x)) == 0


def _wavy(n: int = 30):
    u = np.linspace(-1.0, 1.0, n)
    gx, gy = np.meshgrid(u, u)
    verts = np.column_stack([gx.ravel(), gy.ravel(), 0.3 * np.sin(3.0 * gx.ravel())])
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(), i[:-1, 1:].ravel()
    return verts, np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


@pytest.mark.parametrize("name", ["unit", "turned and stretched", "turned"])
@pytest.mark.parametrize("thickness", [0.0, 0.03])
def test_a_still_mesh_answers_as_if_every_point_were_tested(name, thickness, monkeypatch):
    verts, tris = _wavy()
    m = SOLIDS[name]
    frame = ColliderFrame("Wavy", "MESH", m, m, 0.5, 0.3, thickness=thickness, vertices0=verts,
                          vertices1=verts, triangles=tris)
    path = ColliderPaths().of([frame], DT)[0]
    rng = np.random.default_rng(5)
    on = verts[rng.integers(0, len(verts), 3000)] + rng.normal(scale=0.004, size=(3000, 3))
    far = rng.normal(size=(1000, 3))
    far *= rng.uniform(3.0, 6.0, (1000, 1)) / np.linalg.norm(far, axis=1, keepdims=True)
    lifted = on[:1000] + [0.0, 0.0, thickness]  # about the thickness's grown surface
    x0 = np.vstack([on, lifted, far]) @ m[:3, :3].T + m[:3, 3]
    x1 = x0 + rng.normal(scale=0.05, size=x0.shape)
    n = len(x0)
    near, hits, back = answers = _questions(path, x0, x1)
    assert len(path._near_rows(x0)) <= n - n // 6  # the far ones skipped ...
    assert len(near.index) > 3 and len(hits.index) > 100 and len(back.index) > 100  # ... not all
    monkeypatch.setattr(type(path), "_world_box", lambda self: None)
    _assert_same(answers, _questions(path, x0, x1))


@pytest.mark.parametrize("name", ["unit", "turned and stretched", "turned"])
@pytest.mark.parametrize("deforming", [False, True])
def test_a_moving_mesh_finds_near_points_as_if_every_point_were_tested(name, deforming,
                                                                        monkeypatch):
    """A moving (or deforming) mesh asked which points are near it at one time tests only the
    points within the world box of its local bounds at that time: the same answers."""
    verts, tris = _wavy()
    m = SOLIDS[name]
    m1, samples = _moving(m)
    verts1 = verts * [1.0, 1.0, 1.3] if deforming else verts
    frame = ColliderFrame("Wavy", "MESH", m, m1, 0.5, 0.3, thickness=0.02, vertices0=verts,
                          vertices1=verts1, triangles=tris, matrices=samples)
    path = ColliderPaths().of([frame], DT)[0]
    rng = np.random.default_rng(6)
    on = verts[rng.integers(0, len(verts), 3000)] + rng.normal(scale=0.004, size=(3000, 3))
    far = rng.normal(size=(1000, 3))
    far *= rng.uniform(3.0, 6.0, (1000, 1)) / np.linalg.norm(far, axis=1, keepdims=True)
    local = np.vstack([on, on[:1000] + [0.0, 0.0, 0.02], far])
    answers = []
    for s in (0.0, 0.4, 1.0):
        at = path._at(s)
        x = (local * [1.0, 1.0, 1.0 + 0.3 * s * deforming]) @ at[:3, :3].T + at[:3, 3]
        assert len(path._near_rows(x, s=s)) <= len(x) - len(far) // 2  # far ones skipped ...
        answers.append((x, s, path.near_surface(x, s)))
        assert len(answers[-1][2].index) > 20  # ... not the near ones
    monkeypatch.setattr(type(path), "_near_rows", lambda self, *points, s=None: None)
    for x, s, near in answers:
        _assert_same((near,), (path.near_surface(x, s),))


def test_a_moving_mesh_tests_every_point():
    verts, tris = _wavy(5)
    moved = np.eye(4)
    moved[2, 3] = 0.1
    frame = ColliderFrame("Wavy", "MESH", np.eye(4), moved, vertices0=verts, vertices1=verts,
                          triangles=tris)
    path = ColliderPaths().of([frame], DT)[0]
    assert path._near_rows(np.array([[9.0, 9.0, 9.0]])) is None


@pytest.mark.parametrize("name", ["unit", "turned and stretched", "turned"])
@pytest.mark.parametrize("motion", ["slow", "fast move", "fast turn", "growing"])
@pytest.mark.parametrize("deforming", [False, True])
def test_a_moving_mesh_cuts_segments_over_their_time_as_if_every_one_were_tested(
        name, motion, deforming, monkeypatch):
    """Segments over one time span meet a moving (or deforming) mesh only within the world box
    of its bounds at the start grown by its motion (:meth:`ColliderPath._swept_box`): every
    hit, at its thickness too, and every point it moved onto, as when every segment is mapped
    into its frame; the far ones skipped."""
    verts, tris = _wavy()
    m0 = SOLIDS[name]
    m1 = _sweeps(m0)[motion]
    verts1 = verts * [1.0, 1.0, 1.3] if deforming else verts
    frame = ColliderFrame("Wavy", "MESH", m0, m1, 0.5, 0.3, thickness=0.02, vertices0=verts,
                          vertices1=verts1, triangles=tris)
    path = ColliderPaths().of([frame], DT)[0]
    rng = np.random.default_rng(7)
    on = verts[rng.integers(0, len(verts), 2000)] + rng.normal(scale=0.01, size=(2000, 3))
    x0 = np.vstack([on, on[:600] + [0.0, 0.0, 0.2]]) @ m0[:3, :3].T + m0[:3, 3]
    x1 = np.vstack([on + rng.normal(scale=0.03, size=on.shape),
                    on[:600] - [0.0, 0.0, 0.2]]) @ m0[:3, :3].T + m0[:3, 3]  # (crossing)
    swept = np.linspace(0.0, 1.0, 400)[:, None] * (m1[:3, 3] - m0[:3, 3]) + m0[:3, 3] + \
        rng.uniform(-1.0, 1.0, (400, 3)) @ m0[:3, :3].T  # lying still where it goes
    far = _far_from(rng, m0, m1)
    x0, x1 = np.vstack([x0, swept, far]), np.vstack([x1, swept, far + 0.05])
    n = len(x0)
    kept = _counted_sweeps(monkeypatch, path, n)
    times = (np.broadcast_to(0.0, (n,)), np.broadcast_to(1.0, (n,)))
    got = path.first_hits(x0, x1, *times)
    assert kept[-1] <= n - len(far) and len(got.index) > 100
    monkeypatch.setattr(type(path), "sweep_rows", lambda self, *args: None)
    _assert_same((got,), (path.first_hits(x0, x1, *times),))


def test_a_sheared_mesh_keeps_its_thickness_whatever_else_is_asked():
    """Under a shear (a turned child of a parent scaled unevenly) a world metre spans more
    local units than any row of the inverse says: a point 4.35 cm from a mesh of 5 cm
    thickness is within it, asked alone or beside a far segment (the far segment used to widen
    the search for every row, so the answer depended on what else was asked)."""
    to_local = np.array([[1.0, 0.0, 0.0], [0.9, 0.436, 0.0], [0.0, 0.0, 1.0]])
    m = np.eye(4)
    m[:3, :3] = np.linalg.inv(to_local)
    u, stretch, _ = np.linalg.svd(to_local)
    n = u[:, 0]  # the local direction a world metre stretches most
    t1 = np.cross(n, [0.0, 0.0, 1.0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    verts = 2.0 * np.array([-t1 - t2, t1 - t2, t1 + t2, -t1 + t2])
    frame = ColliderFrame("Sheared", "MESH", m, m, thickness=0.05, vertices0=verts,
                          vertices1=verts, triangles=np.array([[0, 1, 2], [0, 2, 3]]))
    path = ColliderPaths().of([frame], DT)[0]
    resting = (m @ np.append(0.06 * n, 1.0))[:3]  # 0.06 local units off the surface ...
    assert 0.06 / stretch[0] < 0.05  # ... which is within the thickness in the world
    far = np.array([path._world_box()[1][0] + 0.5, 0.0, -10.0])
    for start, end in ((resting[None], resting[None]),
                       (np.array([resting, far]), np.array([resting, far + [0.0, 0.0, 20.0]]))):
        hits = path.first_hits(start, end, np.zeros(len(start)), np.ones(len(start)))
        assert hits.index.tolist() == [0] and hits.t.tolist() == [1.0]


def _crowd():
    """Still spheres, boxes and meshes side by side (scaled and turned), a moving sphere, box and
    mesh, a ground and a plane: the colliders of one scene."""
    verts, tris = _wavy(12)
    frames = []
    for i in range(9):
        m = np.eye(4)
        m[:3, 3] = (1.2 * (i % 3) - 1.2, 1.2 * (i // 3) - 1.2, 0.4)
        m = m @ _turn(i % 3, 0.3 * i) @ np.diag([0.4, 0.3 + 0.05 * i, 0.35, 1.0])
        shape = ("SPHERE", "BOX", "MESH")[i % 3]
        mesh = {"vertices0": verts, "vertices1": verts, "triangles": tris} if shape == "MESH" \
            else {}
        frames.append(ColliderFrame(f"C{i}", shape, m, m, 0.5, 0.3,
                                    thickness=0.02 * (i % 2), **mesh))
    for i in (0, 1, 2):  # a moving sphere, box and mesh (their own cuts at one time only)
        moved = _turn(2, 0.1) @ frames[i].matrix0
        moved[:3, 3] += (0.1, 0.0, 0.05)
        frames.append(ColliderFrame(f"Moving{i}", frames[i].shape, frames[i].matrix0, moved,
                                    0.5, 0.3, **({"vertices0": verts, "vertices1": verts,
                                                  "triangles": tris} if i == 2 else {})))
    frames.append(ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), 0.5, 0.3))
    frames.append(ColliderFrame("Plane", "PLANE", _turn(0, 0.2), _turn(0, 0.2), 0.5, 0.3))
    return ColliderPaths().of(frames, DT)


def test_colliders_cut_together_as_each_cuts_alone(monkeypatch):
    """The rows the colliders' world cuts keep, worked out for all of them together, are each
    collider's own (a moving one's at the one time points are asked at); and the collision
    passes answer to the bit as when each collider cuts its own rows: rain through a crowd of
    still spheres, boxes and meshes, moving ones, a ground and a plane (bounces, resting
    contacts), segments and points alike."""
    from physanim.core.contact import path as path_
    from physanim.core.contact import response

    colliders = _crowd()
    rng = np.random.default_rng(3)
    x0 = rng.uniform((-2.0, -2.0, -0.1), (2.0, 2.0, 1.2), (20000, 3))
    x1 = x0 + rng.normal(scale=0.08, size=x0.shape) + (0.0, 0.0, -0.05)
    span = tuple(np.broadcast_to(t, (len(x0),)) for t in (0.25, 0.5))
    for points, distance, s, times in (((x0, x1), 0.0, None, None),
                                       ((x0, x1), 0.0, None, span),
                                       ((x0,), CONTACT_DISTANCE, 0.25, None)):
        cuts = path_.cut_rows(colliders, distance, *points, s=s, times=times)
        far = path_.farthest(*points)
        sweep = None if times is None else (0.25, 0.5, path_.reach(*points))
        for col, rows in zip(colliders, cuts):
            own = col.world_cut(distance, far, s, sweep)
            if own is None:  # a plane, the ground; moving ones over the interval, a moving
                # mesh over a time span
                assert rows is None and (col.frame.shape in ("HALF_SPACE", "PLANE") or
                                         s is None and col.frame.name.startswith("Moving") and
                                         (times is None or col.frame.shape == "MESH"))
                continue
            alone = path_.rows_meeting(*own, *points)
            assert alone is not None and 0 < len(alone) < len(x0) // 3
            assert np.array_equal(rows, alone)
    v0 = (x1 - x0) / 0.02

    def ask():
        return (response.respond(colliders, x0, x1, v0, v0.copy(), 0.25, 0.5, 0.02, 0.1),
                response.resting_contacts(colliders, x0, v0, 0.25, 0.1))

    moved, resting = ask()
    assert moved.count > 500 and len(resting.index) > 50
    monkeypatch.setattr(response, "cut_rows", lambda *a, **k: None)  # each collider cuts alone
    alone_moved, alone_resting = ask()
    assert moved.count == alone_moved.count
    assert np.array_equal(moved.x, alone_moved.x) and np.array_equal(moved.v, alone_moved.v)
    for key, value in vars(alone_resting).items():
        if isinstance(value, np.ndarray):
            assert np.array_equal(getattr(resting, key), value), key
