"""The include rule of docs/architecture.md, checked over the source tree.

Each stage folder has a rank; a file may include another folder's header only if that folder's
rank is lower (its own folder is always allowed). Folders of the same rank never include each
other, and cluster/ includes only base/. The TFLite runtime (nn/) is included only by the
landmark model that runs it, its test and its fuzz target, so no other stage grows a dependency
on a network runtime. A failure names the file, the line and the include.

Needs neither a build nor the handdb module: it reads the sources.
"""

import os
import re

import pytest

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))

# Mirrors the table "Folders, in dependency order" of docs/architecture.md.
RANK = {
    "base": 0,
    "nn": 1,
    "format": 1,
    "cluster": 1,
    "edges": 2,
    "generator": 3,
    "query": 3,
    "photo": 3,
    "pose": 4,
    "track": 5,
    "evaluate": 6,
    "cli": 7,
    "python": 7,
}

# Folders a folder may include beyond the rank rule's own folder, where the rule is narrower.
ONLY = {"cluster": {"base"}}

# Files outside nn/ that may include "nn/...": the landmark model, its test, its fuzz target.
NN_USERS = re.compile(r"^(nn/|photo/hand_landmarks(_test)?\.(h|cc)$|tests/fuzz/tflite_fuzzer\.cc$|bench/)")

SOURCE = re.compile(r"\.(h|hh|hpp|cc|cpp|cxx|inc)$")
INCLUDE = re.compile(r'^\s*#\s*include\s*"([^"]+)"')
SKIP_DIRS = {".git", "build", "third_party", "node_modules"}


def source_files(top):
    """Repository-relative paths of the C++ sources under top (a folder of the repository)."""
    for root, dirs, files in os.walk(os.path.join(REPO, top)):
        dirs[:] = sorted(d for d in dirs if d not in SKIP_DIRS and not d.startswith("build"))
        for name in sorted(files):
            if SOURCE.search(name):
                yield os.path.relpath(os.path.join(root, name), REPO)


def includes(path, repo=REPO):
    """(line number, included path) of each quoted include of a file."""
    with open(os.path.join(repo, path), encoding="utf-8", errors="replace") as f:
        for number, line in enumerate(f, 1):
            m = INCLUDE.match(line)
            if m:
                yield number, m.group(1)


def stage_violations(path, repo=REPO):
    folder = path.split("/", 1)[0]
    problems = []
    for number, target in includes(path, repo):
        if "/" not in target:
            continue  # generated headers (handdb_version.h) and same-folder includes
        other = target.split("/", 1)[0]
        if other == folder:
            continue
        where = f"{path}:{number}: #include \"{target}\""
        if other not in RANK:
            if os.path.isdir(os.path.join(repo, other)):
                problems.append(f"{where}: {other}/ is not a stage folder; stages include only stages")
            continue
        if folder in ONLY and other not in ONLY[folder]:
            allowed = ", ".join(f"{f}/" for f in sorted(ONLY[folder]))
            problems.append(f"{where}: {folder}/ includes only {allowed}")
        elif RANK[other] >= RANK[folder]:
            problems.append(f"{where}: {other}/ (rank {RANK[other]}) is not before {folder}/ (rank {RANK[folder]})")
    return problems


def test_every_stage_folder_exists():
    missing = [f for f in RANK if not os.path.isdir(os.path.join(REPO, f))]
    assert not missing, f"stage folders in the rank table but not in the tree: {missing}"


@pytest.mark.parametrize("folder", sorted(RANK))
def test_includes_follow_the_stage_order(folder):
    problems = [p for path in source_files(folder) for p in stage_violations(path)]
    assert not problems, "includes against the stage order:\n" + "\n".join(problems)


def test_only_the_landmark_model_includes_the_network_runtime():
    problems = []
    for top in sorted(os.listdir(REPO)):
        if top in SKIP_DIRS or top.startswith("build") or not os.path.isdir(os.path.join(REPO, top)):
            continue
        for path in source_files(top):
            if NN_USERS.match(path):
                continue
            for number, target in includes(path):
                if target.startswith("nn/"):
                    problems.append(f"{path}:{number}: #include \"{target}\"")
    assert not problems, (
        "only photo/hand_landmarks.* (and the TFLite fuzz target) include the network runtime:\n"
        + "\n".join(problems))


def test_the_check_finds_a_violation(tmp_path):
    """The rule can fail: a format/ file including query/, cluster/ including edges/, query/ including photo/."""
    for path, text in {
        "format/x.cc": '#include "query/searcher.h"\n#include "base/status.h"\n',
        "cluster/y.cc": '#include "edges/edges.h"\n',
        "query/z.cc": '#include "photo/image_edges.h"\n',
    }.items():
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text(text)
    assert stage_violations("format/x.cc", str(tmp_path)) == [
        'format/x.cc:1: #include "query/searcher.h": query/ (rank 3) is not before format/ (rank 1)']
    assert stage_violations("cluster/y.cc", str(tmp_path)) == ['cluster/y.cc:1: #include "edges/edges.h": cluster/ includes only base/']
    assert stage_violations("query/z.cc", str(tmp_path)) == [
        'query/z.cc:1: #include "photo/image_edges.h": photo/ (rank 3) is not before query/ (rank 3)']
