"""What every benchmark shares, with no Blender: the checkout's core imported by path, timing,
markdown tables, the machine line that heads a run and the report that closes it.

The Blender-side set-up lives in :mod:`bench.blender_side`; this module never imports ``bpy``, so
``bench/broadphase.py`` runs in a plain interpreter.
"""
from __future__ import annotations

import gc
import importlib
import importlib.util
import os
import platform
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PROBLEM = "SANITY CHECK FAILED:"  # the prefix of a failed check in the closing report
ALIGN = {"l": "---", "r": "---:"}  # markdown rule of a left (text) or right (number) column


# --- the physanim core of this checkout, without Blender ----------------------------------------

def core_module(name: str):
    """``physanim.core.<name>`` of this checkout (e.g. ``"particles"``, ``"collision.broadphase"``),
    the checkout registered by path as the package ``physanim`` on first use."""
    if "physanim" not in sys.modules:
        spec = importlib.util.spec_from_file_location(
            "physanim", ROOT / "__init__.py", submodule_search_locations=[str(ROOT)])
        module = importlib.util.module_from_spec(spec)
        sys.modules["physanim"] = module
        spec.loader.exec_module(module)
    return importlib.import_module(f"physanim.core.{name}")


# --- timing ---------------------------------------------------------------------------------------

def timed(fn: Callable[[], Any]) -> tuple[Any, float, float]:
    """``(fn(), wall time [s], CPU time [s])``, garbage collected before the clocks start. The
    CPU time counts every thread (Blender's particle code may use several) and the child
    processes ``fn`` waited for (a bake's USD writer)."""
    gc.collect()
    wall, cpu = time.perf_counter(), _cpu_time()
    out = fn()
    return out, time.perf_counter() - wall, _cpu_time() - cpu


def _cpu_time() -> float:
    """CPU seconds of this process and of its children that have ended."""
    children = os.times()
    return time.process_time() + children.children_user + children.children_system


def best_of(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    """``(shortest wall time of repeat calls [s], the last call's result)``."""
    best, out = np.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return best, out


# --- output ---------------------------------------------------------------------------------------

def markdown_table(columns: Sequence[str], align: str,
                   rows: Iterable[Sequence[object]]) -> list[str]:
    """The lines of a markdown table.

    Args:
        columns: the header cells.
        align: one letter a column: ``l`` (text, left-aligned) or ``r`` (numbers, right-aligned).
        rows: the cells of each row, already formatted (``str()`` prints the rest as is).
    """
    if len(align) != len(columns) or set(align) - set(ALIGN):
        raise ValueError(f"align needs one of {sorted(ALIGN)} per column ({len(columns)} "
                         f"columns) (got {align!r})")
    lines = ["| " + " | ".join(columns) + " |", "|" + "|".join(ALIGN[a] for a in align) + "|"]
    return lines + ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]


def int_list(text: str) -> list[int]:
    """``"1000,10000"`` -> ``[1000, 10000]`` (empty items skipped)."""
    return [int(s) for s in text.split(",") if s]


def load_average() -> str:
    """The 1, 5 and 15 minute load averages, or ``n/a`` where the system has none."""
    try:
        return " ".join(f"{v:.2f}" for v in os.getloadavg())
    except OSError:
        return "n/a"


def blas_threads() -> str:
    """``, OPENBLAS_NUM_THREADS=..`` for the thread knobs set in the environment, else ``""``."""
    knobs = [f"{k}={os.environ[k]}" for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")
             if k in os.environ]
    return f", {', '.join(knobs)}" if knobs else ""


def machine() -> str:
    """What a run's heading says about the machine: numpy, Python, CPUs, load now."""
    return (f"numpy {np.__version__}, Python {platform.python_version()}, {os.cpu_count()} CPUs, "
            f"load average {load_average()}")


def print_final_load() -> None:
    print(f"load average at the end: {load_average()} (other work on the machine skews timings)")


def report(problems: Sequence[str], prefix: str = PROBLEM) -> int:
    """Print each problem after ``prefix``; the exit status: 1 when there is any, else 0."""
    for p in problems:
        print(prefix, p)
    return 1 if problems else 0
