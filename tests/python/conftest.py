"""Fixtures of the Python module tests: the module, a small Blender-free database
written by tests/install/write_test_database and an edge image of one of its views. Helpers are
in handdb_testing.py.
"""

import os
import subprocess

import pytest

from handdb_testing import WRITER, import_handdb, run_handdb


@pytest.fixture(scope="session")
def handdb():
    return import_handdb()


@pytest.fixture(scope="session")
def db_dir(tmp_path_factory):
    """4 shapes x 12 directions = 48 views x 12 rolls in 2 shards (or $HANDDB_PYTEST_DB)."""
    if os.environ.get("HANDDB_PYTEST_DB"):
        return os.environ["HANDDB_PYTEST_DB"]
    path = tmp_path_factory.mktemp("handdb-py") / "db"
    subprocess.run([WRITER, str(path)], check=True, capture_output=True)
    return str(path)


@pytest.fixture(scope="session")
def db(handdb, db_dir):
    return handdb.Database(db_dir)


@pytest.fixture(scope="session")
def view_image(db_dir, tmp_path_factory):
    """An edge image of view 5 at roll 3, drawn by `handdb show`."""
    path = tmp_path_factory.mktemp("handdb-py-img") / "view5-roll3.png"
    run_handdb("show", db_dir, "--view", 5, "--roll", 3, "-o", path)
    return str(path)
