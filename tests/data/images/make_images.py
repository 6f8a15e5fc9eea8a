#!/usr/bin/env python3
"""Writes the small PNGs of photo/image_read_test.cc and base/image_decode_test.cc: one per PNG
colour type and bit depth that a user could send (grey 1/2/4/8/16 bits, grey + tRNS, grey+alpha,
RGB 8/16, RGB + tRNS, palette 1/2/4/8 bits with and without tRNS, RGBA 8/16, an Adam7-interlaced
one), so the decoder is compared with cv::imread on each of OpenCV's conversions; and four
damaged ones (corrupt_*.png), each with valid chunk CRCs unless the CRC is the damage.

    /usr/bin/python3 tests/data/images/make_images.py   # rewrites tests/data/images/*.png

A minimal PNG writer with zlib (no imaging package in Debian's Python here); pixel values come
from a fixed formula, so the files are the same on every run.
"""
import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
W, H = 23, 17  # odd sizes: partial bytes for low bit depths, every Adam7 pass non-empty


def chunk(kind, data):
    body = kind + data
    return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)


def sample(x, y, c, depth):
    top = (1 << depth) - 1
    return (x * 37 + y * 91 + c * 53 + x * y * 7) % (top + 1)


def pack_row(values, depth):
    if depth == 16:
        return b"".join(struct.pack(">H", v) for v in values)
    if depth == 8:
        return bytes(values)
    out, acc, bits = bytearray(), 0, 0
    for v in values:
        acc = (acc << depth) | v
        bits += depth
        if bits == 8:
            out.append(acc)
            acc, bits = 0, 0
    if bits:
        out.append(acc << (8 - bits))
    return bytes(out)


def pixels(x, y, channels, depth):
    return [sample(x, y, c, depth) for c in range(channels)]


ADAM7 = [(0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2)]


def image_data(channels, depth, interlace, value=pixels):
    raw = bytearray()
    passes = ADAM7 if interlace else [(0, 0, 1, 1)]
    for x0, y0, dx, dy in passes:
        for y in range(y0, H, dy):
            row = []
            for x in range(x0, W, dx):
                row += value(x, y, channels, depth)
            if row:
                raw += b"\0" + pack_row(row, depth)
    return zlib.compress(bytes(raw), 9)


def write(name, color_type, depth, channels, extra=b"", interlace=0, value=pixels, idat=None,
          height=H):
    ihdr = struct.pack(">IIBBBBB", W, height, depth, color_type, 0, 0, interlace)
    data = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + extra
    if idat is None:
        idat = image_data(channels, depth, interlace, value)
    data += chunk(b"IDAT", idat) + chunk(b"IEND", b"")
    with open(os.path.join(HERE, name), "wb") as f:
        f.write(data)


def main():
    for depth in (1, 2, 4, 8, 16):
        write(f"grey{depth}.png", 0, depth, 1)
    write("grey8_trns.png", 0, 8, 1, chunk(b"tRNS", struct.pack(">H", 5)))
    write("grey_alpha8.png", 4, 8, 2)
    write("grey_alpha16.png", 4, 16, 2)
    write("rgb8.png", 2, 8, 3)
    write("rgb16.png", 2, 16, 3)
    write("rgb8_trns.png", 2, 8, 3, chunk(b"tRNS", struct.pack(">HHH", 0, 53, 106)))
    write("rgba8.png", 6, 8, 4)
    write("rgba16.png", 6, 16, 4)
    write("rgb8_interlaced.png", 2, 8, 3, interlace=1)
    for depth in (1, 2, 4, 8):
        n = 1 << depth
        plte = chunk(b"PLTE", bytes((i * 71 + c * 29) % 256 for i in range(n) for c in range(3)))
        write(f"palette{depth}.png", 3, depth, 1, plte)
        trns = chunk(b"tRNS", bytes((i * 97) % 256 for i in range(n)))
        write(f"palette{depth}_trns.png", 3, depth, 1, plte + trns)

    # Damaged files: a filter type of 9 (0-4 exist), a deflate stream with a bad block type, an
    # IHDR that claims more rows than the data holds, a flipped byte under the IDAT CRC.
    raw = bytearray(zlib.decompress(image_data(3, 8, 0)))
    raw[(1 + 3 * W) * 5] = 9
    write("corrupt_filter.png", 2, 8, 3, idat=zlib.compress(bytes(raw), 9))
    stream = bytearray(image_data(3, 8, 0))
    stream[2] |= 0x06  # the first block's BTYPE = 3 (reserved)
    write("corrupt_zlib.png", 2, 8, 3, idat=bytes(stream))
    write("corrupt_ihdr.png", 2, 8, 3, height=4 * H)
    write("corrupt_crc.png", 2, 8, 3)
    path = os.path.join(HERE, "corrupt_crc.png")
    with open(path, "r+b") as f:
        f.seek(os.path.getsize(path) - 12 - 1)  # the last byte of the IDAT CRC (IEND is 12 bytes)
        b = f.read(1)
        f.seek(-1, 1)
        f.write(bytes([b[0] ^ 0x55]))


if __name__ == "__main__":
    main()
