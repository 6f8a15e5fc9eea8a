"""Bad arguments to the Python module raise the exceptions docs/python.md promises, each with one
message saying what is wrong: ValueError for a bad value, TypeError for a wrong type, IndexError
for an index out of range (never pybind11's "Unable to cast Python instance", nor option-check
lines printed on stderr).
"""

import numpy as np
import pytest


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


def test_a_path_with_a_nul_character_is_a_value_error(db, view_image):
    with pytest.raises(ValueError, match=r"query: a path may not contain a NUL character"):
        db.search(str(view_image) + "\0x")
    with pytest.raises(ValueError, match=r"mask: a path may not contain a NUL character"):
        db.search(str(view_image), mask="m\0.png")
