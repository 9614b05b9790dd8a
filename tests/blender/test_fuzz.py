"""A few random scenes of the fuzzer (tools/fuzz.py; `tools/fuzz.sh 200` runs 200): each bakes
or fails with a message naming an object, never lets another exception escape, never writes a
non-finite value, and a failed system keeps its previous bake (and a failed bake the scene's
checkpoint)."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from tools import fuzz  # the repository root is on sys.path first


@pytest.mark.parametrize("seed", range(8))
def test_random_scene_bakes_or_fails_cleanly(physanim_ext, tmp_path, seed, monkeypatch):
    # a checkpoint every frame (not every 10 s of baking): a bake that fails after saving one
    # must put the scene's checkpoint back, however fast the machine
    monkeypatch.setenv("PHYSANIM_CHECKPOINT_SECONDS", "0")
    outcomes = fuzz.run_scene(physanim_ext, seed, tmp_path)
    assert len(outcomes) == 2 and set(outcomes) <= {"finished", "failed", "partial"}
