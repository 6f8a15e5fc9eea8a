"""Helpers of the Python module tests: the build tree, the `handdb` binary and the
module import. A module of its own name, not conftest: blender_scripts/tests has a conftest too,
and `from conftest import ...` would get whichever pytest loaded first.

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
