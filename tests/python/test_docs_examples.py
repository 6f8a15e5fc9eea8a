"""The Python examples of README.md and docs/python.md run as written, in a directory
holding the test database as `db` and an edge image of its view 5 at roll 3 as `hand.png`.

Each file's ```python blocks run in order in one namespace, so a later block may use what an
earlier one defined; a failing block is reported with its file and first line. The README's C++
example is compiled and run by install/consumer_test (tests/install/consumer_test.sh).
"""

import os
import re
import shutil

import pytest

from handdb_testing import REPO, import_handdb

DOCS = ["README.md", "docs/python.md"]


def python_blocks(path):
    text = open(os.path.join(REPO, path)).read()
    for m in re.finditer(r"^```python\n(.*?)^```", text, re.S | re.M):
        yield text[:m.start()].count("\n") + 2, m.group(1)


@pytest.mark.parametrize("doc", DOCS)
def test_examples_run(doc, db_dir, view_image, tmp_path, monkeypatch, capsys):
    import_handdb()
    blocks = list(python_blocks(doc))
    assert blocks, f"{doc}: no ```python examples"
    os.symlink(db_dir, tmp_path / "db")
    shutil.copy(view_image, tmp_path / "hand.png")
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "handdb_docs"}
    for line, code in blocks:
        try:
            exec(compile(code, f"{doc}:{line}", "exec"), namespace)
        except Exception as e:
            raise AssertionError(f"{doc}:{line}: the example fails: {type(e).__name__}: {e}") from e
    out = capsys.readouterr().out
    assert "Traceback" not in out

