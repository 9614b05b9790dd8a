"""PC2 point caches (Blender's Mesh Cache modifier reads them): streamed, one sample per frame.

Layout (little-endian): a 32-byte header ``<12siiffi`` = b"POINTCACHE2\\0", version 1, point
count, start frame, sample rate, sample count; then samples x points x 3 float32.
"""
from __future__ import annotations

import os
import struct

import numpy as np

HEADER = struct.Struct("<12siiffi")
MAGIC = b"POINTCACHE2\0"
SAMPLE_COUNT_OFFSET = 28  # byte offset of the sample count in the header


class Pc2Writer:
    """Appends one (points, 3) sample per call; the header's sample count stays correct after
    every append, so a partial file is always a valid PC2 of the samples written so far.

    Args:
        path: file to create. point_count: points per sample. start_frame, sample_rate: header
        fields (Blender's FRAME time mode ignores them; kept for other readers).
    """

    def __init__(self, path: str | os.PathLike, point_count: int, start_frame: float = 0.0,
                 sample_rate: float = 1.0):
        self.path = os.fspath(path)
        self.point_count = int(point_count)
        self.samples = 0
        self._file = open(self.path, "wb")
        self._file.write(HEADER.pack(MAGIC, 1, self.point_count, float(start_frame),
                                     float(sample_rate), 0))
        self._file.flush()  # a file with no sample yet is already a valid (empty) PC2

    @classmethod
    def resume(cls, path: str | os.PathLike, source: str | os.PathLike,
               samples: int) -> Pc2Writer:
        """A writer on ``path`` that starts as the first ``samples`` samples of the PC2 file
        ``source`` (copied in chunks: memory does not grow with the file), ready to append."""
        with open(source, "rb") as handle:
            header = handle.read(HEADER.size)
            magic, version, points, start, rate, count = HEADER.unpack(header)
            if magic != MAGIC or count < samples:
                raise ValueError(f'"{source}" holds {count} samples, not the {samples} to resume '
                                 "from")
            writer = cls(path, points, start, rate)
            left = samples * points * 12
            while left:
                chunk = handle.read(min(left, 1 << 24))
                if not chunk:
                    raise ValueError(f'"{source}" ends before its sample {samples}')
                writer._file.write(chunk)
                left -= len(chunk)
        writer.samples = samples
        writer._file.seek(SAMPLE_COUNT_OFFSET)
        writer._file.write(struct.pack("<i", samples))
        writer._file.seek(0, os.SEEK_END)
        writer._file.flush()
        return writer

    def append(self, points: np.ndarray) -> None:
        data = np.ascontiguousarray(points, dtype="<f4")
        if data.shape != (self.point_count, 3):
            raise ValueError(f"PC2 sample has shape {data.shape}, expected ({self.point_count}, 3)")
        self._file.write(data.tobytes())
        self.samples += 1
        end = self._file.tell()
        self._file.seek(SAMPLE_COUNT_OFFSET)
        self._file.write(struct.pack("<i", self.samples))
        self._file.seek(end)
        self._file.flush()

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()


def read_pc2(path: str | os.PathLike) -> tuple[np.ndarray, float, float]:
    """(samples, points, 3) float32 array, start frame and sample rate of a PC2 file."""
    with open(path, "rb") as handle:
        header = handle.read(HEADER.size)
        if len(header) != HEADER.size:
            raise ValueError(f'"{path}" is too short to be a PC2 file')
        magic, version, points, start, rate, samples = HEADER.unpack(header)
        if magic != MAGIC:
            raise ValueError(f'"{path}" is not a PC2 file (magic {magic!r})')
        data = np.frombuffer(handle.read(), dtype="<f4")
    expected = samples * points * 3
    if data.size != expected:
        raise ValueError(f'"{path}" holds {data.size} floats, its header says {expected}')
    return data.reshape(samples, points, 3), start, rate
