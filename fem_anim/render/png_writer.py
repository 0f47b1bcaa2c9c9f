"""PNG files of rendered frames, written with zlib directly.

A rendered frame is large areas of one colour; zlib compresses its rows well without PNG's
per-row prediction filters, which Pillow chooses adaptively for every row and which cost
most of its time. :func:`write_png` writes an 8-bit RGB PNG (PNG specification, ISO/IEC
15948: signature, ``IHDR``, one ``IDAT`` of filter-type-0 rows, ``IEND``), any reader's
format, faster than Pillow. zlib's fastest level (1) is used: on rendered frames it takes
less time than its default level (6) for somewhat larger files (measured in
docs/pictures.md).
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

__all__ = ["encode_png", "write_png", "ZLIB_LEVEL"]

#: zlib's compression level (1: its fastest; the pixels are the same at every level).
ZLIB_LEVEL = 1
_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(
        ">I", zlib.crc32(kind + data))


def encode_png(image: np.ndarray) -> bytes:
    """The PNG file of an image.

    Args:
        image: (height, width, 3) uint8 RGB.

    Returns:
        The file's bytes.

    Raises:
        ValueError: if the image is not (h, w, 3) uint8.
    """
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise ValueError(f"an RGB image (h, w, 3) uint8 is needed, got {image.shape} "
                         f"{image.dtype}")
    height, width = image.shape[:2]
    rows = np.hstack([np.zeros((height, 1), np.uint8), image.reshape(height, 3 * width)])
    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)  # 8 bits, RGB
    return (_SIGNATURE + _chunk(b"IHDR", header)
            + _chunk(b"IDAT", zlib.compress(rows.tobytes(), ZLIB_LEVEL)) + _chunk(b"IEND", b""))


def write_png(path: Path, image: np.ndarray) -> None:
    """Write an image as a PNG file (see :func:`encode_png`).

    Args:
        path: The file to write.
        image: (height, width, 3) uint8 RGB.
    """
    Path(path).write_bytes(encode_png(image))
