"""Argument checks shared by the frozen settings of every system: each error names its owner
(an object), the value's name and the value."""
from __future__ import annotations

import math

import numpy as np


def is_finite(value) -> bool:
    """``math.isfinite`` that answers False for an integer too large for a float (which
    ``math.isfinite`` refuses with an OverflowError)."""
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def finite(owner: str, **values: float) -> None:
    for key, value in values.items():
        if not is_finite(value):
            shown = f"a {len(str(value))}-digit number" if isinstance(value, int) else value
            raise ValueError(f'{owner}: {key} must be finite (got {shown})')


def non_negative(owner: str, **values: float) -> None:
    for value in values.values():
        if not (0.0 <= value < math.inf):  # (False for NaN): a value fails; name the first
            finite(owner, **values)  # non-finite one, else the first negative one
            key, value = next((k, v) for k, v in values.items() if v < 0.0)
            raise ValueError(f'{owner}: {key} must be >= 0 (got {value})')


def matrix(owner: str, key: str, m) -> np.ndarray:
    m = np.asarray(m, dtype=np.float64)
    if m.shape != (4, 4):
        raise ValueError(f"{owner}: {key} must be a 4x4 matrix (got shape {m.shape})")
    if not np.isfinite(m).all():
        raise ValueError(f"{owner}: {key} has non-finite entries")
    return m


def frozen(a, dtype=np.float64) -> np.ndarray:
    """A read-only copy of ``a``: what a frozen model holds."""
    a = np.array(a, dtype=dtype)
    a.flags.writeable = False
    return a
