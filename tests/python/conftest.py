"""Fixtures of the Python module tests (issue 13): the build tree, the `handdb` binary and a
small Blender-free database written by tests/install/write_test_database.

The module is imported from $PYTHONPATH (scripts/test.sh sets it to build/python). Without it the
module tests are skipped, unless HANDDB_REQUIRE_PYTHON_MODULE=1 (scripts/test.sh), where a
missing module fails them.
"""

import json
import os
import subprocess

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BUILD = os.environ.get("HANDDB_BINARY_DIR") or os.path.join(REPO, "build")
HANDDB = os.path.join(BUILD, "cli", "handdb")
WRITER = os.path.join(BUILD, "tests", "install", "write_test_database")


def import_handdb():
    try:
        import handdb
    except ImportError as e:
        if os.environ.get("HANDDB_REQUIRE_PYTHON_MODULE") == "1":
            raise
        pytest.skip(f"the handdb Python module is not importable ({e}); set PYTHONPATH=build/python")
    return handdb


def run_handdb(*args, check=True):
    r = subprocess.run([HANDDB, *map(str, args)], capture_output=True, text=True)
    if check and r.returncode != 0:
        raise AssertionError(f"handdb {' '.join(map(str, args))}: exit {r.returncode}: {r.stderr}")
    return r


def handdb_json(*args):
    return json.loads(run_handdb(*args).stdout)


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
