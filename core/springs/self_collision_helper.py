"""Self-collision's helper process: a mesh's point-triangle pairs found in a child process
(:mod:`..helper_process`) while the bake finds its edge-edge pairs (:mod:`.self_collision`).

A mesh with HELPER_EDGES edges or more starts one where the bake may run on two cores or more
(:func:`~..helper_process.room`): a 32 x 32 cloth's detection is about a third shorter. Smaller
meshes' detections are too short to pay for the round trip, and a mesh without faces has no
point pairs. PHYSANIM_SELF_COLLISION_PROCESS=0 never starts one, =1 starts one for any mesh
with faces (where a process can start).
"""
from __future__ import annotations

import os

from ..errors import PhysanimError, SimulationError
from ..helper_process import Helper, can_start, pipes_safe, room

HELPER_EDGES = 1_000
ENVIRONMENT_HELPER = "PHYSANIM_SELF_COLLISION_PROCESS"


def start_helper(itself) -> Helper | None:
    """A helper for the :class:`~.self_collision.SelfCollision` ``itself`` (starting: not yet
    ready), or None where none should or can start (as its ``_helper_mode`` says)."""
    faces, mode = itself.faces, itself._helper_mode
    if mode == "off" or not len(faces.triangles) or (mode == "auto" and (
            len(faces.edges) < HELPER_EDGES or not room())) or not can_start() \
            or not pipes_safe():
        return None
    try:
        return Helper("springs.self_collision_helper:point_server", {
            "triangles": faces.triangles, "edges": faces.edges, "loose": faces.loose,
            "mass": itself.mass, "inv_mass": itself.inv_mass, "distance": itself.distance,
            "friction": itself.friction})
    except Exception:  # (it cannot start here: the bake finds every pair itself)
        return None


def helper_mode() -> str:
    """"auto", "off" or "on" from ENVIRONMENT_HELPER (unset: "auto")."""
    raw = os.environ.get(ENVIRONMENT_HELPER, "").strip()
    if raw not in ("", "0", "1"):
        raise PhysanimError(f"{ENVIRONMENT_HELPER} must be 0 (no helper process for "
                            f"self-collision) or 1 (one for any mesh), got {raw!r}")
    return {"": "auto", "0": "off", "1": "on"}[raw]


def point_server(setup: dict):
    """The helper process's handler (:mod:`..helper_process`): a request ``(x0, x1, margin)``
    is answered ``("pairs", SelfCollision._point_pairs(...))`` of a copy of the mesh's
    self-collision that keeps its own candidate pairs and tests between requests, or
    ``("error", message)`` where its search refuses a crowded sub-step. (The point pairs'
    search and tests take about two thirds as long as the edge pairs', which the bake finds
    meanwhile.)"""
    from ..contact.features import FaceSet
    from .self_collision import SelfCollision

    itself = SelfCollision(FaceSet(setup["triangles"], setup["edges"], setup["loose"]),
                           setup["mass"], setup["inv_mass"], setup["distance"],
                           setup["friction"])

    def handle(request):
        x0, x1, itself._margin = request
        try:
            return "pairs", itself._point_pairs(x0, x1, *itself._prepare(x0, x1))
        except SimulationError as exc:
            return "error", exc.detail

    return handle
