"""A small reader for the scanline OpenEXR files Blender writes (no bpy, no OpenEXR bindings).

Supports single-part scanline images with NONE, ZIPS or ZIP compression and HALF/FLOAT/UINT
channels: enough for the label and depth channels of our multilayer renders, so the tests and
tools read them with numpy alone.
"""

from __future__ import annotations

import struct
import zlib
from typing import Dict, Tuple

import numpy as np

MAGIC = 20000630
_PIXEL_TYPES = {0: np.dtype("<u4"), 1: np.dtype("<f2"), 2: np.dtype("<f4")}
_LINES_PER_BLOCK = {0: 1, 2: 1, 3: 16}  # NONE, ZIPS, ZIP


class ExrError(Exception):
    pass


def _read_header(data: bytes, path: str) -> Tuple[dict, int]:
    if len(data) < 8:
        raise ExrError(f"{path}: truncated (no header)")
    magic, version = struct.unpack_from("<ii", data, 0)
    if magic != MAGIC:
        raise ExrError(f"{path}: not an OpenEXR file (magic {magic})")
    if version & 0x200 or version & 0x1000:
        raise ExrError(f"{path}: tiled or multi-part EXR is not supported (flags {version:#x})")
    pos = 8
    header: Dict[str, object] = {}
    while True:
        end = data.index(b"\0", pos)
        name = data[pos:end].decode()
        pos = end + 1
        if not name:
            break
        end = data.index(b"\0", pos)
        typ = data[pos:end].decode()
        pos = end + 1
        (size,) = struct.unpack_from("<i", data, pos)
        pos += 4
        value = data[pos:pos + size]
        pos += size
        if typ == "chlist":
            chans = []
            p = 0
            while value[p] != 0:
                e = value.index(b"\0", p)
                cname = value[p:e].decode()
                ptype, _, _, xs, ys = struct.unpack_from("<iBBxxii", value, e + 1)
                chans.append((cname, ptype, xs, ys))
                p = e + 1 + 16
            header[name] = chans
        elif typ == "compression":
            header[name] = value[0]
        elif typ == "box2i":
            header[name] = struct.unpack("<iiii", value)
        else:
            header[name] = (typ, value)
    return header, pos


def _unzip(block: bytes, expected: int) -> bytes:
    raw = np.frombuffer(zlib.decompress(block), dtype=np.uint8)
    if raw.size != expected:
        raise ExrError(f"decompressed block has {raw.size} bytes, expected {expected}")
    # Undo the predictor (running sum of deltas biased by 128), then the byte split.
    t = ((np.cumsum(np.concatenate(([raw[0]], raw[1:].astype(np.int64) - 128)))) & 0xFF).astype(np.uint8)
    half = (t.size + 1) // 2
    out = np.empty_like(t)
    out[0::2] = t[:half]
    out[1::2] = t[half:]
    return out.tobytes()


def read_exr(path: str) -> Dict[str, np.ndarray]:
    """All channels of a scanline EXR as float32/uint32 arrays of shape (height, width)."""
    with open(path, "rb") as f:
        data = f.read()
    header, pos = _read_header(data, path)
    try:
        chans = sorted(header["channels"])
        comp = header["compression"]
        x0, y0, x1, y1 = header["dataWindow"]
    except KeyError as e:
        raise ExrError(f"{path}: header lacks {e}") from None
    if comp not in _LINES_PER_BLOCK:
        raise ExrError(f"{path}: unsupported compression {comp}")
    if any(xs != 1 or ys != 1 for _, _, xs, ys in chans):
        raise ExrError(f"{path}: subsampled channels are not supported")
    width, height = x1 - x0 + 1, y1 - y0 + 1
    lpb = _LINES_PER_BLOCK[comp]
    nblocks = (height + lpb - 1) // lpb
    if len(data) < pos + 8 * nblocks:
        raise ExrError(f"{path}: truncated offset table")
    offsets = struct.unpack_from(f"<{nblocks}Q", data, pos)
    out = {name: np.empty((height, width), dtype=_PIXEL_TYPES[pt]) for name, pt, _, _ in chans}
    for b, off in enumerate(offsets):
        if off + 8 > len(data):
            raise ExrError(f"{path}: block {b} at offset {off} is past the end ({len(data)} bytes)")
        y, size = struct.unpack_from("<ii", data, off)
        if off + 8 + size > len(data):
            raise ExrError(f"{path}: block {b} at offset {off} is truncated")
        row0 = y - y0
        nrows = min(lpb, height - row0)
        expected = sum(_PIXEL_TYPES[pt].itemsize for _, pt, _, _ in chans) * width * nrows
        block = data[off + 8:off + 8 + size]
        if size < expected:
            block = _unzip(block, expected)
        elif size != expected:
            raise ExrError(f"{path}: block {b} has {size} bytes, expected at most {expected}")
        p = 0
        for r in range(nrows):
            for name, pt, _, _ in chans:
                dt = _PIXEL_TYPES[pt]
                n = dt.itemsize * width
                out[name][row0 + r] = np.frombuffer(block, dtype=dt, count=width, offset=p)
                p += n
    return {k: v.astype(np.float32) if v.dtype == np.float16 else v for k, v in out.items()}


def channel_ending(channels: Dict[str, np.ndarray], suffix: str, path: str = "") -> np.ndarray:
    names = [k for k in channels if k.endswith(suffix)]
    if len(names) != 1:
        raise ExrError(f"{path}: expected one channel ending in '{suffix}', found {names}")
    return channels[names[0]]


def read_labels_depth(path: str) -> Tuple[np.ndarray, np.ndarray]:
    """(labels uint8 (H, W), depth float32 (H, W)) of a handdb render."""
    ch = read_exr(path)
    lab = channel_ending(ch, "IndexMA.X", path)
    depth = channel_ending(ch, "Depth.Z", path)
    li = np.rint(lab)
    if np.abs(li - lab).max() > 0 or li.min() < 0 or li.max() > 255:
        raise ExrError(f"{path}: label channel is not integer-valued")
    return li.astype(np.uint8), depth
