"""The Python module against a shard changed under it: a shard truncated while a Database has it
mapped ended the interpreter with SIGBUS (exit -7, no word); now one line naming the shard on
stderr and exit status 1, as from the CLI.
"""

import os
import shutil
import subprocess
import sys
import textwrap


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
