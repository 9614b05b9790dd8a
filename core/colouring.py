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

    First fit in index order: each constraint takes the lowest group none of its dynamic items
    is in yet. So group 0 is the maximal set a greedy pass in index order takes, group 1 the
    same of what is left, and so on (at most k (D - 1) + 1 groups for D constraints on the
    busiest item); each group's indices ascend. One pass, each item's groups a bit mask: a
    Python loop over the rows, faster than repeated vectorised passes (one per group and round)
    from a few constraints to hundreds of thousands.
    """
    members = np.asarray(members, np.int64)
    members = members.reshape(len(members), -1) if members.ndim != 2 else members
    if not len(members):
        return []
    rows = np.where(np.asarray(dynamic, bool)[members], members, -1).tolist()  # -1: static
    used = [0] * len(dynamic)  # per item: bit g set when it is in group g
    group = []
    if members.shape[1] == 2:  # (pairs: the common case, unrolled)
        for a, b in rows:
            taken = (used[a] if a >= 0 else 0) | (used[b] if b >= 0 else 0)
            bit = ~taken & (taken + 1)  # the lowest group free for both
            if a >= 0:
                used[a] |= bit
            if b >= 0:
                used[b] |= bit
            group.append(bit.bit_length() - 1)
    else:
        for row in rows:
            taken = 0
            for i in row:
                if i >= 0:
                    taken |= used[i]
            bit = ~taken & (taken + 1)
            for i in row:
                if i >= 0:
                    used[i] |= bit
            group.append(bit.bit_length() - 1)
    group = np.array(group, np.int64)
    order = np.argsort(group, kind="stable")  # by group, ascending indices within each
    return np.split(order, np.cumsum(np.bincount(group))[:-1])
