import shutil
import subprocess

import numpy as np
import pytest

from handdb_blender import exr

OIIOTOOL = shutil.which("oiiotool")


def make(tmp_path, name, compression, dtype):
    """A 2-channel multilayer-named EXR with known values, written by OpenImageIO's oiiotool."""
    if OIIOTOOL is None:
        pytest.skip("oiiotool not installed")
    path = str(tmp_path / name)
    # 37 x 21: more than one 16-line ZIP block and a partial last block.
    subprocess.run([OIIOTOOL, "--pattern", "fill:topleft=0,0:topright=36,3.5:bottomleft=0,0:bottomright=36,3.5",
                    "37x21", "2", "--chnames", "ViewLayer.Depth.Z,ViewLayer.IndexMA.X", "-d", dtype,
                    "--compression", compression, "-o", path], check=True)
    return path


@pytest.mark.parametrize("compression", ["none", "zips", "zip"])
@pytest.mark.parametrize("dtype", ["float", "half"])
def test_reads_what_oiiotool_wrote(tmp_path, compression, dtype):
    path = make(tmp_path, f"t_{compression}_{dtype}.exr", compression, dtype)
    ch = exr.read_exr(path)
    assert sorted(ch) == ["ViewLayer.Depth.Z", "ViewLayer.IndexMA.X"]
    z = exr.channel_ending(ch, "Depth.Z")
    assert z.shape == (21, 37) and z.dtype == np.float32
    # fill: a ramp along x (IndexMA 0..3.5, not integer-valued).
    assert z[0, 0] == pytest.approx(0.0, abs=1e-3) and z[20, 36] == pytest.approx(36.0, rel=1e-3)
    assert np.all(np.diff(z[5]) > 0)


def test_label_channel_must_be_integer(tmp_path):
    path = make(tmp_path, "nonint.exr", "zip", "float")
    with pytest.raises(exr.ExrError, match="not integer-valued"):
        exr.read_labels_depth(path)


def test_rejects_non_exr_and_truncated(tmp_path):
    p = tmp_path / "bad.exr"
    p.write_bytes(b"hello world, not an exr")
    with pytest.raises(exr.ExrError, match="not an OpenEXR file"):
        exr.read_exr(str(p))
    good = make(tmp_path, "t.exr", "zip", "float")
    data = open(good, "rb").read()
    p.write_bytes(data[: len(data) - 40])
    with pytest.raises(exr.ExrError, match="truncated|past the end"):
        exr.read_exr(str(p))


def test_missing_channel(tmp_path):
    ch = exr.read_exr(make(tmp_path, "t.exr", "zip", "float"))
    with pytest.raises(exr.ExrError, match="Foo.X"):
        exr.channel_ending(ch, "Foo.X", "t.exr")
