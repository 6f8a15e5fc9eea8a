#!/usr/bin/env python3
"""Writes the small TFLite models of query/input/tflite_test.cc and the fuzz seeds
(tests/fuzz/corpus/tflite): one operator each (or a short chain), weights from a fixed formula so
the C++ test recomputes the expected output independently of the interpreter.

    /usr/bin/python3 tests/data/tflite/make_models.py   # rewrites tests/data/tflite/*.tflite

A minimal flatbuffer writer (no flatbuffers package in Debian's Python here): tables are laid
out front to back, each vtable right before its table, every referenced object after its
referrer, so every uoffset points forward as the format requires. Field numbers follow
tensorflow/lite/schema/schema.fbs.
"""
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))

# BuiltinOperator, TensorType, BuiltinOptions union types, ActivationFunctionType, Padding.
ADD, CONV_2D, DEPTHWISE_CONV_2D, DEQUANTIZE, FULLY_CONNECTED, LOGISTIC, MAX_POOL_2D, MEAN = (
    0, 3, 4, 6, 9, 14, 17, 40)
FLOAT32, FLOAT16, INT32 = 0, 1, 2
OPT_CONV, OPT_DW, OPT_FC, OPT_POOL, OPT_ADD, OPT_REDUCER = 1, 2, 8, 5, 11, 27
RELU6 = 3
SAME, VALID = 0, 1


class Table:
    """fields: {index: (fmt, value)} for scalars, {index: ('off', obj)} for references."""

    def __init__(self, fields):
        self.fields = fields


class Vector:
    def __init__(self, fmt, items):  # fmt: struct code for scalars, 'off' for tables
        self.fmt, self.items = fmt, items


class Bytes:
    def __init__(self, data):
        self.data = data


class Writer:
    def __init__(self):
        self.buf = bytearray()
        self.pending = []  # (position of a uoffset, object)

    def align(self, n):
        while len(self.buf) % n:
            self.buf.append(0)

    def put(self, obj):
        """Writes obj and every object it references; returns obj's position."""
        pos = self._write(obj)
        while self.pending:
            at, child = self.pending.pop(0)
            target = self._write(child)
            struct.pack_into("<I", self.buf, at, target - at)
        return pos

    def _write(self, obj):
        if isinstance(obj, Table):
            n = max(obj.fields) + 1 if obj.fields else 0
            # Table body: soffset, then fields each aligned to 4 (simple and valid).
            layout, size = {}, 4
            for i in sorted(obj.fields):
                fmt = obj.fields[i][0]
                width = 4 if fmt == "off" else struct.calcsize("<" + fmt)
                size = (size + width - 1) // width * width
                layout[i] = size
                size += width
            size = (size + 3) // 4 * 4
            self.align(2)
            vt = len(self.buf)
            self.buf += struct.pack("<HH", 4 + 2 * n, size)
            for i in range(n):
                self.buf += struct.pack("<H", layout.get(i, 0))
            self.align(4)
            table = len(self.buf)
            self.buf += bytes(size)
            struct.pack_into("<i", self.buf, table, table - vt)
            for i, (fmt, value) in obj.fields.items():
                if fmt == "off":
                    self.pending.append((table + layout[i], value))
                else:
                    struct.pack_into("<" + fmt, self.buf, table + layout[i], value)
            return table
        if isinstance(obj, Vector):
            self.align(4)
            pos = len(self.buf)
            self.buf += struct.pack("<I", len(obj.items))
            if obj.fmt == "off":
                for item in obj.items:
                    self.pending.append((len(self.buf), item))
                    self.buf += bytes(4)
            else:
                for item in obj.items:
                    self.buf += struct.pack("<" + obj.fmt, item)
            return pos
        if isinstance(obj, Bytes):
            self.align(16)
            self.buf += bytes(12)  # the length sits right before 16-aligned data
            pos = len(self.buf) - 4
            struct.pack_into("<I", self.buf, pos, len(obj.data))
            self.buf += obj.data
            return pos
        raise TypeError(obj)


def weights(n, seed):
    """The fixed formula the C++ test repeats: w_i = ((i * 7 + seed) % 11 - 5) / 8."""
    return [((i * 7 + seed) % 11 - 5) / 8.0 for i in range(n)]


def model(tensors, ops, inputs, outputs):
    """tensors: (shape, type, data bytes or None); ops: (builtin, inputs, outputs, options type,
    options fields)."""
    codes = sorted({op[0] for op in ops})
    buffers = [Table({})]  # buffer 0: the empty sentinel
    tensor_tables = []
    for shape, ttype, data in tensors:
        fields = {0: ("off", Vector("i", shape)), 1: ("b", ttype)}
        if data is not None:
            buffers.append(Table({0: ("off", Bytes(data))}))
            fields[2] = ("I", len(buffers) - 1)
        tensor_tables.append(Table(fields))
    op_tables = []
    for builtin, ins, outs, opt_type, opt_fields in ops:
        fields = {0: ("I", codes.index(builtin)), 1: ("off", Vector("i", ins)),
                  2: ("off", Vector("i", outs))}
        if opt_type:
            fields[3] = ("B", opt_type)
            fields[4] = ("off", Table(opt_fields))
        op_tables.append(Table(fields))
    subgraph = Table({0: ("off", Vector("off", tensor_tables)), 1: ("off", Vector("i", inputs)),
                      2: ("off", Vector("i", outputs)), 3: ("off", Vector("off", op_tables))})
    op_codes = [Table({0: ("b", min(c, 127)), 2: ("i", 1), 3: ("i", c)}) for c in codes]
    root = Table({0: ("I", 3), 1: ("off", Vector("off", op_codes)),
                  2: ("off", Vector("off", [subgraph])), 4: ("off", Vector("off", buffers))})
    w = Writer()
    w.buf += bytes(8)  # root uoffset + file identifier
    w.buf[4:8] = b"TFL3"
    w.pending.append((0, root))
    w.put(Bytes(b""))  # flushes `pending`; the empty bytes object is harmless padding
    return bytes(w.buf)


def f32(values):
    return struct.pack("<%df" % len(values), *values)


def f16(values):
    return struct.pack("<%de" % len(values), *values)


def i32(values):
    return struct.pack("<%di" % len(values), *values)


def main():
    out = {}
    # conv: 1x5x6x3 -> 3x3 stride 2 SAME, 4 filters, bias, RELU6; weights float16 through
    # DEQUANTIZE; then a 1x1 convolution (2 filters, no activation) on its output.
    out["conv"] = model(
        [([1, 5, 6, 3], FLOAT32, None),
         ([4, 3, 3, 3], FLOAT16, f16(weights(108, 1))),
         ([4, 3, 3, 3], FLOAT32, None),
         ([4], FLOAT32, f32(weights(4, 2))),
         ([1, 3, 3, 4], FLOAT32, None),
         ([2, 1, 1, 4], FLOAT32, f32(weights(8, 3))),
         ([2], FLOAT32, f32(weights(2, 4))),
         ([1, 3, 3, 2], FLOAT32, None)],
        [(DEQUANTIZE, [1], [2], 0, {}),
         (CONV_2D, [0, 2, 3], [4], OPT_CONV, {0: ("b", SAME), 1: ("i", 2), 2: ("i", 2),
                                               3: ("b", RELU6)}),
         (CONV_2D, [4, 5, 6], [7], OPT_CONV, {0: ("b", SAME), 1: ("i", 1), 2: ("i", 1)})],
        [0], [7])
    # depthwise: 1x5x5x3 -> 3x3 stride 2 SAME with bias -> 3x3 stride 1 SAME without bias; ADD
    # of the two; LOGISTIC.
    out["depthwise"] = model(
        [([1, 5, 5, 3], FLOAT32, None),
         ([1, 3, 3, 3], FLOAT32, f32(weights(27, 5))),
         ([3], FLOAT32, f32(weights(3, 6))),
         ([1, 3, 3, 3], FLOAT32, None),
         ([1, 3, 3, 3], FLOAT32, f32(weights(27, 7))),
         ([1, 3, 3, 3], FLOAT32, None),
         ([1, 3, 3, 3], FLOAT32, None),
         ([1, 3, 3, 3], FLOAT32, None)],
        [(DEPTHWISE_CONV_2D, [0, 1, 2], [3], OPT_DW, {0: ("b", SAME), 1: ("i", 2), 2: ("i", 2),
                                                       3: ("i", 1)}),
         (DEPTHWISE_CONV_2D, [3, 4, -1], [5], OPT_DW, {0: ("b", SAME), 1: ("i", 1), 2: ("i", 1),
                                                        3: ("i", 1)}),
         (ADD, [3, 5], [6], OPT_ADD, {}),
         (LOGISTIC, [6], [7], 0, {})],
        [0], [7])
    # head: 1x4x4x3 -> MAX_POOL 2x2 stride 2 VALID -> MEAN over H, W -> FULLY_CONNECTED (3 -> 2).
    out["head"] = model(
        [([1, 4, 4, 3], FLOAT32, None),
         ([1, 2, 2, 3], FLOAT32, None),
         ([2], INT32, i32([1, 2])),
         ([1, 3], FLOAT32, None),
         ([2, 3], FLOAT32, f32(weights(6, 8))),
         ([2], FLOAT32, f32(weights(2, 9))),
         ([1, 2], FLOAT32, None)],
        [(MAX_POOL_2D, [0], [1], OPT_POOL, {0: ("b", VALID), 1: ("i", 2), 2: ("i", 2),
                                            3: ("i", 2), 4: ("i", 2)}),
         (MEAN, [1, 2], [3], OPT_REDUCER, {}),
         (FULLY_CONNECTED, [3, 4, 5], [6], OPT_FC, {})],
        [0], [6])
    # Refused at load (found by tests/fuzz/tflite_fuzzer.cc): FULLY_CONNECTED whose weights are
    # int32, and an operator without an output.
    bad = {}
    bad["bad_int32_weights"] = model(
        [([1, 3], FLOAT32, None),
         ([2, 3], INT32, i32([1, 2, 3, 4, 5, 6])),
         ([1, 2], FLOAT32, None)],
        [(FULLY_CONNECTED, [0, 1, -1], [2], OPT_FC, {})],
        [0], [2])
    bad["bad_no_output"] = model(
        [([1, 3], FLOAT32, None), ([1, 3], FLOAT32, None)],
        [(LOGISTIC, [0], [], 0, {})],
        [0], [1])
    for name, data in bad.items():
        with open(os.path.join(HERE, name + ".tflite"), "wb") as f:
            f.write(data)
        print(name, len(data), "bytes")
    corpus = os.path.join(HERE, "..", "..", "fuzz", "corpus", "tflite")
    os.makedirs(corpus, exist_ok=True)
    for name, data in out.items():
        for path in (os.path.join(HERE, name + ".tflite"), os.path.join(corpus, name + ".tflite")):
            with open(path, "wb") as f:
                f.write(data)
        print(name, len(data), "bytes")


if __name__ == "__main__":
    main()
