"""PC2 point caches: byte layout, streamed writing (valid after every append), round trip and
malformed files."""
from __future__ import annotations

import struct

import numpy as np
import pytest

from physanim.core.pc2 import HEADER, MAGIC, SAMPLE_COUNT_OFFSET, Pc2Writer, read_pc2


def _samples(count: int, points: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(scale=3.0, size=(count, points, 3))


def test_header_layout_is_blenders():
    """Blender's reader (MOD_meshcache_pc2.c): char[12] "POINTCACHE2\\0", int32 version 1, int32
    points, float32 start, float32 sampling, int32 samples — 32 bytes, little-endian."""
    assert HEADER.size == 32 and HEADER.format == "<12siiffi"
    assert MAGIC == b"POINTCACHE2\0" and len(MAGIC) == 12
    assert SAMPLE_COUNT_OFFSET == struct.calcsize("<12siiff")


def test_round_trip(tmp_path):
    path = tmp_path / "cloth.pc2"
    data = _samples(5, 7)
    writer = Pc2Writer(path, 7, start_frame=12.0, sample_rate=0.5)
    for sample in data:
        writer.append(sample)
    writer.close()
    writer.close()  # closing twice is harmless
    raw = path.read_bytes()
    assert len(raw) == 32 + 5 * 7 * 3 * 4
    assert HEADER.unpack(raw[:32]) == (MAGIC, 1, 7, 12.0, 0.5, 5)
    samples, start, rate = read_pc2(path)
    assert samples.dtype == np.float32 and samples.shape == (5, 7, 3)
    assert (start, rate) == (12.0, 0.5)
    np.testing.assert_array_equal(samples, data.astype(np.float32))  # float32 is what's stored
    np.testing.assert_allclose(samples, data, rtol=2 ** -23)


def test_file_is_valid_after_every_append(tmp_path):
    """A bake stopped at any frame leaves a PC2 of the frames written so far (the header's sample
    count is patched after each append, and the data reaches the file before the next call)."""
    path = tmp_path / "partial.pc2"
    data = _samples(4, 3, seed=1)
    writer = Pc2Writer(path, 3, start_frame=1.0)
    try:
        for k, sample in enumerate(data, start=1):
            writer.append(sample)
            samples, _, _ = read_pc2(path)  # read while the writer is still open
            assert samples.shape == (k, 3, 3) and writer.samples == k
            np.testing.assert_array_equal(samples, data[:k].astype(np.float32))
    finally:
        writer.close()


def test_empty_cache_is_valid_before_the_first_append(tmp_path):
    """'a partial file is always a valid PC2 of the samples written so far' — zero samples too
    (a bake that fails on its first frame): the header must reach the file on construction."""
    path = tmp_path / "empty.pc2"
    writer = Pc2Writer(path, 3, start_frame=1.0)
    try:
        samples, start, _ = read_pc2(path)
        assert samples.shape == (0, 3, 3) and start == 1.0
    finally:
        writer.close()


def test_append_accepts_any_float_array_of_the_right_shape(tmp_path):
    path = tmp_path / "list.pc2"
    writer = Pc2Writer(path, 2)
    writer.append([[1, 2, 3], [4, 5, 6]])  # ints, a list
    writer.append(np.arange(6, dtype=np.float64).reshape(2, 3)[::1])
    writer.append(np.asfortranarray(np.ones((2, 3))))  # non-C-contiguous input
    writer.close()
    samples, start, rate = read_pc2(path)
    np.testing.assert_array_equal(samples[0], [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(samples[2], np.ones((2, 3)))
    assert (start, rate) == (0.0, 1.0)


@pytest.mark.parametrize("shape", [(3, 3), (2,), (2, 2), (2, 3, 1), (1, 2, 3)])
def test_sample_of_the_wrong_shape_is_refused_and_leaves_the_file_valid(tmp_path, shape):
    path = tmp_path / "bad.pc2"
    writer = Pc2Writer(path, 2)
    writer.append(np.zeros((2, 3)))
    with pytest.raises(ValueError, match=rf"PC2 sample has shape \({shape[0]},.*expected \(2, 3\)"):
        writer.append(np.zeros(shape))
    writer.close()
    samples, _, _ = read_pc2(path)
    assert samples.shape == (1, 2, 3)


def test_wrong_magic_is_refused(tmp_path):
    path = tmp_path / "fake.pc2"
    path.write_bytes(HEADER.pack(b"POINTCACHE3\0", 1, 2, 0.0, 1.0, 1) + bytes(24))
    with pytest.raises(ValueError, match=r'is not a PC2 file \(magic b.POINTCACHE3'):
        read_pc2(path)


def test_truncated_or_inconsistent_files_are_refused(tmp_path):
    short = tmp_path / "short.pc2"
    short.write_bytes(MAGIC + bytes(8))
    with pytest.raises(ValueError, match="too short to be a PC2 file"):
        read_pc2(short)
    lying = tmp_path / "lying.pc2"
    lying.write_bytes(HEADER.pack(MAGIC, 1, 2, 0.0, 1.0, 3) + bytes(2 * 3 * 4 * 2))  # 2 of 3
    with pytest.raises(ValueError, match="holds 12 floats, its header says 18"):
        read_pc2(lying)
