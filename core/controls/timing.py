"""Timing (Lasseter): a time scale, simulated time per frame, for slow motion and speed ramps.

The simulation keeps its own clock: it always steps whole *simulation frames* (one frame
length of simulated time each, with the scene's sub-steps), exactly as at scale 1, so paths in
space do not depend on the time scale. Only which instants the scene's frames show changes:
frame f shows simulated time ``tau(f)`` (in frame lengths), where

    tau(start) = start,  tau(f + 1) = tau(f) + (s(f) + s(f + 1)) / 2

(the trapezoid rule over the scale s sampled at each frame: exact for a linear ramp), linear
between frames. A frame whose instant falls inside a simulation frame is drawn from the state
between two sub-steps (each system interpolates its own, see ``WorldSystem.blend``). At scale 1
every frame is a simulation frame's end: nothing is interpolated and a bake is bit-identical to
one without a time map. Animated inputs (colliders, emitters, pins) are read at the scene frame
that shows the simulated instant, so what is simulated is what the frames show.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MIN_SCALE = 0.01  # 100 x slow motion
MAX_SCALE = 100.0


@dataclass(frozen=True)
class TimeMap:
    """Scene frames <-> simulated time (in frame lengths) over frames ``frame_start`` ..
    ``frame_start + len(scale) - 1``; outside them the first and last scales continue.

    Attributes:
        frame_start: the first frame (its simulated time is ``frame_start``).
        scale: (m,) the time scale at each frame, in [MIN_SCALE, MAX_SCALE].
    """

    frame_start: int
    scale: np.ndarray

    def __post_init__(self):
        scale = np.asarray(self.scale, dtype=np.float64).reshape(-1)
        if len(scale) == 0:
            raise ValueError("a time map needs the scale of at least one frame")
        bad = ~(np.isfinite(scale) & (scale >= MIN_SCALE) & (scale <= MAX_SCALE))
        if bad.any():
            k = int(np.argmax(bad))
            raise ValueError(f"time scale must be within {MIN_SCALE:g} .. {MAX_SCALE:g} "
                             f"(got {scale[k]!r} at frame {self.frame_start + k})")
        scale.setflags(write=False)
        object.__setattr__(self, "scale", scale)
        tau = np.empty(len(scale))
        tau[0] = self.frame_start
        tau[1:] = self.frame_start + np.cumsum(0.5 * (scale[1:] + scale[:-1]))
        tau.setflags(write=False)
        object.__setattr__(self, "_tau", tau)

    @classmethod
    def constant(cls, frame_start: int, frame_end: int, scale: float = 1.0) -> TimeMap:
        return cls(frame_start, np.full(max(1, frame_end - frame_start + 1), float(scale)))

    @property
    def frame_end(self) -> int:
        return self.frame_start + len(self.scale) - 1

    @property
    def identity(self) -> bool:
        """Scale 1 throughout: every frame is a simulation frame."""
        return bool((self.scale == 1.0).all())

    def tau(self, frame):
        """Simulated time [frame lengths] a (float) frame shows; arrays map elementwise."""
        f = np.asarray(frame, dtype=np.float64)
        rel = f - self.frame_start
        last = len(self._tau) - 1
        i = np.clip(np.floor(rel), 0, max(last - 1, 0)).astype(np.int64)
        if last == 0:
            out = self._tau[0] + rel * self.scale[0]
        else:
            slope = self._tau[i + 1] - self._tau[i]
            out = self._tau[i] + (rel - i) * slope
            out = np.where(rel < 0, self._tau[0] + rel * self.scale[0], out)
            out = np.where(rel > last, self._tau[last] + (rel - last) * self.scale[-1], out)
        exact = (rel == np.round(rel)) & (rel >= 0) & (rel <= last)
        out = np.where(exact, self._tau[np.clip(np.round(rel), 0, last).astype(np.int64)], out)
        return float(out) if out.ndim == 0 else out

    def frame(self, tau: float) -> float:
        """The (float) scene frame showing simulated time ``tau`` (the inverse of :meth:`tau`);
        an int when it is a whole frame."""
        t = self._tau
        if tau <= t[0]:
            f = self.frame_start + (tau - t[0]) / self.scale[0]
        elif tau >= t[-1]:
            f = self.frame_end + (tau - t[-1]) / self.scale[-1]
        else:
            i = int(np.searchsorted(t, tau, side="right")) - 1
            f = self.frame_start + i + (tau - t[i]) / (t[i + 1] - t[i])
        return int(round(f)) if abs(f - round(f)) < 1e-9 else f

    def seconds(self, frames, frame_length: float) -> np.ndarray:
        """Simulated time [s] of (float) frames, the clock starting at frame 0 as the core's
        does; ``frame_length`` [s] is the scene's frame length."""
        return np.asarray(self.tau(frames)) * frame_length

    def frames_in(self, tau0: float, after: int, last: int) -> list[tuple[int, float]]:
        """The frames ``after`` < f <= ``last`` shown by the simulation frame (tau0, tau0 + 1],
        with the fraction of it each shows (in (0, 1]; exactly 1.0 at its end)."""
        out = []
        f = after + 1
        while f <= last:
            w = self.tau(f) - tau0
            if w > 1.0 + 1e-12:
                break
            if w > 1e-12:
                out.append((f, 1.0 if abs(w - 1.0) <= 1e-12 else w))
            f += 1
        return out

    def simulation_frames(self) -> int:
        """Simulation frames from the first frame to the last (the last one may run past it)."""
        return max(0, math.ceil(self._tau[-1] - self.frame_start - 1e-9))


def window_active(first: int, last: int, f0: float, f1: float) -> bool:
    """Whether an emission window (births of frames ``first`` .. ``last``, a frame's births
    spanning (f - 1, f]) gives births in the simulation frame showing frames (f0, f1]: when the
    window holds the frame's end, or lies wholly inside it (a burst in slow motion: it still
    gives one frame's births, once). At scale 1 (f1 = f0 + 1) this is first <= f1 <= last."""
    if first - 1 < f1 <= last:
        return True
    return f0 <= first - 1 and last < f1 and first <= last
