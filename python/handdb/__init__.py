"""handdb: read and search databases of synthetic hand views from Python.

A thin layer over the C++ libraries the ``handdb`` tool is built from, so Python sees exactly
what the tool sees (docs/python.md)::

    import handdb

    db = handdb.Database("db")            # manifest + shards, memory-mapped read-only
    len(db), db.num_rolls                  # canonical views, rolls per view
    v = db[0]                              # View: v.points (zero-copy int16, 1/16 px), v.keypoints
    cols = db.read()                       # every view as numpy columns
    for m in db.search("hand.jpg", top_k=5):
        print(m.rank, m.distance, m.shape_name, m.keypoints_image_px[0])
    problems = handdb.validate("db")       # [] when valid

Errors raise :class:`handdb.Error` with the tool's one-line message (``str(e)``) and its status
code name (``e.code``).
"""

from ._handdb import (  # noqa: F401
    NUM_JOINT_ANGLES,
    NUM_KEYPOINTS,
    POINT_SCALE,
    ArgumentError,
    Database,
    Error,
    Match,
    QueryEdges,
    View,
    __version__,
    query_edges,
    validate,
)

__all__ = [
    "Database",
    "Error",
    "ArgumentError",
    "Match",
    "QueryEdges",
    "View",
    "query_edges",
    "validate",
    "POINT_SCALE",
    "NUM_JOINT_ANGLES",
    "NUM_KEYPOINTS",
    "__version__",
]
