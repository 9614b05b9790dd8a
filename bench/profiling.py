"""A cProfile of one physanim bake as markdown tables, its functions grouped by the layer of this
checkout they live in (core, add-on)."""
from __future__ import annotations

import cProfile
import os
import pstats
from functools import cache
from pathlib import Path

from bench import common

ROOT = common.ROOT


@cache
def _real(file: str) -> str:
    return os.path.realpath(file) if file.endswith(".py") else ""


def _layer(file: str) -> str | None:
    """'core' or 'addon' when ``file`` is a source file of this checkout (the extension runs it
    through a symlinked repo folder), else None."""
    for layer in ("core", "addon"):
        if _real(file).startswith(str(ROOT / layer) + os.sep):
            return layer
    return None


def _short(key) -> str:
    file, line, func = key
    if file == "~":
        return func  # a builtin, e.g. <method 'reduce' of 'numpy.ufunc' objects>
    if _layer(file):
        return f"{os.path.relpath(_real(file), ROOT)}:{line} {func}"
    return f"{'/'.join(Path(file).parts[-2:])}:{line} {func}"


def format_profile(prof: cProfile.Profile, top: int) -> str:
    """Three tables of ``top`` rows each: core and add-on functions by cumulative time, all
    functions by own time; times also as shares of the whole bake."""
    stats = pstats.Stats(prof)
    total = max(stats.total_tt, 1e-12)
    entries = stats.stats  # key -> (primitive calls, calls, tottime, cumtime, callers)

    out = [f"cProfile of one physanim bake: {total:.2f} s profiled (profiling overhead "
           "included; shares, not absolute times, are what matter)", ""]
    core = [k for k in entries if _layer(k[0]) == "core"]
    addon = [k for k in entries if _layer(k[0]) == "addon"]
    for title, keys, sort in (("core functions by cumulative time", core, 3),
                              ("add-on functions by cumulative time", addon, 3),
                              ("all functions by own time (tottime)", list(entries), 2)):
        rows = []
        for k in sorted(keys, key=lambda k: entries[k][sort], reverse=True)[:top]:
            _, nc, tt, ct, _ = entries[k]
            rows.append((f"`{_short(k)}`", f"{nc:,}", f"{ct:.2f}", f"{100 * ct / total:.1f}",
                         f"{tt:.2f}", f"{100 * tt / total:.1f}"))
        out += [f"**{title}**", "", *common.markdown_table(
            ("function", "calls", "cumulative (s)", "% of bake", "own (s)", "own %"), "lrrrrr",
            rows), ""]
    return "\n".join(out)
