"""The handdb Python module against the handdb binary: what Python reads and finds is
what `handdb info --json`, `handdb show`, `handdb query --json` and `handdb validate --json`
report; errors carry the tool's one-line message; several processes read one database at once.
"""

import json
import multiprocessing
import os
import pydoc
import shutil
import subprocess

import numpy as np
import pytest

from handdb_testing import handdb_json, import_handdb, run_handdb

cv2 = pytest.importorskip("cv2")


def test_counts_and_manifest_equal_info_json(db, db_dir):
    info = handdb_json("info", db_dir, "--json")
    assert db.num_shards == info["num_shards"]
    assert db.size_bytes == info["total_bytes"]
    assert db.num_points == info["total_points"]
    assert db.shards_with_coarse_fields == info["shards_with_coarse_fields"]
    assert db.manifest == info["manifest"]
    assert db.metadata == info["manifest"]["metadata"]
    assert len(db) == db.num_views == info["manifest"]["num_views"]
    assert db.num_rolls == info["manifest"]["rolls"]
    assert db.num_virtual_views == info["manifest"]["num_virtual_views"]
    assert sum(len(v) for v in db) == db.num_points


def show_pixels(db_dir, tmp_path, view, roll):
    """The lit pixels of `handdb show --view --roll` (384 px: 1 px per normalised px) and its
    caption (PNG text)."""
    png = tmp_path / f"show-{view}-{roll}.png"
    run_handdb("show", db_dir, "--view", view, "--roll", roll, "-o", png)
    img = cv2.imread(str(png), cv2.IMREAD_GRAYSCALE)
    ys, xs = np.nonzero(img)
    data = png.read_bytes()
    start = data.index(b"tEXtDescription\0") + len(b"tEXtDescription\0")
    length = int.from_bytes(data[start - len(b"tEXtDescription\0") - 4:start - len(b"tEXtDescription\0")], "big")
    caption = data[start:start + length - len(b"Description\0")].decode("latin-1")
    return set(zip(xs.tolist(), ys.tolist())), caption


def drawn(points_px):
    """show's rasterisation: pixel floor(192 + p) inside the 384 x 384 image."""
    px = np.floor(192.0 + points_px.astype(np.float64)).astype(int)
    keep = (px >= 0).all(axis=1) & (px < 384).all(axis=1)
    return set(map(tuple, px[keep].tolist()))


@pytest.mark.parametrize("view,roll", [(0, 0), (5, 3), (-1, 7)])
def test_points_equal_show(db, db_dir, tmp_path, view, roll):
    v = db[view]
    index = v.index
    assert index == (view if view >= 0 else len(db) + view)
    pixels, caption = show_pixels(db_dir, tmp_path, index, roll)
    rolled_px, label = v.rolled(roll)
    assert drawn(rolled_px) == pixels
    if roll == 0:
        assert drawn(v.points / np.float32(16)) == pixels
    assert caption.endswith(f"view {index} roll {roll}/{db.num_rolls}  {v.shape_name}  {len(v)} pts")
    assert v.points.dtype == np.int16 and v.points.shape == (len(v), 2)
    assert np.array_equal(v.points_px, v.points.astype(np.float32) / 16)


def test_points_are_read_only_zero_copy_views(db):
    v = db[3]
    p = v.points
    assert not p.flags.writeable and not p.flags.owndata
    with pytest.raises(ValueError):
        p[0, 0] = 1
    # Two reads of one view share the mapping's bytes.
    assert np.shares_memory(p, db.points(3))
    # A range inside one shard is one zero-copy run; across shards it is copied once.
    first_shard = db.manifest["shards"][0]["views"]
    inside = db.read(0, first_shard)
    assert not inside["points"].flags.owndata and np.shares_memory(inside["points"], db.points(0))
    across = db.read(first_shard - 2, first_shard + 2)
    assert not across["points"].flags.writeable and across["points"].flags.owndata
    # shard_ranges are the manifest's shards.
    ends = np.cumsum([s["views"] for s in db.manifest["shards"]]).tolist()
    assert db.shard_ranges == list(zip([0] + ends[:-1], ends))


def test_read_columns_equal_views(db):
    cols = db.read()
    assert cols["point_offsets"][-1] == db.num_points == len(cols["points"])
    for i in [0, 1, len(db) // 2, len(db) - 1]:
        v = db[i]
        a, b = cols["point_offsets"][i], cols["point_offsets"][i + 1]
        assert np.array_equal(cols["points"][a:b], v.points)
        label = v.label()
        for key, value in label.items():
            assert np.array_equal(cols[key][i], value), key
        assert np.array_equal(v.keypoints, label["keypoints"]) and v.keypoints.shape == (21, 3)
        assert v.joint_angles.shape == (20,) and v.view_direction.shape == (3,)
    part = db.read(-5)
    assert part["start"] == len(db) - 5 and len(part["joint_angles"]) == 5
    assert [v.index for v in db[2:9:3]] == [2, 5, 8]
    with pytest.raises(IndexError):
        db[len(db)]


def test_search_equals_query_json(handdb, db, db_dir, view_image):
    for hand in ["either", "right"]:
        cli = handdb_json("query", db_dir, view_image, "--json", "--top", 10, "--threads", 2, "--hand", hand)
        matches, stats = db.search(view_image, top_k=10, threads=2, hand=hand, return_stats=True)
        assert [m.to_dict() for m in matches] == cli["matches"]
        # (the counters of pruning depend on the threads' timing; the matches do not)
        assert stats["searches"] == cli["stats"]["searches"] == (2 if hand == "either" else 1)
        assert stats["virtual_views"] == cli["stats"]["virtual_views"]
        # The module's counters are named as the CLI's (it adds the threads used), and both say
        # how the bounds pruned.
        assert set(stats) - {"threads"} <= set(cli["stats"])
        assert {"grids", "grid_bounded"} <= set(stats)
    top = matches[0]
    assert (top.view_id, top.roll, top.rank) == (5, 3, 1)
    assert top.keypoints.shape == (21, 3) and top.keypoints_image_px.shape == (21, 2)
    # The match's label is the stored view's, rolled (right-hand matches).
    for m in matches:
        _, label = db[m.view_id].rolled(m.roll)
        for key in ["joint_angles", "view_direction", "keypoints", "camera_roll", "view_theta"]:
            assert np.array_equal(label[key], m.label()[key]), key
    # The edges the search used are query_edges' (label EXRs would use the database's options).
    edges = handdb.query_edges(view_image, database=db)
    q = db.search(edges, top_k=10, threads=2, hand="right")
    assert [m.to_dict() for m in q] == [m.to_dict() for m in matches]


def test_per_shape_ranks_shapes_like_the_cli(db, db_dir, view_image):
    """per_shape=1: one match per basic shape, the shapes ranked by their best view, the same
    matches as `handdb query --per-shape 1`; the first is the unlimited search's first."""
    cli = handdb_json("query", db_dir, view_image, "--json", "--top", 4, "--threads", 2,
                      "--per-shape", 1)
    shapes = db.search(view_image, top_k=4, threads=2, per_shape=1)
    assert [m.to_dict() for m in shapes] == cli["matches"] and cli["options"]["max_per_shape"] == 1
    names = [m.shape_name for m in shapes]
    assert len(set(names)) == len(names) == min(4, len({v.shape_name for v in db}))
    views = db.search(view_image, top_k=20, threads=2)
    assert views[0].to_dict() == shapes[0].to_dict()
    # Each shape's match is its best among the unlimited ranking's (when it is in the top 20).
    for m in shapes:
        best = next((v for v in views if v.shape_name == m.shape_name), None)
        if best is not None:
            assert (best.view_id, best.roll, best.hand, best.distance) == (
                m.view_id, m.roll, m.hand, m.distance)
    with pytest.raises(ValueError, match="per_shape"):
        db.search(view_image, per_shape=-1)


def test_points_query_finds_the_view(db):
    v = db[7]
    for query in [v.points, v.points_px]:
        (m,) = db.search(query, top_k=1, hand="right")
        assert (m.view_id, m.roll, m.distance) == (7, 0, 0.0)
        assert m.keypoints_image_px is None
    rolled, _ = v.rolled(4)
    best = db.search(rolled, top_k=3)
    assert (best[0].view_id, best[0].roll) == (7, 4)
    assert db.search(rolled, top_k=3, brute_force=True)[0].to_dict() == best[0].to_dict()


def test_query_edges(handdb, view_image):
    q = handdb.query_edges(view_image)
    assert q.kind == "edges" and (q.width, q.height) == (384, 384)
    assert q.points.dtype == np.int16 and len(q) == len(q.points) == len(q.points_px)
    assert np.array_equal(q.points_px, q.points / np.float32(16))
    assert q.image_from_normalised(np.zeros((1, 2), np.float32))[0].tolist() == pytest.approx(q.centre_px)
    with pytest.raises(TypeError):
        handdb.query_edges(view_image, no_such_option=1)
    with pytest.raises(ValueError):
        handdb.query_edges(view_image, canny=(5, 1))
    with pytest.raises(handdb.Error) as e:
        handdb.query_edges(view_image + ".missing.png")
    assert e.value.code == "kNotFound"


def error_line(result, command):
    """The one line `handdb <command>` printed, without its 'handdb <command>: ' prefix."""
    assert result.returncode == 1
    (line,) = result.stderr.strip().splitlines()
    prefix = f"handdb {command}: "
    assert line.startswith(prefix)
    return line[len(prefix):]


def test_errors_carry_the_tools_message(handdb, db_dir, tmp_path, view_image):
    missing = tmp_path / "no-db"
    with pytest.raises(handdb.Error) as e:
        handdb.Database(missing)
    assert str(e.value) == error_line(run_handdb("query", missing, view_image, check=False), "query")
    assert e.value.code == "kNotFound" and isinstance(e.value, RuntimeError)


def corrupt_copy(db_dir, tmp_path, offset_in, value=None):
    bad = tmp_path / "bad-db"
    shutil.copytree(db_dir, bad)
    shard = bad / "shard-00001.hdb"
    data = bytearray(shard.read_bytes())
    at = offset_in(data)
    data[at] ^= 0x10
    shard.write_bytes(bytes(data))
    return bad


def test_corrupt_shard_raises(handdb, db_dir, tmp_path, view_image):
    # A flipped header byte fails the open checks: the same line as `handdb query`.
    bad = corrupt_copy(db_dir, tmp_path / "header", lambda d: 40)
    with pytest.raises(handdb.Error) as e:
        handdb.Database(bad)
    assert str(e.value) == error_line(run_handdb("query", bad, view_image, check=False), "query")
    assert "shard-00001.hdb" in str(e.value)
    # A flipped point byte is found by the checksums: verify=True and validate().
    bad = corrupt_copy(db_dir, tmp_path / "points", lambda d: len(d) // 2)
    with pytest.raises(handdb.Error) as e:
        handdb.Database(bad, verify=True)
    assert e.value.code == "kChecksumMismatch" and "shard-00001.hdb" in str(e.value)
    problems = handdb.validate(bad)
    cli = run_handdb("validate", "--json", bad, check=False)
    assert cli.returncode == 1
    assert problems and problems == json.loads(cli.stdout)["paths"][0]["problems"]
    assert handdb.validate(db_dir) == []


def read_everything(db, barrier, out):
    """A data-loader worker: waits for the other, then reads every view of its own mapping."""
    handdb = import_handdb()
    barrier.wait(timeout=60)
    total = 0
    for v in db:
        total += int(v.points.astype(np.int64).sum()) + int(round(float(v.joint_angles.sum()) * 1e6))
    cols = db.read()
    out.put((os.getpid(), total, int(cols["points"].astype(np.int64).sum()), handdb.__file__))


def test_two_processes_read_concurrently(db):
    ctx = multiprocessing.get_context("spawn")  # no inherited mapping: each child opens its own
    barrier, out = ctx.Barrier(2), ctx.Queue()
    procs = [ctx.Process(target=read_everything, args=(db, barrier, out)) for _ in range(2)]
    for p in procs:
        p.start()
    results = [out.get(timeout=120) for _ in procs]
    for p in procs:
        p.join(timeout=60)
        assert p.exitcode == 0
    expected = sum(int(v.points.astype(np.int64).sum()) + int(round(float(v.joint_angles.sum()) * 1e6)) for v in db)
    assert {r[0] for r in results} == {p.pid for p in procs}
    for _, total, points_sum, _ in results:
        assert total == expected
        assert points_sum == int(db.read()["points"].astype(np.int64).sum())


def test_help_explains_itself(handdb):
    text = pydoc.render_doc(handdb.Database, renderer=pydoc.plaintext)
    for word in ["search(", "read(", "top_k", "zero-copy", "handdb.Error", "verify"]:
        assert word in text, word
    assert "GIL" in handdb.Database.search.__doc__
    assert "query_edges" in handdb.__doc__ or "search" in handdb.__doc__
    assert handdb.View.points.__doc__ and handdb.Match.to_dict.__doc__


def test_search_releases_the_gil(db):
    """While one thread searches, another runs Python code; and threads sharing one Database
    get the sequential results."""
    import threading

    query = db[11].rolled(5)[0]
    expected = [m.to_dict() for m in db.search(query, top_k=5, threads=1, brute_force=True)]
    results = []
    searcher = threading.Thread(target=lambda: results.extend(
        [m.to_dict() for m in db.search(query, top_k=5, threads=1, brute_force=True)] for _ in range(3)))
    spins = 0
    searcher.start()
    while searcher.is_alive():
        spins += 1
    searcher.join()
    # With the GIL held for the whole search this loop would barely run (the searching thread
    # only lets go of it between its three calls).
    assert spins > 10000, spins
    assert results == [expected] * 3
    pool = [threading.Thread(target=lambda: results.append(
        [m.to_dict() for m in db.search(query, top_k=5, threads=1)])) for _ in range(2)]
    for t in pool:
        t.start()
    for t in pool:
        t.join()
    assert results[3:] == [expected] * 2


def test_search_many_is_search_per_picture_in_order(handdb, db, db_dir, view_image, tmp_path):
    """search_many: what search() returns for each picture, in order; a bad picture does not stop
    the others, then raises (the first in order), or takes its place with
    return_exceptions=True."""
    other = tmp_path / "view11-roll7.png"
    run_handdb("show", db_dir, "--view", 11, "--roll", 7, "-o", other)
    bad = tmp_path / "bad.jpg"
    bad.write_bytes(b"not a jpeg")
    pictures = [view_image, other, view_image]
    many = db.search_many(pictures, top_k=5, threads=2)
    assert len(many) == 3
    for picture, got in zip(pictures, many):
        want = db.search(picture, top_k=5, threads=2)
        assert [m.to_dict() for m in got] == [m.to_dict() for m in want]
    assert (many[0][0].view_id, many[0][0].roll) == (5, 3)
    assert many[1][0].to_dict() != many[0][0].to_dict()
    assert many[1][0].keypoints_image_px.shape == (21, 2)
    with_stats = db.search_many([other], top_k=2, threads=1, hand="right", return_stats=True)
    (matches, stats), = with_stats
    assert len(matches) == 2 and stats["searches"] == 1 and stats["threads"] == 1

    with pytest.raises(handdb.Error) as e:
        db.search_many([view_image, bad, str(bad) + ".missing", other], top_k=1)
    assert "bad.jpg" in str(e.value) and ".missing" not in str(e.value)
    mixed = db.search_many([view_image, bad, other], top_k=1, return_exceptions=True)
    assert mixed[0][0].to_dict() == many[0][0].to_dict()
    assert mixed[2][0].to_dict() == many[1][0].to_dict()
    assert isinstance(mixed[1], handdb.Error) and "bad.jpg" in str(mixed[1]) and mixed[1].code
    with pytest.raises(handdb.Error) as single:
        db.search(bad, top_k=1)
    assert str(single.value) == str(mixed[1]) and single.value.code == mixed[1].code

    assert db.search_many([]) == []
    with pytest.raises(TypeError):
        db.search_many([db[3].points])
    with pytest.raises(ValueError):
        db.search_many([view_image], top_k=0)
    assert "GIL" in handdb.Database.search_many.__doc__
    # The GIL is released while the pictures run: another thread keeps running Python code.
    import threading
    results = []
    worker = threading.Thread(target=lambda: results.append(
        db.search_many([view_image] * 4, top_k=5, threads=1, brute_force=True)))
    spins = 0
    worker.start()
    while worker.is_alive():
        spins += 1
    worker.join()
    assert spins > 10000, spins
    assert [[m.to_dict() for m in r] for r in results[0]] == [[m.to_dict() for m in many[0]]] * 4


@pytest.mark.parametrize("flags,options", [
    ([], {}),
    (["--contour-clearance", "4", "--canny", "30,100", "--edges-outside"],
     {"contour_clearance": 4, "canny": (30, 100), "edges_outside": True}),
    (["--landmarks", "off"], {"landmarks": "off"}),
    (["--landmark-passes", "1"], {"landmark_passes": 1}),
])
def test_photo_search_equals_query_json(handdb, db, db_dir, flags, options):
    """A real photo (tests/data/photos) through the skin-colour path, with the command's photo
    flags given as keywords: the same matches as `handdb query --json`."""
    from handdb_testing import REPO
    photo = os.path.join(REPO, "tests/data/photos/asl-digits/asl-5", sorted(
        os.listdir(os.path.join(REPO, "tests/data/photos/asl-digits/asl-5")))[0])
    cli = handdb_json("query", db_dir, photo, "--json", "--top", 5, *flags)
    matches = db.search(photo, top_k=5, **options)
    assert [m.to_dict() for m in matches] == cli["matches"]
    assert len(matches) == 5 and cli["input_kind"] == "photo"
    edges = handdb.query_edges(photo, **options)
    assert (len(edges), edges.kind, edges.hand_pixels) == (
        cli["query"]["edge_points"], "photo", cli["query"]["hand_pixels"])
    assert edges.centre_px == tuple(cli["query"]["centre_px"]) and edges.scale == cli["query"]["scale"]


def test_photo_landmarks_rerank_like_the_cli(handdb, db, db_dir):
    """The installed landmark model (the test command installs it): a real photo's QueryEdges
    carry the network's 21 joints, and the search ranks by the documented score; landmarks='off'
    ranks by D_c alone."""
    from handdb_testing import REPO
    photo = os.path.join(REPO, "tests/data/photos/asl-digits/asl-1/IMG_1170.JPG")
    edges = handdb.query_edges(photo)
    assert edges.landmarks is not None and edges.landmarks["presence"] > 0.9
    assert edges.landmarks["image_px"].shape == (21, 2)
    assert edges.landmarks["handedness"] > 0.9  # a right hand, named by the network
    matches = db.search(edges, top_k=5, per_shape=1)
    scores = [m.score for m in matches]
    assert all(s is not None for s in scores) and scores == sorted(scores)
    cli = handdb_json("query", db_dir, photo, "--json", "--top", 5, "--per-shape", 1)
    assert cli["query"]["landmarks"]["used"] is True
    assert [m.to_dict() for m in matches] == cli["matches"]
    assert cli["query"]["landmarks"]["image_px"] == edges.landmarks["image_px"].tolist()
    plain = db.search(handdb.query_edges(photo, landmarks="off"), top_k=5, per_shape=1)
    assert all(m.score is None for m in plain)
    assert [m.distance for m in plain] == sorted(m.distance for m in plain)
    # One pass: the network's joints on the segmentation's crop, 1.5 hand diameters wide, which
    # the second pass replaces by the crop around those joints.
    once = handdb.query_edges(photo, landmark_passes=1)
    cli_once = handdb_json("query", db_dir, photo, "--json", "--landmark-passes", 1)
    assert cli_once["query"]["landmarks"]["passes"] == 1 and cli["query"]["landmarks"]["passes"] == 2
    assert once.landmarks["crop_side_px"] == pytest.approx(cli_once["query"]["landmarks"]["crop"]["side_px"])
    assert once.landmarks["crop_side_px"] != pytest.approx(edges.landmarks["crop_side_px"])
    with pytest.raises(ValueError, match="landmark_passes"):
        handdb.query_edges(photo, landmark_passes=3)


def test_coded_database_reads_and_searches_like_the_plain_one(handdb, db, tmp_path, view_image):
    """The same views written as coded shards (format v1.2): the columns, the views' points and
    the search results are the plain database's."""
    from handdb_testing import WRITER

    coded_dir = tmp_path / "coded"
    subprocess.run([WRITER, str(coded_dir), "--coded", "1"], check=True, capture_output=True)
    coded = handdb.Database(str(coded_dir))
    assert len(coded) == len(db) and coded.num_points == db.num_points
    a, b = db.read(), coded.read()
    assert np.array_equal(a["point_offsets"], b["point_offsets"])
    assert np.array_equal(a["points"], b["points"])
    for i in [0, len(db) // 2, len(db) - 1]:
        assert np.array_equal(db[i].points, coded[i].points)
    for hand in ["either", "right"]:
        want = db.search(view_image, top_k=10, threads=2, hand=hand)
        got = coded.search(view_image, top_k=10, threads=2, hand=hand)
        assert [m.to_dict() for m in got] == [m.to_dict() for m in want]


def test_search_uses_the_index_the_manifest_lists(handdb, tmp_path, view_image):
    """A database with an index searches indexed by default, as `handdb query` does, and
    search="exact" opts out."""
    import pickle

    from handdb_testing import WRITER

    path = tmp_path / "indexed"
    subprocess.run([WRITER, str(path)], check=True, capture_output=True)
    run_handdb("index", path, "--dims", 16, "--nlist", 4, "--cell-px", 16, "--grid-side", 15)
    indexed = handdb.Database(str(path))
    assert indexed.search_mode == "auto"
    matches, stats = indexed.search(view_image, top_k=5, threads=2, return_stats=True)
    assert stats["candidates"] > 0
    cli = handdb_json("query", path, view_image, "--json", "--top", 5, "--threads", 2)
    assert cli["options"]["search"] == "indexed"
    assert [m.to_dict() for m in matches] == cli["matches"]
    exact = handdb.Database(str(path), search="exact")
    _, exact_stats = exact.search(view_image, top_k=5, threads=2, return_stats=True)
    assert exact_stats["candidates"] == 0
    assert pickle.loads(pickle.dumps(exact)).search_mode == "exact"
    with pytest.raises(ValueError):
        handdb.Database(str(path), search="fast")


def test_track_equals_the_track_command(handdb, db, db_dir, view_image, tmp_path):
    """Database.track: the dicts of `handdb track`'s JSON lines, frame by frame; a frame that is
    not a picture is an item with found "none", a path that is neither a video nor a folder an
    error."""
    frames = tmp_path / "frames"
    frames.mkdir()
    other = frames / "f002.png"
    run_handdb("show", db_dir, "--view", 11, "--roll", 7, "-o", other)
    shutil.copy(view_image, frames / "f000.png")
    (frames / "f001.png").write_bytes(b"not a png")
    got = db.track(str(frames), top_k=3, smooth="off", fit="off")
    # After the bad frame the search starts from view 5's answer: a local search near it, or the
    # full one when the local best is far worse.
    assert [f["found"] for f in got] in (["full", "none", "local"], ["full", "none", "full"])
    assert got[1]["code"] == "kBadImage" and "pose" not in got[1]
    assert got[0]["pose"]["view_id"] == 5 and "pose" in got[2]
    out = run_handdb("track", db_dir, frames, "--top", 3, "--smooth", "off", "--quiet", "--fit", "off")
    lines = [json.loads(line) for line in out.stdout.splitlines() if line]
    assert len(lines) == len(got) == 3
    for a, b in zip(got, lines):
        assert a["found"] == b["found"]
        assert [m["view_id"] for m in a["matches"]] == [m["view_id"] for m in b["matches"]]
        assert a.get("pose", {}).get("view_id") == b.get("pose", {}).get("view_id")
    with pytest.raises(handdb.Error) as e:
        db.track(str(tmp_path / "nothing-here"))
    assert e.value.code == "kNotFound"


@pytest.mark.parametrize("tracking", [True, False])
def test_track_landmark_tracking_equals_the_command(handdb, db, db_dir, tmp_path, tracking):
    """Real photos as frames, the landmark network on the last frame's crop or on each frame's
    own: the same frames as `handdb track` with or without --no-landmark-tracking."""
    from handdb_testing import REPO
    folder = os.path.join(REPO, "tests/data/photos/asl-digits/asl-5")
    frames = tmp_path / "frames"
    frames.mkdir()
    for i, name in enumerate(sorted(os.listdir(folder))[:3]):
        shutil.copy(os.path.join(folder, name), frames / f"f{i:03d}.jpg")
    got = db.track(str(frames), top_k=3, smooth="off", fit="off", landmark_tracking=tracking)
    flags = [] if tracking else ["--no-landmark-tracking"]
    out = run_handdb("track", db_dir, frames, "--top", 3, "--smooth", "off", "--quiet", "--fit", "off",
                     *flags)
    lines = [json.loads(line) for line in out.stdout.splitlines() if line]
    assert len(lines) == len(got) == 3
    for a, b in zip(got, lines):
        assert a["matches"] == b["matches"]
