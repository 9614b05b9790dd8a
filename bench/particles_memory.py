"""Part 3 of the particle benchmark (``bench/particles.py``), "memory": the peak memory of a
large bake at the product's defaults, and whether it grows with the frame count.

Each bake runs in a process of its own (``python bench/particles_memory.py --child``), so its
peak resident set (Linux's ``VmHWM``) is its own: the benchmark's scene (``particles_compare``) with
all ``--count`` particles born over the first frames and alive to the end, baked through the
add-on at its defaults (USD points output included) for each frame count. A bake whose memory is
flat in frame count writes each frame out and keeps nothing per frame. Beside it, the processes
that write the USD layers (as many as the cores, up to four): their count and the largest one's
peak resident set, on top of the bake's.
"""
from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

EMIT_FRAMES = 10  # every particle is born within these first frames: the count is flat after


def _peak_mb(pid: int | str = "self") -> float | None:
    """The peak resident set [MB] of a process (this one by default): Linux's VmHWM, which
    starts afresh with each program (``ru_maxrss`` keeps the largest of the parent's at the
    fork, so a bake run from a benchmark that had simulated Blender's particles started at
    830 MB). None for another process that has none (ended); this one's ``ru_maxrss`` where
    there is no /proc."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0  # kB
    except OSError:
        pass
    if pid != "self":
        return None
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


def child(count: int, frames: int) -> dict:
    """One bake in this process: its time, the memory before and at the peak, what is alive."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from bench import blender_side, particles_compare  # blender_side first: it sets up Blender
    import bpy  # noqa: F401  (then Blender's own modules load)

    sc = particles_compare.Scene(count, frames, min(EMIT_FRAMES, frames - 1))
    with (tempfile.TemporaryDirectory(prefix="physanim_memory_", ignore_cleanup_errors=True)
          as folder, blender_side.extension_enabled()):
        scene, emitter = particles_compare.build_physanim_scene(sc, folder)
        # the USD writers' peaks, read as the bake ends each of them
        usd_process = next(m for name, m in sys.modules.items()
                           if name.endswith(".addon.usd_process"))
        writer_peaks: list[float] = []
        close = usd_process.UsdProcess.close

        def measured_close(self, kill: bool = False) -> None:
            peak = _peak_mb(self._proc.pid) if self._proc.poll() is None else None
            if peak is not None:
                writer_peaks.append(peak)
            close(self, kill)

        usd_process.UsdProcess.close = measured_close
        before = _peak_mb()
        start = time.perf_counter()
        particles_compare._bake()
        took = time.perf_counter() - start
        peak = _peak_mb()
        scene.frame_set(frames)
        from sample_scenes._common import result_points

        alive = len(result_points(emitter.physanim.emitter.result)["position"])
        cache = sum(f.stat().st_size for f in Path(folder).rglob("*") if f.is_file())
    return {"frames": frames, "time": took, "before": before, "peak": peak, "alive": alive,
            "cache": cache / 2 ** 20, "writers": len(writer_peaks),
            "writer_peak": max(writer_peaks, default=0.0)}


def measure(count: int, frame_counts: list[int]) -> list[dict]:
    """:func:`child` for each frame count, each in a fresh process."""
    rows = []
    for frames in frame_counts:
        out = subprocess.run([sys.executable, __file__, "--child", str(count), str(frames)],
                             capture_output=True, text=True, check=False,
                             env={**os.environ, "PYTHONUNBUFFERED": "1"})
        lines = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
        if out.returncode != 0 or not lines:
            raise RuntimeError(f"memory bake of {frames} frames failed:\n{out.stderr[-3000:]}")
        rows.append(json.loads(lines[-1]))
        print(f"(memory: {frames} frames, peak {rows[-1]['peak']:,.0f} MB)", flush=True)
    return rows


def table(count: int, rows: list[dict]) -> str:
    """Markdown: each frame count's bake, and the growth of its peak over the shortest's."""
    from bench import common

    first = rows[0]["peak"] - rows[0]["before"]
    cells = [(r["frames"], f"{r['alive']:,}", f"{r['time']:.1f}", f"{r['before']:,.0f}",
              f"{r['peak']:,.0f}", f"{r['peak'] - r['before']:,.0f}",
              f"{(r['peak'] - r['before']) / first:.2f}" if first > 0 else "—",
              f"{r['writers']} x {r['writer_peak']:,.0f}", f"{r['cache']:,.0f}")
             for r in rows]
    return "\n".join([
        f"\n### Peak memory of a {count:,}-particle bake (defaults, USD points output), by "
        "frame count\n",
        *common.markdown_table(("frames", "alive at the end", "bake (s)", "memory before (MB)",
                                "peak (MB)", "bake's peak (MB)", "x shortest",
                                "USD writers x peak (MB)", "cache (MB)"),
                               "rrrrrrrrr", cells)])


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:
        print(json.dumps(child(int(sys.argv[2]), int(sys.argv[3]))), flush=True)
