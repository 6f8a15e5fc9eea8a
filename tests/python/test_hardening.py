"""The Python module against hostile inputs. A shard truncated while a Database has it mapped
ended the interpreter with SIGBUS (exit -7, no word); now one line naming the shard on stderr and
exit status 1, as from the CLI. Bad arguments raise the exceptions docs/python.md promises, each
with one message saying what is wrong: ValueError for a bad value, TypeError for a wrong type,
IndexError for an index out of range (never pybind11's "Unable to cast Python instance", nor
option-check lines printed on stderr); a picture the library refuses as an invalid argument is a
handdb.ArgumentError, both a handdb.Error and a ValueError.
"""

import os
import shutil
import subprocess
import sys
import textwrap

import numpy as np
import pytest


READ_AFTER_TRUNCATE = textwrap.dedent(
    """
    import os, sys
    import handdb
    db = handdb.Database(sys.argv[1])
    shard = os.path.join(sys.argv[1], "shard-00001.hdb")
    os.truncate(shard, 4096)
    total = 0
    for v in db:
        total += int(v.points.sum())
    print("read everything", total)
    """
)


def test_shard_truncated_while_mapped_is_one_line_and_exit_1(handdb, db_dir, tmp_path):
    copy = tmp_path / "db"
    shutil.copytree(db_dir, copy)
    r = subprocess.run(
        [sys.executable, "-c", READ_AFTER_TRUNCATE, str(copy)],
        capture_output=True,
        text=True,
        env=dict(os.environ),
        timeout=120,
    )
    assert r.returncode == 1, (r.returncode, r.stderr)
    assert r.stderr == f"handdb: {copy / 'shard-00001.hdb'}: changed or truncated while being read\n"
    assert "read everything" not in r.stdout


def test_dt_cell_is_checked_in_one_value_error(db, capfd):
    query = np.asarray(db[0].points, dtype=np.float32)
    with pytest.raises(ValueError, match=r"dt_cell_px 0\.3.*: must be 1, 0\.5, 0\.25"):
        db.search(query, dt_cell_px=0.3)
    assert capfd.readouterr().err == ""


def test_an_index_too_large_for_the_platform_is_out_of_range(db):
    with pytest.raises(IndexError, match=r"view 9223372036854775808 out of range"):
        db[2**63]
    with pytest.raises(IndexError, match=r"out of range"):
        db[-(2**70)]


def test_a_float_index_is_a_type_error(db):
    with pytest.raises(TypeError, match=r"integers or slices, not float"):
        db[1.5]
    assert db[np.int64(0)].points.shape == db[0].points.shape  # __index__ still works


def test_a_path_with_a_nul_character_is_a_value_error(handdb, db, db_dir, view_image):
    with pytest.raises(ValueError, match=r"query: a path may not contain a NUL character"):
        db.search(str(view_image) + "\0x")
    with pytest.raises(ValueError, match=r"mask: a path may not contain a NUL character"):
        db.search(str(view_image), mask="m\0.png")
    with pytest.raises(ValueError, match=r"path: a path may not contain a NUL character"):
        handdb.Database(db_dir + "\0")
    with pytest.raises(ValueError, match=r"path: a path may not contain a NUL character"):
        handdb.validate(db_dir + "\0")
    with pytest.raises(ValueError, match=r"image: a path may not contain a NUL character"):
        handdb.query_edges(str(view_image) + "\0")
    # Paths still come as str, bytes or os.PathLike.
    assert len(handdb.Database(os.fsencode(db_dir))) == len(db)


def test_a_thin_picture_is_a_value_error_naming_it(handdb, db, tmp_path):
    import cv2

    strip = tmp_path / "strip-2000x1.png"
    cv2.imwrite(str(strip), np.full((1, 2000, 3), (120, 150, 210), np.uint8))
    message = f"{strip}: a 2000x1 picture is too thin to hold a hand (16 px each way at least)"
    for call in (lambda: db.search(str(strip)), lambda: handdb.query_edges(strip)):
        with pytest.raises(ValueError) as e:
            call()
        assert str(e.value) == message
        assert isinstance(e.value, handdb.Error) and e.value.code == "kInvalidArgument"
