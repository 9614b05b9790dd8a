"""Droplet: a mist condenses into drops. A burst of 2,000 particles fills a 2 m cube at rest (a
little thermal jitter, no gravity); a Lennard-Jones force among them makes them cling, a drag
force carries off the heat of their falling together, and the mist gathers into round drops
(the particles as spheres of their size: touching at the potential's minimum).

Self-check: at the end a particle has 10 or more neighbours within 1.5 sigma on average (close
packing: 12), at most 10 % are left as vapour (no neighbour), neighbours sit close-packed near
the pair potential's minimum (within 15 %: the soft core gives a little under many
neighbours), and the drops have grown: the largest holds 5 % of the particles or more (at the
start: a few particles).
"""
from __future__ import annotations

import bpy
import numpy as np

from sample_scenes import _common

NAME = "droplet"
SIGMA = 0.1  # [m]
EPSILON = 0.03  # [J]: strong enough to condense a mist at rest
FRAMES = 150

# Frames that show the point: the mist (1), drops forming (40), round drops (150)
SHOWCASE = (1, 40, 150)
README_FRAME = 150


def build(scene, particles: int = 2000) -> None:
    import bmesh

    _common.stage(scene, (4.5, -6.0, 3.5), (0.0, 0.0, 0.0), frame_end=FRAMES)
    scene.use_gravity = False
    # the stiffness check asks for 7 sub-steps at this epsilon (the bake says so at fewer)
    scene.physanim.substeps = 7
    box = _common.add_mesh(scene, "Mist", lambda bm: bmesh.ops.create_cube(bm, size=2.0))
    box.display_type = 'WIRE'
    box.hide_render = True
    p = box.physanim.emitter
    p.enabled = True
    p.source = 'VOLUME'
    p.rate, p.frame_start, p.frame_end = float(particles), 1, 1
    p.speed, p.speed_random = 0.0, 0.3  # a little heat
    p.direction = 'RANDOM'
    p.lifetime = 10.0 * FRAMES
    p.size = 0.06
    p.mass = 0.1
    p.seed = 2
    p.color_stops[0].color = (0.12, 0.4, 0.85, 1.0)
    p.color_stops[1].color = (0.05, 0.25, 0.7, 1.0)
    cling = bpy.data.objects.new("Cling", None)
    scene.collection.objects.link(cling)
    f = cling.physanim.force
    f.enabled = True
    f.type = 'LENNARD_JONES'
    f.sigma, f.epsilon, f.cutoff = SIGMA, EPSILON, 2.5 * SIGMA
    air = bpy.data.objects.new("Air", None)
    scene.collection.objects.link(air)
    air.physanim.force.enabled = True
    air.physanim.force.type = 'DRAG'
    air.physanim.force.linear = 0.05


def _positions(scene, frame: int) -> np.ndarray:
    scene.frame_set(frame)
    points = _common.result_points(bpy.data.objects["Mist"].physanim.emitter.result)
    return points["position"].astype(float)


def check(scene) -> list[str]:
    problems = []
    last = _positions(scene, FRAMES)
    if len(last) < 100:
        return [f"only {len(last)} particles at the end"]
    d = np.linalg.norm(last[:, None] - last[None], axis=2) if len(last) <= 4000 else None
    if d is None:
        return []
    np.fill_diagonal(d, np.inf)
    bonds = (d < 1.5 * SIGMA).sum(axis=1)
    minimum = SIGMA * 1.5 ** (1.0 / 6.0)  # the default core softness 0.5
    if bonds.mean() < 10.0:
        problems.append(f"{bonds.mean():.1f} neighbours per particle at the end, not 10 or more "
                        "(not condensed)")
    vapour = (bonds == 0).mean()
    if vapour > 0.1:
        problems.append(f"{100 * vapour:.0f} % of the particles are still vapour")
    nearest = np.median(d.min(axis=1))
    if abs(nearest - minimum) > 0.15 * minimum:
        problems.append(f"neighbours sit {nearest:.4f} m apart, not near the minimum "
                        f"{minimum:.4f} m")
    grown = _largest_drop(d < 1.5 * SIGMA) / len(last)
    if grown < 0.05:
        problems.append(f"the largest drop holds {100 * grown:.1f} % of the particles, not 5 % "
                        "or more")
    return problems


def _largest_drop(bonded: np.ndarray) -> int:
    """The particle count of the largest cluster of bonded particles (labels spread along
    bonds until nothing changes)."""
    label = np.arange(len(bonded))
    i, j = np.nonzero(np.triu(bonded, 1))
    while True:
        low = np.minimum(label[i], label[j])
        new = label.copy()
        np.minimum.at(new, i, low)
        np.minimum.at(new, j, low)
        new = new[new]  # follow the chain of labels
        if np.array_equal(new, label):
            return int(np.bincount(label).max())
        label = new
