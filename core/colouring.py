"""Graph colouring of constraints for batched Gauss-Seidel: constraints grouped so that no
moving item (a body, a vertex) is in two constraints of one group, which makes each group one
vectorised pass whose updates never collide."""
from __future__ import annotations

import numpy as np


def colour(members: np.ndarray, dynamic: np.ndarray) -> list[np.ndarray]:
    """Constraint indices grouped so that no dynamic item appears in two constraints of a group.

    Args:
        members: (c, k) the items each constraint acts on (an item may repeat within a row).
        dynamic: (n,) bool, whether each item moves (a static one may be shared freely).

    Each group is a maximal set (greedy): it keeps taking constraints whose dynamic items are
    still free in it, so there are at most k (D - 1) + 1 groups for D constraints on the
    busiest item.
    """
    members = np.asarray(members, np.int64)
    members = members.reshape(len(members), -1) if members.ndim != 2 else members
    left = np.arange(len(members))
    groups = []
    while len(left):
        used = np.zeros(len(dynamic), bool)
        group, candidates = [], left
        while len(candidates):
            chosen = _first_of_their_items(members[candidates], dynamic)
            picked = candidates[chosen]
            group.append(picked)
            used[members[picked].ravel()] = True
            candidates = candidates[~chosen]
            rows = members[candidates]
            candidates = candidates[~np.any(used[rows] & dynamic[rows], axis=1)]
        group = np.sort(np.concatenate(group))
        groups.append(group)
        left = np.setdiff1d(left, group, assume_unique=True)
    return groups


def _first_of_their_items(members: np.ndarray, dynamic: np.ndarray) -> np.ndarray:
    """Which constraints come first (lowest position) among those of each of their dynamic
    items (the first constraint always does)."""
    count, k = members.shape
    pos = np.arange(count)
    ends, at = members.ravel(), np.repeat(pos, k)
    dyn = dynamic[ends]
    first = np.full(len(dynamic), count)
    np.minimum.at(first, ends[dyn], at[dyn])
    return np.all(~dynamic[members] | (first[members] == pos[:, None]), axis=1)
