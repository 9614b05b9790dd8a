"""On-disk bake cache: frames round-trip, commit swaps atomically, abort leaves the previous bake
byte-identical, and an unusable folder is named in the error."""
from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import pytest

from physanim.core.cache import (
    META_NAME, CacheWriter, frame_file, read_frame, read_meta, remove_cache,
)


def _arrays(seed: int, n: int = 5) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {"id": np.arange(n, dtype=np.int32),
            "position": rng.normal(size=(n, 3)).astype(np.float32),
            "color": rng.random((n, 4)).astype(np.float32)}


def _snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative path -> bytes)."""
    return {str(p.relative_to(folder)): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _bake(cache_dir: Path, frames, seed: int, streams=("Fountain",)) -> Path:
    writer = CacheWriter(cache_dir)
    for stream in streams:
        for f in frames:
            writer.write_frame(stream, f, _arrays(seed + f))
    return writer.commit({"frame_start": min(frames), "frame_end": max(frames), "seed": seed})


def test_frames_round_trip(tmp_path):
    cache = tmp_path / "bake"
    writer = CacheWriter(cache)
    written = {f: _arrays(f) for f in (1, 2, 3)}
    paths = [writer.write_frame("Sparks", f, arrays) for f, arrays in written.items()]
    writer.flush()  # frames are written by a background thread; flush waits for them
    assert all(path.is_file() for path in paths)
    assert not cache.exists()  # nothing visible before commit
    writer.commit({"inputs_hash": "abc"})
    for f, arrays in written.items():
        got = read_frame(cache / "Sparks", f)
        assert set(got) == set(arrays)
        for key in arrays:
            np.testing.assert_array_equal(got[key], arrays[key])
            assert got[key].dtype == arrays[key].dtype
    assert frame_file(cache / "Sparks", 2).name == "frame_000002.npz"
    meta = read_meta(cache)
    assert meta["inputs_hash"] == "abc" and meta["streams"] == ["Sparks"]
    assert "format_version" in meta


def test_frames_are_the_files_np_savez_writes(tmp_path):
    """The cache writes each array from its own memory, not through numpy's copies; the zip
    members are byte for byte those of ``np.savez`` (so ``np.load`` and any reader of npz
    files read them alike), for every kind of array, contiguous or not."""
    import zipfile

    rng = np.random.default_rng(4)
    arrays = {"id": np.arange(7, dtype=np.int32), "position": rng.random((7, 3), np.float32),
              "flag": rng.random(7) > 0.5, "wide": rng.random((2, 3, 4)),
              "empty": np.zeros((0, 3)), "fortran": np.asfortranarray(rng.random((5, 3))),
              "scalar": np.array(2.5), "big_endian": np.arange(10, dtype=">i4"),
              "bytes": np.arange(5, dtype=np.uint8), "strided": rng.random((6, 4))[:, 1],
              "pairs": np.zeros(3, dtype=[("a", "<f4"), ("b", "<i2")])}
    from physanim.core.cache import _save

    writer = CacheWriter(tmp_path / "bake", background=False)
    ours = writer.write_frame("points", 1, arrays)  # (made contiguous first, as np.savez...)
    theirs = tmp_path / "savez.npz"
    np.savez(theirs, **{k: np.ascontiguousarray(v) for k, v in arrays.items()})
    direct, as_given = tmp_path / "direct.npz", tmp_path / "as_given.npz"
    _save(direct, arrays)  # ... and as they are: 0-d, Fortran order, strided
    np.savez(as_given, **arrays)
    for mine, numpys in ((ours, theirs), (direct, as_given)):
        with zipfile.ZipFile(mine) as got, zipfile.ZipFile(numpys) as expected:
            assert got.namelist() == expected.namelist() == [f"{k}.npy" for k in arrays]
            for name in expected.namelist():
                assert got.read(name) == expected.read(name), name  # (read checks the CRC)
    with pytest.raises(ValueError):  # no pickles in a cache
        _save(tmp_path / "objects.npz", {"names": np.array(["a", None], dtype=object)})
    writer.abort()


def test_read_frame_missing_returns_none(tmp_path):
    cache = _bake(tmp_path / "bake", [1, 2], seed=0)
    assert read_frame(cache / "Fountain", 3) is None
    assert read_frame(cache / "NoSuchStream", 1) is None
    assert read_meta(tmp_path / "nowhere") is None


def test_previous_bake_intact_until_commit(tmp_path):
    cache = tmp_path / "bake"
    _bake(cache, [1, 2, 3, 4], seed=0)
    before = _snapshot(cache)
    writer = CacheWriter(cache)
    writer.write_frame("Fountain", 1, _arrays(100))
    writer.write_frame("Fountain", 2, _arrays(101))
    assert _snapshot(cache) == before  # the new frames are not visible yet
    np.testing.assert_array_equal(read_frame(cache / "Fountain", 1)["position"],
                                  _arrays(1)["position"])
    writer.commit({"seed": 100})
    # the new bake replaced the old one completely: frames 3, 4 of the old bake are gone
    np.testing.assert_array_equal(read_frame(cache / "Fountain", 1)["position"],
                                  _arrays(100)["position"])
    assert read_frame(cache / "Fountain", 3) is None
    assert read_meta(cache)["seed"] == 100
    # no leftovers next to the bake (partial or old folders)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bake"]


def test_abort_leaves_previous_bake_byte_identical(tmp_path):
    cache = tmp_path / "bake"
    _bake(cache, [1, 2, 3], seed=0, streams=("A", "B"))
    before = _snapshot(cache)
    assert META_NAME in before
    writer = CacheWriter(cache)
    writer.write_frame("A", 1, _arrays(50))
    writer.write_frame("C", 7, _arrays(51))
    writer.abort()
    assert _snapshot(cache) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bake"]
    writer.abort()  # idempotent
    with pytest.raises(RuntimeError):
        writer.write_frame("A", 2, _arrays(52))
    with pytest.raises(RuntimeError):
        writer.commit({})


def test_commit_twice_raises(tmp_path):
    writer = CacheWriter(tmp_path / "bake")
    writer.write_frame("A", 1, _arrays(0))
    writer.commit({})
    with pytest.raises(RuntimeError):
        writer.commit({})
    writer.abort()  # after commit: a no-op that must not delete the bake
    assert read_frame(tmp_path / "bake" / "A", 1) is not None


def test_missing_parent_is_created(tmp_path):
    cache = tmp_path / "deep" / "er" / "bake"
    _bake(cache, [1], seed=0)
    assert read_meta(cache) is not None


def test_remove_cache(tmp_path):
    cache = _bake(tmp_path / "bake", [1], seed=0)
    assert remove_cache(cache) is True
    assert not cache.exists()
    assert remove_cache(cache) is False
    stray = tmp_path / "not_a_bake"
    stray.mkdir()
    (stray / "keep.txt").write_text("x")
    assert remove_cache(stray) is False and (stray / "keep.txt").exists()


def test_parent_that_is_a_file_names_the_folder(tmp_path):
    blocker = tmp_path / "blocker"
    blocker.write_text("a regular file where the cache folder's parent should be")
    with pytest.raises(OSError) as info:
        CacheWriter(blocker / "bake")
    assert str(blocker) in str(info.value)
    assert blocker.read_text().startswith("a regular file")


def test_read_only_parent_names_the_folder(tmp_path):
    parent = tmp_path / "locked"
    parent.mkdir()
    parent.chmod(stat.S_IRUSR | stat.S_IXUSR)  # 0o500
    try:
        probe = parent / "probe"
        try:
            probe.mkdir()
            writable = True  # root ignores the mode bits
            probe.rmdir()
        except PermissionError:
            writable = False
        if writable:
            # The OS lets this user write here, so the writer must simply work; the error path
            # is covered by test_parent_that_is_a_file_names_the_folder.
            _bake(parent / "bake", [1], seed=0)
            assert read_frame(parent / "bake" / "Fountain", 1) is not None
        else:
            with pytest.raises(OSError) as info:
                CacheWriter(parent / "bake")
            assert str(parent) in str(info.value)
            assert list(parent.iterdir()) == []
    finally:
        parent.chmod(stat.S_IRWXU)
    assert os.access(parent, os.W_OK)


def test_write_errors_of_the_background_thread_surface_at_commit(tmp_path):
    import shutil

    writer = CacheWriter(tmp_path / "bake")
    writer.write_frame("Sparks", 1, _arrays(1))
    writer.flush()
    shutil.rmtree(writer.partial_dir / "Sparks")  # the next write cannot create its file
    writer.write_frame("Sparks", 2, _arrays(2))
    with pytest.raises(FileNotFoundError):
        writer.commit({})
    writer.abort()
    assert not (tmp_path / "bake").exists()
    assert not any(p.name.startswith(".bake.partial") for p in tmp_path.iterdir())
