// handdb._handdb: the Python module, a thin layer over the libraries' public API
// (query/database.h, query/searcher.h, photo/image_edges.h, format/manifest.h,
// format/validator.h), so Python reads and searches exactly what the `handdb` binary does.
// docs/python.md describes the API; python/handdb/__init__.py re-exports it.
//
// - Points are zero-copy, read-only numpy views of the shard mapping (PointQ is two little-endian
//   int16, which the library already reads in place); the array keeps the Database alive.
// - Every long call (open, read, search, image edges, validate) releases the GIL.
// - A library error (Status) raises handdb.Error carrying the tool's one-line message and its
//   code name; bad arguments raise ValueError / TypeError / IndexError.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <bit>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "base/status.h"
#include "base/thread_pool.h"
#include "edges/view_conversion.h"
#include "format/manifest.h"
#include "format/roll.h"
#include "format/validator.h"
#include "format/view.h"
#include "generator/hand/database_rig.h"
#include "handdb_version.h"
#include "photo/image_edges.h"
#include "pose/landmark_rank.h"
#include "pose/match_json.h"
#include "pose/picture_search.h"
#include "query/database.h"
#include "query/searcher.h"
#include "track/frames.h"
#include "track/track_json.h"
#include "track/tracker.h"

namespace handdb::python {
namespace {

namespace py = pybind11;
namespace fs = std::filesystem;
using json = nlohmann::json;

static_assert(std::endian::native == std::endian::little,
              "points are handed out as views of the little-endian shard bytes");
static_assert(sizeof(PointQ) == 2 * sizeof(int16_t) && offsetof(PointQ, y) == sizeof(int16_t));

// A library error on its way to Python: handdb.Error(message) with .code = "kChecksumMismatch".
struct StatusError : std::exception {
  explicit StatusError(Status s) : status(std::move(s)) {}
  const char* what() const noexcept override { return status.message().c_str(); }
  Status status;
};

template <typename T>
T Unwrap(Result<T> r) {
  if (!r.ok()) throw StatusError(r.status());
  return std::move(r).value();
}

py::object* error_type = nullptr;  // handdb.Error, created in the module init (never freed)
// handdb.ArgumentError: a handdb.Error that is also a ValueError, for the library's
// kInvalidArgument (a picture or value the library cannot take), so both handlers catch it.
py::object* argument_error_type = nullptr;

// Marks a fresh array read-only (it views the mapping, or is shared by every caller).
template <typename A>
A ReadOnly(A a) {
  py::detail::array_proxy(a.ptr())->flags &= ~py::detail::npy_api::NPY_ARRAY_WRITEABLE_;
  return a;
}

// Zero-copy (n, 2) int16 view of points; `owner` keeps the memory alive.
py::array PointsView(std::span<const PointQ> pts, py::handle owner) {
  const auto n = static_cast<py::ssize_t>(pts.size());
  return ReadOnly(py::array_t<int16_t>({n, py::ssize_t{2}},
                                       {py::ssize_t{sizeof(PointQ)}, py::ssize_t{sizeof(int16_t)}},
                                       reinterpret_cast<const int16_t*>(pts.data()),
                                       owner));
}

template <typename T, size_t N>
py::array_t<T> Array1(const std::array<T, N>& a) {
  py::array_t<T> out(static_cast<py::ssize_t>(N));
  std::memcpy(out.mutable_data(), a.data(), sizeof(T) * N);
  return out;
}

py::array_t<float> Keypoints(const ViewLabel& l) {
  py::array_t<float> out({py::ssize_t{kNumKeypoints}, py::ssize_t{3}});
  float* p = out.mutable_data();
  for (const auto& k : l.keypoints) {
    *p++ = k[0];
    *p++ = k[1];
    *p++ = k[2];
  }
  return out;
}

// The label fields as a dict of numpy arrays / numbers (names as in manifest.json's labels[]).
py::dict LabelDict(const ViewLabel& l) {
  py::dict d;
  d["render_id"] = l.render_id;
  d["shape_id"] = l.shape_id;
  d["dir_id"] = l.dir_id;
  d["joint_angles"] = Array1(l.joint_angles);
  d["view_direction"] = Array1(l.view_direction);
  d["view_theta"] = l.view_theta;
  d["view_phi"] = l.view_phi;
  d["camera_roll"] = l.camera_roll;
  d["keypoints"] = Keypoints(l);
  d["source_diameter_px"] = l.source_diameter_px;
  d["scale"] = l.scale;
  d["source_centre_px"] = Array1(l.source_centre_px);
  return d;
}

// Python's json module turns our JSON text into plain dicts and lists (one conversion, no
// hand-written walker to keep in step with nlohmann).
py::object JsonToPython(const json& doc) {
  static py::object* loads = new py::object(py::module_::import("json").attr("loads"));
  return (*loads)(doc.dump());
}

// ---------------------------------------------------------------------------------------------
// Query edges.

struct PyQueryEdges {
  PictureEvidence picture;
};

// A path argument (str, bytes or os.PathLike), encoded as the file system wants it (os.fsencode,
// as pybind11's own path conversion does). No file name holds a NUL character: that is a bad
// value (ValueError naming the argument), not a failed cast.
fs::path PathArg(py::handle value, const char* name) {
  const std::string bytes = py::module_::import("os").attr("fsencode")(value).cast<std::string>();
  if (bytes.find('\0') != std::string::npos) {
    throw py::value_error(std::string(name) + ": a path may not contain a NUL character");
  }
  return fs::path(bytes);
}

py::array_t<int32_t> PixelArray(const std::vector<EdgePixelXY>& px) {
  py::array_t<int32_t> out({static_cast<py::ssize_t>(px.size()), py::ssize_t{2}});
  int32_t* p = out.mutable_data();
  for (const auto& e : px) {
    *p++ = e.x;
    *p++ = e.y;
  }
  return out;
}

py::array_t<float> Point2fArray(const std::vector<Point2f>& pts) {
  py::array_t<float> out({static_cast<py::ssize_t>(pts.size()), py::ssize_t{2}});
  float* p = out.mutable_data();
  for (const auto& q : pts) {
    *p++ = q.x;
    *p++ = q.y;
  }
  return out;
}

// "x,y,w,h" or a 4-sequence; "a,b,..." or an n-sequence of ints.
std::vector<int> IntList(const py::handle& value, size_t n, const char* name) {
  std::vector<int> out;
  if (py::isinstance<py::str>(value)) {
    const std::string text = py::cast<std::string>(value);
    size_t pos = 0;
    while (true) {
      const size_t comma = text.find(',', pos);
      const std::string item = text.substr(pos, comma == std::string::npos ? comma : comma - pos);
      size_t used = 0;
      try {
        out.push_back(std::stoi(item, &used));
      } catch (const std::exception&) {
        used = std::string::npos;
      }
      if (used != item.size()) {
        throw py::value_error(std::string(name) + ": '" + text + "' is not " + std::to_string(n) +
                              " comma-separated integers");
      }
      if (comma == std::string::npos) break;
      pos = comma + 1;
    }
  } else {
    for (const py::handle item : value) out.push_back(py::cast<int>(item));
  }
  if (out.size() != n) {
    throw py::value_error(std::string(name) + " needs " + std::to_string(n) + " integers");
  }
  return out;
}

// The landmark model `spec` names ("auto", "off" or a file), loaded once per path and kept: a
// Python loop over photos would otherwise read and check the 5 MB model per photo. "auto"
// without the installed model: None and a Python warning (the CLI's warning), D_c alone.
std::shared_ptr<const HandLandmarker> Landmarker(const std::string& spec) {
  if (spec == "off") return nullptr;
  const fs::path path = spec == "auto" ? HandLandmarker::DefaultModelPath() : fs::path(spec);
  static std::mutex mu;
  static std::map<fs::path, std::shared_ptr<const HandLandmarker>> cache;
  {
    std::lock_guard<std::mutex> lock(mu);
    if (auto it = cache.find(path); it != cache.end()) return it->second;
  }
  std::error_code ec;
  if (spec == "auto" && !fs::exists(path, ec)) {
    const std::string msg = "no hand landmark model at " + path.string() +
                            " (scripts/deps.sh --asset installs it): photos are ranked by D_c "
                            "alone";
    if (PyErr_WarnEx(PyExc_RuntimeWarning, msg.c_str(), 1) != 0) throw py::error_already_set();
    return nullptr;
  }
  auto opened = HandLandmarker::Open(path);
  if (!opened.ok()) throw StatusError(opened.status());
  std::lock_guard<std::mutex> lock(mu);
  return cache.emplace(path, std::move(opened).value()).first->second;
}

// The keyword options of query_edges() and search(), named like `handdb query`'s flags.
PictureOptions PictureOptionsFromKwargs(const py::kwargs& kw) {
  PictureOptions picture;
  ImageEdgeOptions& o = picture.edges;
  std::string landmarks = "auto";
  for (const auto& [key_handle, value] : kw) {
    const std::string key = py::cast<std::string>(key_handle);
    if (key == "input") {
      auto kind = ParseQueryInputKind(py::cast<std::string>(value));
      if (!kind.ok()) throw py::value_error("input must be auto, photo, edges or labels");
      o.kind = *kind;
    } else if (key == "mask") {
      if (!value.is_none()) o.mask = PathArg(value, "mask");
    } else if (key == "roi") {
      if (!value.is_none()) {
        const auto v = IntList(value, 4, "roi (x, y, w, h)");
        o.roi = {v[0], v[1], v[2], v[3]};
        if (o.roi.empty()) throw py::value_error("roi: width and height must be positive");
      }
    } else if (key == "skin") {
      if (!value.is_none()) {
        const auto v = IntList(value, 6, "skin (Ymin, Ymax, Crmin, Crmax, Cbmin, Cbmax)");
        o.skin = {v[0], v[1], v[2], v[3], v[4], v[5]};
      }
    } else if (key == "canny") {
      if (!value.is_none()) {
        const auto v = IntList(value, 2, "canny (low, high)");
        o.canny_low = v[0];
        o.canny_high = v[1];
      }
    } else if (key == "contour_clearance") {
      o.contour_clearance_px = py::cast<int>(value);
    } else if (key == "edges_outside") {
      o.interior_edges_only = !py::cast<bool>(value);
    } else if (key == "work_diameter") {
      o.work_diameter_px = py::cast<double>(value);
    } else if (key == "wrist_cut") {
      o.cut_forearm = py::cast<bool>(value);
    } else if (key == "landmarks") {
      landmarks = value.is_none() ? "off" : py::cast<std::string>(py::str(value));
    } else if (key == "landmark_passes") {
      picture.landmark_passes = py::cast<int>(value);
      if (picture.landmark_passes != 1 && picture.landmark_passes != 2) {
        throw py::value_error("landmark_passes must be 1 or 2");
      }
    } else {
      throw py::type_error("unexpected keyword argument '" + key + "'");
    }
  }
  if (!o.Check()) {
    throw py::value_error(
        "invalid photo options (skin box within 0..255 and min <= max, 0 <= canny low <= high, "
        "contour_clearance 0..20, "
        "work_diameter 0 or 16..4096)");
  }
  // Edge images and label EXRs have no photo to find landmarks in.
  if (o.kind != QueryInputKind::kEdges && o.kind != QueryInputKind::kLabels) {
    picture.landmarker = Landmarker(landmarks);
  }
  return picture;
}

// A label EXR is converted with the edge options the database was made with (as `handdb query`
// does).
void UseDatabaseConversion(const fs::path& db_dir, PictureOptions* options) {
  auto recorded = ReadDatabaseViewConversion(db_dir);
  if (!recorded.ok()) throw StatusError(recorded.status());
  options->edges.label_edges = recorded->edges;
  options->edges.label_joint_pairs = recorded->joint_pairs;
}

PyQueryEdges LoadEdges(const fs::path& image,
                       PictureOptions options,
                       const std::optional<fs::path>& db_dir) {
  py::gil_scoped_release release;
  if (db_dir) UseDatabaseConversion(*db_dir, &options);
  return PyQueryEdges{Unwrap(ReadPicture(image, options))};
}

// ---------------------------------------------------------------------------------------------
// The database.

class PyDatabase;

struct PyView {
  py::object owner;  // the Database (keeps the mapping alive)
  const PyDatabase* db = nullptr;
  view_id_t index = 0;
  ViewLabel label;
  std::span<const PointQ> points;
  std::string shape_name;
};

class PyDatabase {
 public:
  PyDatabase(fs::path path, bool verify, const std::string& search)
      : path_(std::move(path)), verify_(verify), search_(search) {
    auto use = ParseIndexUse(search);
    if (!use.ok()) throw py::value_error("search must be auto, exact or indexed");
    searcher_options_.verify = verify;
    searcher_options_.use_index = *use;
    {
      py::gil_scoped_release release;
      // The errors are the ones `handdb query` prints.
      db_ = std::make_shared<const Database>(Unwrap(Database::Open(path_, verify)));
    }
  }

  const Database& db() const { return *db_; }
  const fs::path& path() const { return path_; }
  // The rig the database was rendered with (the pose fit's), read on the first fit under the
  // GIL, as the searcher is; null when the database carries none and `required` is false.
  std::shared_ptr<const DatabaseRig> rig(bool required) const {
    if (!rig_loaded_) {
      auto rig = LoadDatabaseRig(path_);
      if (rig.ok()) {
        rig_ = std::make_shared<const DatabaseRig>(std::move(rig).value());
      } else {
        rig_status_ = rig.status();
      }
      rig_loaded_ = true;
    }
    if (rig_ == nullptr && required) throw StatusError(rig_status_);
    return rig_;
  }
  bool verify() const { return verify_; }
  const std::string& search() const { return search_; }
  // The manifest the shards were opened with (Database keeps it): re-reading manifest.json could
  // see a newer one while `handdb convert` rewrites the database (docs/format.md section 8).
  const Manifest& manifest() const { return db_->manifest(); }

  view_id_t Index(py::ssize_t i) const {
    const auto n = static_cast<py::ssize_t>(db_->num_views());
    if (i < 0) i += n;
    if (i < 0 || i >= n) {
      throw py::index_error(path_.string() + ": view " + std::to_string(i) +
                            " out of range (database has " + std::to_string(n) +
                            " canonical views)");
    }
    return static_cast<view_id_t>(i);
  }

  PyView View(py::object self, py::ssize_t i) const {
    const view_id_t v = Index(i);
    PyView out;
    out.owner = std::move(self);
    out.db = this;
    out.index = v;
    out.label = db_->label(v);
    out.points = db_->points(v);
    out.shape_name = std::string(db_->shape_name(out.label.shape_id));
    return out;
  }

  // Every field of views [start, stop) as columns; points zero-copy when the range's points are
  // one contiguous run of a mapping (always inside one shard), else copied into one array.
  py::dict Read(py::object self, py::ssize_t start, std::optional<py::ssize_t> stop_arg) const {
    const auto n = static_cast<py::ssize_t>(db_->num_views());
    py::ssize_t stop = stop_arg.value_or(n);
    if (start < 0) start += n;
    if (stop < 0) stop += n;
    start = std::clamp<py::ssize_t>(start, 0, n);
    stop = std::clamp<py::ssize_t>(stop, start, n);
    const py::ssize_t count = stop - start;

    py::array_t<int64_t> offsets(count + 1);
    int64_t* off = offsets.mutable_data();
    off[0] = 0;
    // A coded database's views are decoded into the copy (not kept by the Database).
    bool contiguous = !db_->coded();
    const PointQ* first =
        count && contiguous ? db_->points(static_cast<view_id_t>(start)).data() : nullptr;
    for (py::ssize_t k = 0; k < count; ++k) {
      const auto v = static_cast<view_id_t>(start + k);
      if (contiguous) {
        const auto pts = db_->points(v);
        if (pts.data() != first + off[k] && !pts.empty()) contiguous = false;
      }
      off[k + 1] = off[k] + static_cast<int64_t>(db_->point_count(v));
    }
    py::array points;
    if (contiguous) {
      points = PointsView({first, static_cast<size_t>(off[count])}, self);
    } else {
      py::array_t<int16_t> copy({static_cast<py::ssize_t>(off[count]), py::ssize_t{2}});
      auto* dst = reinterpret_cast<PointQ*>(copy.mutable_data());
      {
        py::gil_scoped_release release;
        std::vector<PointQ> scratch;
        for (py::ssize_t k = 0; k < count; ++k) {
          const auto pts = db_->ViewPoints(static_cast<view_id_t>(start + k), &scratch);
          std::memcpy(dst + off[k], pts.data(), pts.size_bytes());
        }
      }
      points = ReadOnly(std::move(copy));
    }

    const auto c = static_cast<py::ssize_t>(count);
    py::array_t<uint32_t> render_id(c), shape_id(c), dir_id(c);
    py::array_t<float> joints({c, py::ssize_t{kNumJointAngles}});
    py::array_t<float> direction({c, py::ssize_t{3}});
    py::array_t<float> theta(c), phi(c), roll(c), diameter(c), scale(c);
    py::array_t<float> keypoints({c, py::ssize_t{kNumKeypoints}, py::ssize_t{3}});
    py::array_t<float> centre({c, py::ssize_t{2}});
    {
      uint32_t* rid = render_id.mutable_data();
      uint32_t* sid = shape_id.mutable_data();
      uint32_t* did = dir_id.mutable_data();
      float* ja = joints.mutable_data();
      float* vd = direction.mutable_data();
      float* th = theta.mutable_data();
      float* ph = phi.mutable_data();
      float* cr = roll.mutable_data();
      float* kp = keypoints.mutable_data();
      float* sd = diameter.mutable_data();
      float* sc = scale.mutable_data();
      float* ce = centre.mutable_data();
      py::gil_scoped_release release;
      for (py::ssize_t k = 0; k < count; ++k) {
        const ViewLabel l = db_->label(static_cast<view_id_t>(start + k));
        rid[k] = l.render_id;
        sid[k] = l.shape_id;
        did[k] = l.dir_id;
        std::memcpy(ja + k * kNumJointAngles, l.joint_angles.data(), sizeof(l.joint_angles));
        std::memcpy(vd + k * 3, l.view_direction.data(), sizeof(l.view_direction));
        th[k] = l.view_theta;
        ph[k] = l.view_phi;
        cr[k] = l.camera_roll;
        static_assert(sizeof(l.keypoints) == sizeof(float) * kNumKeypoints * 3);
        std::memcpy(kp + k * kNumKeypoints * 3, l.keypoints.data(), sizeof(l.keypoints));
        sd[k] = l.source_diameter_px;
        sc[k] = l.scale;
        std::memcpy(ce + k * 2, l.source_centre_px.data(), sizeof(l.source_centre_px));
      }
    }
    py::dict d;
    d["start"] = start;
    d["stop"] = stop;
    d["points"] = points;
    d["point_offsets"] = offsets;
    d["render_id"] = render_id;
    d["shape_id"] = shape_id;
    d["dir_id"] = dir_id;
    d["joint_angles"] = joints;
    d["view_direction"] = direction;
    d["view_theta"] = theta;
    d["view_phi"] = phi;
    d["camera_roll"] = roll;
    d["keypoints"] = keypoints;
    d["source_diameter_px"] = diameter;
    d["scale"] = scale;
    d["source_centre_px"] = centre;
    return d;
  }

  // [start, stop) of each shard's views: the maximal runs whose points are one contiguous array
  // (a shard's point ranges are contiguous and in order, docs/format.md 3.2; two shards' points
  // never touch, their headers lie between).
  std::vector<std::pair<size_t, size_t>> ShardRanges() const {
    std::vector<std::pair<size_t, size_t>> out;
    const PointQ* next = nullptr;
    for (size_t v = 0; v < db_->num_views(); ++v) {
      const auto pts = db_->points(static_cast<view_id_t>(v));
      if (out.empty() || (pts.data() != next && !pts.empty())) {
        out.emplace_back(v, v + 1);
      } else {
        out.back().second = v + 1;
      }
      if (!pts.empty()) next = pts.data() + pts.size();
    }
    return out;
  }

  // Built on the first search (it scans every view's points once), under the GIL, as
  // `handdb query` opens one: with the index the manifest lists unless search='exact'.
  const Searcher& searcher() const {
    if (!searcher_) searcher_ = Unwrap(Searcher::Create(db_, searcher_options_));
    return *searcher_;
  }

 private:
  fs::path path_;
  bool verify_ = false;
  std::string search_ = "auto";
  SearcherOptions searcher_options_;
  std::shared_ptr<const Database> db_;
  mutable std::unique_ptr<Searcher> searcher_;
  mutable bool rig_loaded_ = false;
  mutable std::shared_ptr<const DatabaseRig> rig_;
  mutable Status rig_status_;
};

// ---------------------------------------------------------------------------------------------
// Search.

struct PyMatch {
  int rank = 0;
  Match match;
  std::optional<MatchFit> fit;  // a picture search with fit on: this match's pose fit
  std::optional<std::vector<Point2f>> keypoints_image;  // only for an image query
  std::shared_ptr<const QueryEdges> query;              // only for an image query
};

py::object KeypointsImage(const PyMatch& m) {
  if (!m.keypoints_image) return py::none();
  return Point2fArray(*m.keypoints_image);
}

// The match as `handdb query --json` prints it (schemas/query_result.schema.json, matches[]):
// the one JSON writer of a match (pose/match_json.h), as plain dicts and lists.
py::dict MatchDict(const PyMatch& pm) {
  json j = MatchToJson(pm.match, pm.rank, pm.query.get());
  if (pm.fit) j["fit"] = MatchFitToJson(*pm.fit);
  return JsonToPython(j);
}

py::dict StatsDict(const SearchStats& st, const Database& db) {
  py::dict d;
  d["virtual_views"] = st.virtual_views;
  d["canonical_views"] = db.num_views();
  d["rolls"] = db.num_rolls();
  d["refined"] = st.refined;
  d["abandoned"] = st.abandoned;
  d["view_kdtrees"] = st.view_trees;
  d["scan_abandoned"] = st.probe_abandoned;
  d["grids"] = st.grids;
  d["grid_bounded"] = st.grid_bounded;
  d["searches"] = st.searches;
  d["candidates"] = st.candidates;
  d["seconds"] = st.seconds_total;
  d["seconds_bounds"] = st.seconds_bounds;
  d["seconds_refine"] = st.seconds_refine;
  return d;
}

// (n, 2) points: float -> normalised px; int16 -> PointQ units (1/16 px, as stored).
std::vector<Point2f> QueryPoints(const py::array& a) {
  if (a.ndim() != 2 || a.shape(1) != 2) {
    throw py::value_error("query points must be an (n, 2) array (x, y in the normalised frame)");
  }
  std::vector<Point2f> out(static_cast<size_t>(a.shape(0)));
  if (a.dtype().kind() == 'i' && a.itemsize() == 2) {
    auto q = py::array_t<int16_t, py::array::c_style | py::array::forcecast>::ensure(a);
    const int16_t* p = q.data();
    for (size_t i = 0; i < out.size(); ++i)
      out[i] = {PointQToPx(p[2 * i]), PointQToPx(p[2 * i + 1])};
    return out;
  }
  if (a.dtype().kind() != 'f') {
    throw py::type_error(
        "query points must be float (px in the normalised frame) or int16 (1/16 px, as "
        "View.points)");
  }
  auto f = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(a);
  const float* p = f.data();
  for (size_t i = 0; i < out.size(); ++i) out[i] = {p[2 * i], p[2 * i + 1]};
  return out;
}

// The keyword options search() and search_many() share, checked (ValueError).
SearchOptions SearchOptionsFromArgs(int top_k,
                                    int threads,
                                    const std::string& hand,
                                    bool brute_force,
                                    const std::string& kdtree,
                                    float dt_cell_px,
                                    bool coarse_bound,
                                    int per_shape) {
  SearchOptions options;
  options.top_k = top_k;
  options.max_per_shape = per_shape;
  options.num_threads = threads;
  options.brute_force = brute_force;
  options.dt_cell_px = dt_cell_px;
  options.coarse_bound = coarse_bound;
  auto h = ParseHand(hand);
  if (!h.ok()) throw py::value_error("hand must be right, left or either");
  options.hand = *h;
  auto k = ParseKdTreeBackend(kdtree);
  if (!k.ok()) throw py::value_error("kdtree must be nanoflann or pcl");
  options.kdtree = *k;
  if (top_k < 1) throw py::value_error("top_k must be >= 1");
  if (per_shape < 0) throw py::value_error("per_shape must be >= 0");
  if (threads == 0 || threads < -1 || threads > MaxNumThreads()) {
    throw py::value_error("threads must be -1 or 1.." + std::to_string(MaxNumThreads()));
  }
  // The grids the distance transform supports (as `handdb query --dt-cell` checks): one message
  // naming the argument, not the option check's source lines.
  bool dt_cell_ok = false;
  for (int k = 0; k <= 4; ++k) dt_cell_ok |= dt_cell_px == 1.0f / static_cast<float>(1 << k);
  if (!dt_cell_ok) {
    throw py::value_error("dt_cell_px " + py::str(py::float_(dt_cell_px)).cast<std::string>() +
                          ": must be 1, 0.5, 0.25, 0.125 or 0.0625 (px)");
  }
  return options;
}

LandmarkRankOptions LandmarkRankFromArgs(double landmark_weight, float landmark_handedness) {
  LandmarkRankOptions landmark_rank;
  landmark_rank.weight = landmark_weight;
  landmark_rank.handedness = landmark_handedness;
  if (!landmark_rank.Check()) {
    throw py::value_error("landmark_weight must be >= 0 and landmark_handedness in [0.5, 1]");
  }
  return landmark_rank;
}

// The fit options search() and search_many() share: the database's rig unless fit is 'off'.
void FitFromArgs(const PyDatabase& self,
                 const std::string& fit,
                 int fit_matches,
                 PictureSearchOptions* options) {
  if (fit != "auto" && fit != "on" && fit != "off") {
    throw py::value_error("fit must be auto, on or off");
  }
  if (fit_matches < 1) throw py::value_error("fit_matches must be >= 1");
  options->fit.max_matches = fit_matches;
  // As `handdb query --fit on`: a picture without landmarks fitted to its silhouette.
  options->fit.use_silhouette = fit == "on";
  if (fit != "off") options->rig = self.rig(fit == "on");
}

// A search's matches as Match objects, with their keypoints in the picture and their pose fits
// when there are.
py::list MatchList(std::vector<Match> matches,
                   std::optional<PictureEvidence> picture,
                   PictureFit fitted = {}) {
  const std::shared_ptr<const QueryEdges> query_edges =
      picture ? std::make_shared<const QueryEdges>(std::move(picture->edges)) : nullptr;
  py::list out;
  int rank = 1;
  for (Match& m : matches) {
    PyMatch pm;
    pm.rank = rank++;
    if (query_edges) {
      pm.query = query_edges;
      pm.keypoints_image.emplace();
      for (const auto& kp : m.label.keypoints) {
        pm.keypoints_image->push_back(query_edges->ImageFromNormalised({kp[0], kp[1]}));
      }
    }
    if (static_cast<size_t>(pm.rank - 1) < fitted.fits.size()) {
      pm.fit = std::move(fitted.fits[pm.rank - 1]);
    }
    pm.match = std::move(m);
    out.append(py::cast(std::move(pm)));
  }
  return out;
}

py::object Search(const PyDatabase& self,
                  py::object query,
                  int top_k,
                  int threads,
                  const std::string& hand,
                  bool brute_force,
                  const std::string& kdtree,
                  float dt_cell_px,
                  bool coarse_bound,
                  bool return_stats,
                  int per_shape,
                  double landmark_weight,
                  float landmark_handedness,
                  const std::string& fit,
                  int fit_matches,
                  const py::kwargs& edge_kwargs) {
  const SearchOptions options = SearchOptionsFromArgs(
      top_k, threads, hand, brute_force, kdtree, dt_cell_px, coarse_bound, per_shape);
  const LandmarkRankOptions landmark_rank =
      LandmarkRankFromArgs(landmark_weight, landmark_handedness);

  std::optional<PictureEvidence> picture;
  std::vector<Point2f> points;
  // A picture file is read and searched in one call (pose/picture_search.h), as `handdb query`
  // does.
  std::optional<fs::path> picture_file;
  PictureSearchOptions picture_search;
  if (py::isinstance<PyQueryEdges>(query)) {
    if (edge_kwargs.size()) throw py::type_error("image options given with a QueryEdges query");
    picture = py::cast<const PyQueryEdges&>(query).picture;
  } else if (py::isinstance<py::str>(query) || py::hasattr(query, "__fspath__")) {
    picture_file = PathArg(query, "query");
    picture_search.picture = PictureOptionsFromKwargs(edge_kwargs);
    picture_search.search = options;
    picture_search.landmark_rank = landmark_rank;
    FitFromArgs(self, fit, fit_matches, &picture_search);
    picture_search.fit.num_threads = ResolveNumThreads(options.num_threads);
  } else {
    if (edge_kwargs.size()) throw py::type_error("image options given with a points query");
    points = QueryPoints(py::array::ensure(query));
  }

  const Searcher& searcher = self.searcher();
  SearchStats stats;
  std::optional<Result<std::vector<Match>>> matches;
  PictureFit fitted;
  {
    py::gil_scoped_release release;
    if (picture_file) {
      UseDatabaseConversion(self.path(), &picture_search.picture);
      auto found = SearchPicture(searcher, *picture_file, picture_search, &stats);
      if (!found.ok()) throw StatusError(found.status());
      picture = std::move(found->evidence);
      matches.emplace(std::move(found->matches));
      fitted = std::move(found->fit);
    } else if (picture) {
      matches.emplace(SearchEvidence(searcher, *picture, options, landmark_rank, &stats));
    } else {
      matches.emplace(searcher.Search(points, options, &stats));
    }
  }
  if (!matches->ok()) throw StatusError(matches->status());
  py::list out = MatchList(std::move(matches->value()), std::move(picture), std::move(fitted));
  if (!return_stats) return out;
  py::dict st = StatsDict(stats, self.db());
  st["threads"] = ResolveNumThreads(threads);
  return py::make_tuple(out, st);
}

// A video's (or a folder of frames') poses, one dict per frame as `handdb track` prints them
// (track/track_json.h); the GIL is released while tracking.
py::list Track(const PyDatabase& self,
               py::object path,
               int top_k,
               int threads,
               const std::string& hand,
               const std::string& smooth,
               bool local_search,
               bool landmark_tracking,
               int full_every,
               double fps,
               const std::string& fit,
               const py::kwargs& edge_kwargs) {
  const fs::path input = PathArg(path, "path");
  TrackOptions options;
  options.picture.search =
      SearchOptionsFromArgs(top_k, threads, hand, false, "nanoflann", 1.0f, true, 0);
  options.picture.picture = PictureOptionsFromKwargs(edge_kwargs);
  FitFromArgs(self, fit, MatchFitOptions{}.max_matches, &options.picture);
  auto smoothing = ParseSmoothing(smooth);
  if (!smoothing.ok()) throw py::value_error(smoothing.status().message());
  options.smoothing = *smoothing;
  options.local_search = local_search;
  options.landmark_tracking = landmark_tracking;
  if (full_every < 0) throw py::value_error("full_every must be >= 0");
  options.full_every = full_every;
  FrameSourceOptions source;
  source.folder_fps = fps;
  if (!source.Check()) throw py::value_error("fps must be in (0, 10000]");
  const Searcher& searcher = self.searcher();
  std::vector<json> frames;
  {
    py::gil_scoped_release release;
    UseDatabaseConversion(self.path(), &options.picture.picture);
    auto opened = OpenFrames(input, source);
    if (!opened.ok()) throw StatusError(opened.status());
    auto summary = TrackFrames(searcher, **opened, options, [&](const TrackFrame& f) {
      frames.push_back(TrackFrameToJson(f));
      return Status::Ok();
    });
    if (!summary.ok()) throw StatusError(summary.status());
  }
  py::list out;
  for (const json& f : frames) out.append(JsonToPython(f));
  return out;
}

// handdb.Error for a library error, as the exception translator raises it (BindError).
py::object ErrorObject(const Status& status) {
  py::object exc = (*error_type)(status.message());
  exc.attr("code") = StatusCodeName(status.code());
  return exc;
}

// Many pictures with one call: the options (and the landmark model) are resolved once, and the
// pictures are searched in parallel with the GIL released, each as search() would.
py::list SearchMany(const PyDatabase& self,
                    const py::iterable& pictures,
                    int top_k,
                    int threads,
                    const std::string& hand,
                    bool brute_force,
                    const std::string& kdtree,
                    float dt_cell_px,
                    bool coarse_bound,
                    bool return_stats,
                    int per_shape,
                    double landmark_weight,
                    float landmark_handedness,
                    const std::string& fit,
                    int fit_matches,
                    bool return_exceptions,
                    const py::kwargs& edge_kwargs) {
  std::vector<fs::path> paths;
  for (const py::handle item : pictures) {
    if (!py::isinstance<py::str>(item) && !py::hasattr(item, "__fspath__")) {
      throw py::type_error(
          "search_many takes picture paths (str or os.PathLike); search() takes QueryEdges and "
          "point arrays");
    }
    paths.push_back(PathArg(item, "pictures"));
  }
  PictureSearchOptions options;
  options.search = SearchOptionsFromArgs(
      top_k, threads, hand, brute_force, kdtree, dt_cell_px, coarse_bound, per_shape);
  options.landmark_rank = LandmarkRankFromArgs(landmark_weight, landmark_handedness);
  options.picture = PictureOptionsFromKwargs(edge_kwargs);
  FitFromArgs(self, fit, fit_matches, &options);
  const Searcher& searcher = self.searcher();
  const size_t n = paths.size();
  std::vector<std::optional<Result<PictureMatches>>> found(n);
  std::vector<SearchStats> stats(n);
  {
    py::gil_scoped_release release;
    if (n > 0) UseDatabaseConversion(self.path(), &options.picture);
    // Pictures in parallel first (reading and the landmark network are one thread each), the
    // threads left over shared by each picture's search; the results do not depend on the split.
    const int total = ResolveNumThreads(threads);
    const int workers = static_cast<int>(std::min<size_t>(static_cast<size_t>(total), n));
    options.search.num_threads = std::max(1, total / std::max(workers, 1));
    options.fit.num_threads = options.search.num_threads;
    ParallelFor(n, workers, [&](size_t i, int) {
      found[i].emplace(SearchPicture(searcher, paths[i], options, &stats[i]));
      return true;
    });
  }
  py::list out;
  for (size_t i = 0; i < n; ++i) {
    Result<PictureMatches>& r = *found[i];
    if (!r.ok()) {
      // Every picture has run; without return_exceptions the first failure (in input order)
      // is raised as search() would raise it.
      if (!return_exceptions) throw StatusError(r.status());
      out.append(ErrorObject(r.status()));
      continue;
    }
    py::list matches = MatchList(std::move(r->matches), std::move(r->evidence), std::move(r->fit));
    if (!return_stats) {
      out.append(matches);
      continue;
    }
    py::dict st = StatsDict(stats[i], self.db());
    st["threads"] = ResolveNumThreads(threads);
    out.append(py::make_tuple(matches, st));
  }
  return out;
}

py::list Validate(const fs::path& path, bool verify_checksums, size_t max_problems) {
  ValidateOptions options;
  options.verify_checksums = verify_checksums;
  options.max_problems_per_check = max_problems;
  ValidationReport r;
  {
    py::gil_scoped_release release;
    r = ValidatePath(path, options);
  }
  py::list problems;
  for (const auto& p : r.problems) {
    py::dict d;
    d["code"] = StatusCodeName(p.code);
    d["file"] = p.file;
    d["offset"] = p.offset;
    d["message"] = p.message;
    problems.append(d);
  }
  if (r.suppressed > 0) {
    // The rest were counted only; say so rather than return a list that looks complete.
    py::dict d;
    d["code"] = "kSuppressed";
    d["file"] = path.string();
    d["offset"] = 0;
    d["message"] = path.string() + ": " + std::to_string(r.suppressed) +
                   " more problem(s) not listed (use max_problems=0 to list them)";
    problems.append(d);
  }
  return problems;
}

// handdb.Error and the translation of a library error (Status) into it.
void BindError(py::module_& m) {
  error_type = new py::object(py::exception<StatusError>(m, "Error", PyExc_RuntimeError));
  error_type->attr("__doc__") =
      "A handdb library error: str(e) is the one-line message `handdb` prints after "
      "'handdb <command>: ' (it names the file and the problem); e.code is the status code name, "
      "e.g. 'kChecksumMismatch', 'kNotFound', 'kNoHand'.";
  py::object bases = py::make_tuple(*error_type, py::handle(PyExc_ValueError));
  argument_error_type = new py::object(py::reinterpret_steal<py::object>(
      PyErr_NewException("handdb._handdb.ArgumentError", bases.ptr(), nullptr)));
  if (!*argument_error_type) throw py::error_already_set();
  argument_error_type->attr("__doc__") =
      "A handdb.Error that is also a ValueError: what the library was given cannot be used (code "
      "'kInvalidArgument'), e.g. a picture too thin to hold a hand.";
  m.attr("ArgumentError") = *argument_error_type;
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const StatusError& e) {
      const py::object& type =
          e.status.code() == StatusCode::kInvalidArgument ? *argument_error_type : *error_type;
      py::object exc = type(e.status.message());
      exc.attr("code") = StatusCodeName(e.status.code());
      PyErr_SetObject(type.ptr(), exc.ptr());
    }
  });
}

// QueryEdges and query_edges(): a picture's evidence.
void BindQueryEdges(py::module_& m) {
  py::class_<PyQueryEdges>(m,
                           "QueryEdges",
                           "A query image's edge points in the database's normalised frame "
                           "(handdb.query_edges(); docs/query.md 'From a picture to edges').")
      .def_property_readonly(
          "kind",
          [](const PyQueryEdges& q) {
            return std::string(QueryInputKindName(q.picture.edges.kind));
          },
          "the input kind used: 'photo', 'edges' or 'labels'")
      .def_property_readonly(
          "points",
          [](py::object self) {
            const auto& q = py::cast<const PyQueryEdges&>(self).picture.edges;
            return PointsView(q.points, self);
          },
          "(n, 2) int16, read-only: normalised points in 1/16 px (sorted by y, x; unique)")
      .def_property_readonly(
          "points_px",
          [](const PyQueryEdges& q) { return Point2fArray(q.picture.edges.points_px()); },
          "(n, 2) float32: the same in px (what the search uses)")
      .def_property_readonly(
          "edge_pixels",
          [](const PyQueryEdges& q) { return PixelArray(q.picture.edges.edge_pixels); },
          "(n, 2) int32: edge pixels (column, row) of the input image")
      .def_property_readonly(
          "contour_pixels",
          [](const PyQueryEdges& q) { return PixelArray(q.picture.edges.contour_pixels); },
          "(n, 2) int32: the silhouette contour used for the normalisation")
      .def_property_readonly("width", [](const PyQueryEdges& q) { return q.picture.edges.width; })
      .def_property_readonly("height", [](const PyQueryEdges& q) { return q.picture.edges.height; })
      .def_property_readonly("hand_pixels",
                             [](const PyQueryEdges& q) { return q.picture.edges.hand_pixels; })
      .def_property_readonly(
          "touches_border",
          [](const PyQueryEdges& q) { return q.picture.edges.touches_border; },
          "the hand region reaches the image border")
      .def_property_readonly("diameter_px",
                             [](const PyQueryEdges& q) { return q.picture.edges.diameter_px; })
      .def_property_readonly(
          "centre_px",
          [](const PyQueryEdges& q) {
            return py::make_tuple(q.picture.edges.centre_x, q.picture.edges.centre_y);
          },
          "normalisation centre in image px: normalised = (pixel centre - centre) * scale")
      .def_property_readonly("scale", [](const PyQueryEdges& q) { return q.picture.edges.scale; })
      .def_property_readonly(
          "palm",
          [](const PyQueryEdges& q) -> py::object {
            if (q.picture.edges.palm_radius_px <= 0) return py::none();
            return py::make_tuple(q.picture.edges.palm_centre_x,
                                  q.picture.edges.palm_centre_y,
                                  q.picture.edges.palm_radius_px);
          },
          "photo: the palm's largest inscribed circle (x, y, radius) in image px, or None")
      .def_property_readonly(
          "arm_direction",
          [](const PyQueryEdges& q) -> py::object {
            if (!q.picture.edges.arm_found) return py::none();
            return py::make_tuple(q.picture.edges.arm_dir_x, q.picture.edges.arm_dir_y);
          },
          "photo: unit vector (x right, y down, image px) from the palm centre towards where "
          "the arm leaves the picture, or None when no arm was found")
      .def_property_readonly(
          "wrist_line",
          [](const PyQueryEdges& q) -> py::object {
            if (!q.picture.edges.forearm_cut) return py::none();
            const auto& w = q.picture.edges.wrist_line;
            return py::make_tuple(w[0], w[1], w[2], w[3]);
          },
          "photo: the wrist cut (x0, y0, x1, y1) in image px, or None when no forearm was cut")
      .def_property_readonly(
          "landmarks",
          [](const PyQueryEdges& q) -> py::object {
            if (!q.picture.landmarks) return py::none();
            const HandLandmarks& l = *q.picture.landmarks;
            py::dict d;
            d["presence"] = l.presence;
            d["handedness"] = l.handedness;
            d["image_px"] =
                Point2fArray(std::vector<Point2f>(l.image_px.begin(), l.image_px.end()));
            d["crop_centre_px"] = py::make_tuple(l.crop.centre.x, l.crop.centre.y);
            d["crop_side_px"] = l.crop.side;
            d["crop_angle_deg"] = l.crop.angle_deg;
            return d;
          },
          "photo: the hand landmark network's joints, {presence, handedness, image_px (21, 2), "
          "crop_*}, or None (no model, or not a photo)")
      .def(
          "image_from_normalised",
          [](const PyQueryEdges& q,
             py::array_t<float, py::array::c_style | py::array::forcecast> xy) {
            if (xy.ndim() != 2 || xy.shape(1) < 2)
              throw py::value_error("expected an (n, 2) array");
            std::vector<Point2f> out;
            for (py::ssize_t i = 0; i < xy.shape(0); ++i) {
              out.push_back(q.picture.edges.ImageFromNormalised({xy.at(i, 0), xy.at(i, 1)}));
            }
            return Point2fArray(out);
          },
          py::arg("xy"),
          "Normalised px (n, 2) -> input image px (pixel centres at integer + 0.5).")
      .def("__len__", [](const PyQueryEdges& q) { return q.picture.edges.points.size(); })
      .def("__repr__", [](const PyQueryEdges& q) {
        return "<handdb.QueryEdges " + std::string(QueryInputKindName(q.picture.edges.kind)) + " " +
               std::to_string(q.picture.edges.width) + "x" +
               std::to_string(q.picture.edges.height) + ", " +
               std::to_string(q.picture.edges.points.size()) + " points>";
      });

  m.def(
      "query_edges",
      [](py::object image, py::object database, const py::kwargs& kw) {
        std::optional<fs::path> db_dir;
        if (py::isinstance<PyDatabase>(database)) {
          db_dir = py::cast<const PyDatabase&>(database).path();
        } else if (!database.is_none()) {
          db_dir = PathArg(database, "database");
        }
        return LoadEdges(PathArg(image, "image"), PictureOptionsFromKwargs(kw), db_dir);
      },
      py::arg("image"),
      py::arg("database") = py::none(),
      "A query image -> QueryEdges (normalised points), exactly as `handdb query` converts it.\n\n"
      "Options, named like the command's flags: input='auto'|'photo'|'edges'|'labels', "
      "mask=path, roi=(x, y, w, h), skin=(Ymin, Ymax, Crmin, Crmax, Cbmin, Cbmax), "
      "canny=(low, high), contour_clearance=2, edges_outside=False, work_diameter=128, "
      "wrist_cut=True, landmarks='auto' (the installed hand landmark model; 'off' or None: "
      "none; or a .tflite file), landmark_passes=2 (1: the network on the segmentation's crop "
      "only). database (a Database or "
      "its path): label EXRs use the edge options it was converted with.");
}

// View: one canonical view of a database.
void BindView(py::module_& m) {
  py::class_<PyView>(m,
                     "View",
                     "One canonical (roll 0) view: its edge points and pose label, read from the "
                     "database's mapping. Label fields follow docs/format.md 3.2 and "
                     "docs/conventions.md (radians, normalised px).")
      .def_readonly("index", &PyView::index, "canonical view index (manifest order)")
      .def_property_readonly(
          "points",
          [](const PyView& v) { return PointsView(v.points, v.owner); },
          "(n, 2) int16, read-only, zero-copy view of the shard: x, y in 1/16 px (divide by "
          "handdb.POINT_SCALE for px), normalised frame")
      .def_property_readonly(
          "points_px",
          [](const PyView& v) {
            py::array_t<float> out({static_cast<py::ssize_t>(v.points.size()), py::ssize_t{2}});
            float* p = out.mutable_data();
            for (const PointQ& q : v.points) {
              *p++ = PointQToPx(q.x);
              *p++ = PointQToPx(q.y);
            }
            return out;
          },
          "(n, 2) float32 copy of the points in px")
      .def_property_readonly(
          "shape_name",
          [](const PyView& v) { return v.shape_name; },
          "name of the shape from the database's shape table, '' if unknown")
      .def_property_readonly("render_id", [](const PyView& v) { return v.label.render_id; })
      .def_property_readonly("shape_id", [](const PyView& v) { return v.label.shape_id; })
      .def_property_readonly("dir_id", [](const PyView& v) { return v.label.dir_id; })
      .def_property_readonly(
          "joint_angles",
          [](const PyView& v) { return Array1(v.label.joint_angles); },
          "(20,) float32, radians, hand-model DOF order (docs/conventions.md)")
      .def_property_readonly(
          "view_direction",
          [](const PyView& v) { return Array1(v.label.view_direction); },
          "(3,) float32 unit vector hand -> camera, hand frame")
      .def_property_readonly("view_theta", [](const PyView& v) { return v.label.view_theta; })
      .def_property_readonly("view_phi", [](const PyView& v) { return v.label.view_phi; })
      .def_property_readonly(
          "camera_roll", [](const PyView& v) { return v.label.camera_roll; }, "radians")
      .def_property_readonly(
          "keypoints",
          [](const PyView& v) { return Keypoints(v.label); },
          "(21, 3) float32: x, y in normalised px, z depth in the same units")
      .def_property_readonly("source_diameter_px",
                             [](const PyView& v) { return v.label.source_diameter_px; })
      .def_property_readonly("scale", [](const PyView& v) { return v.label.scale; })
      .def_property_readonly("source_centre_px",
                             [](const PyView& v) { return Array1(v.label.source_centre_px); })
      .def(
          "label",
          [](const PyView& v) { return LabelDict(v.label); },
          "Every label field as a dict of numbers and numpy arrays.")
      .def(
          "rolled",
          [](const PyView& v, int64_t roll) {
            const uint32_t rolls = v.db->db().num_rolls();
            if (roll < 0 || roll >= static_cast<int64_t>(rolls)) {
              throw py::index_error("roll " + std::to_string(roll) + " out of range 0.." +
                                    std::to_string(rolls - 1));
            }
            const float angle = RollAngle(static_cast<roll_id_t>(roll), rolls);
            std::vector<Point2f> pts;
            RollPoints(v.points, angle, &pts);
            return py::make_tuple(Point2fArray(pts), LabelDict(RollLabel(v.label, angle)));
          },
          py::arg("roll"),
          "Virtual view (index, roll): (points in px (n, 2) float32, label dict), rotated by "
          "2*pi*roll/R as the search sees it (camera_roll and keypoints rolled too).")
      .def("__len__", [](const PyView& v) { return v.points.size(); })
      .def("__repr__", [](const PyView& v) {
        return "<handdb.View " + std::to_string(v.index) + " shape " +
               std::to_string(v.label.shape_id) +
               (v.shape_name.empty() ? "" : " '" + v.shape_name + "'") + ", " +
               std::to_string(v.points.size()) + " points>";
      });
}

// Match: one (view, roll, hand) of a search's answer.
void BindMatch(py::module_& m) {
  py::class_<PyMatch>(m,
                      "Match",
                      "One search result: virtual view (view_id, roll), its chamfer distance "
                      "D_c = a + b (px) and its rolled pose label, as `handdb query --json` "
                      "reports it (to_dict() gives exactly that match object).")
      .def_readonly("rank", &PyMatch::rank)
      .def_property_readonly("view_id", [](const PyMatch& p) { return p.match.view_id; })
      .def_property_readonly("roll", [](const PyMatch& p) { return p.match.roll; })
      .def_property_readonly(
          "roll_angle", [](const PyMatch& p) { return p.match.roll_angle; }, "radians")
      .def_property_readonly("roll_deg",
                             [](const PyMatch& p) { return RollDegrees0To360(p.match.roll_angle); })
      .def_property_readonly(
          "distance", [](const PyMatch& p) { return p.match.distance; }, "D_c = a + b, px")
      .def_property_readonly(
          "a", [](const PyMatch& p) { return p.match.a; }, "query -> view term, px")
      .def_property_readonly(
          "b", [](const PyMatch& p) { return p.match.b; }, "view -> query term, px")
      .def_property_readonly("hand",
                             [](const PyMatch& p) { return std::string(HandName(p.match.hand)); })
      .def_property_readonly(
          "score",
          [](const PyMatch& p) -> py::object {
            if (p.match.score < 0) return py::none();
            return py::cast(p.match.score);
          },
          "when a photo's hand landmarks re-ranked the matches: distance / best distance + "
          "weight x landmark_error (the order of the list); None: ranked by distance")
      .def_property_readonly(
          "landmark_error",
          [](const PyMatch& p) -> py::object {
            if (p.match.landmark_error < 0) return py::none();
            return py::cast(p.match.landmark_error);
          },
          "with score: mean distance of the keypoints to the photo's landmarks, in hand radii")
      .def_property_readonly("shape_name", [](const PyMatch& p) { return p.match.shape_name; })
      .def_property_readonly("render_id", [](const PyMatch& p) { return p.match.label.render_id; })
      .def_property_readonly("shape_id", [](const PyMatch& p) { return p.match.label.shape_id; })
      .def_property_readonly("dir_id", [](const PyMatch& p) { return p.match.label.dir_id; })
      .def_property_readonly("joint_angles",
                             [](const PyMatch& p) { return Array1(p.match.label.joint_angles); })
      .def_property_readonly("view_direction",
                             [](const PyMatch& p) { return Array1(p.match.label.view_direction); })
      .def_property_readonly("view_theta",
                             [](const PyMatch& p) { return p.match.label.view_theta; })
      .def_property_readonly("view_phi", [](const PyMatch& p) { return p.match.label.view_phi; })
      .def_property_readonly("camera_roll",
                             [](const PyMatch& p) { return p.match.label.camera_roll; })
      .def_property_readonly(
          "keypoints",
          [](const PyMatch& p) { return Keypoints(p.match.label); },
          "(21, 3) float32 in the query's normalised frame (rolled, mirrored back for a left "
          "hand)")
      .def_property_readonly(
          "keypoints_image_px",
          &KeypointsImage,
          "(21, 2) float32 keypoints in the input image's pixels, or None for a points query")
      .def(
          "label",
          [](const PyMatch& p) { return LabelDict(p.match.label); },
          "The rolled label as a dict of numbers and numpy arrays.")
      .def_property_readonly(
          "fit",
          [](const PyMatch& p) -> py::object {
            if (!p.fit) return py::none();
            return JsonToPython(MatchFitToJson(*p.fit));
          },
          "The pose fit from this match (a dict as `handdb query --json`'s matches[].fit: "
          "fitted, joint_angles, cam_from_hand, keypoints, keypoints_image_px, cost, ...), or "
          "None when no fit ran (fit='off', a points query)")
      .def("to_dict", &MatchDict, "The match as in `handdb query --json` (plain lists).")
      .def("__repr__", [](const PyMatch& p) {
        char buf[160];
        std::snprintf(buf,
                      sizeof(buf),
                      "<handdb.Match #%d view %u roll %u D_c %.3f %s%s%s>",
                      p.rank,
                      p.match.view_id,
                      p.match.roll,
                      p.match.distance,
                      std::string(HandName(p.match.hand)).c_str(),
                      p.match.shape_name.empty() ? "" : " ",
                      p.match.shape_name.c_str());
        return std::string(buf);
      });
}

// Database: open, read and search a database.
void BindDatabase(py::module_& m) {
  py::class_<PyDatabase>(
      m,
      "Database",
      "A database directory (manifest.json + shard-*.hdb), memory-mapped read-only.\n\n"
      "Database(path, verify=False) runs the open checks of `handdb query` (manifest schema, "
      "every shard's header, section table, footer and labels, counts against the manifest); "
      "verify=True also hashes every section. Errors raise handdb.Error with the tool's "
      "one-line message. search='auto' (default) searches with the index the manifest lists, "
      "as `handdb query` does; 'exact' opts out, 'indexed' requires one.\n\n"
      "A sequence of canonical views: len(db), db[i] / db.view(i) -> View, db[a:b] -> list of "
      "View, iteration; db.read(start, stop) -> every field as numpy columns. Pickling "
      "reopens the path, so each worker process of a data loader maps the shards itself.")
      .def(py::init([](py::object path, bool verify, const std::string& search) {
             return PyDatabase(PathArg(path, "path"), verify, search);
           }),
           py::arg("path"),
           py::arg("verify") = false,
           py::arg("search") = "auto")
      .def_property_readonly(
          "search_mode",
          [](const PyDatabase& d) { return d.search(); },
          "how searches use the database's index: 'auto' (the index the manifest lists, as "
          "`handdb query`), 'exact' or 'indexed'")
      .def_property_readonly(
          "path", [](const PyDatabase& d) { return d.path().string(); }, "the directory")
      .def_property_readonly(
          "num_views",
          [](const PyDatabase& d) { return d.db().num_views(); },
          "canonical (roll 0) views")
      .def_property_readonly(
          "num_rolls",
          [](const PyDatabase& d) { return d.db().num_rolls(); },
          "R: virtual rolls per canonical view")
      .def_property_readonly("num_virtual_views",
                             [](const PyDatabase& d) { return d.db().num_virtual_views(); })
      .def_property_readonly(
          "num_points", [](const PyDatabase& d) { return d.db().num_points(); }, "edge points")
      .def_property_readonly("num_shards",
                             [](const PyDatabase& d) { return d.manifest().shards.size(); })
      .def_property_readonly(
          "shard_ranges",
          [](const PyDatabase& d) { return d.ShardRanges(); },
          "[(start, stop)] view ranges of the shards, in order: read(start, stop) of one is "
          "zero-copy (a data loader's natural chunks)")
      .def_property_readonly(
          "size_bytes",
          [](const PyDatabase& d) { return d.db().size_bytes(); },
          "bytes of the shards on disk")
      .def_property_readonly("shards_with_coarse_fields",
                             [](const PyDatabase& d) {
                               return d.manifest().shards.size() -
                                      d.db().shards_without_coarse_fields();
                             })
      .def_property_readonly(
          "manifest",
          [](const PyDatabase& d) { return JsonToPython(ManifestToJson(d.manifest())); },
          "manifest.json as a dict (what `handdb info DB --json` prints under 'manifest')")
      .def_property_readonly(
          "metadata",
          [](const PyDatabase& d) { return JsonToPython(d.manifest().metadata); },
          "the manifest's metadata (generation config, hand model, conversion, shapes)")
      .def_property_readonly(
          "shape_names",
          [](const PyDatabase& d) {
            std::map<shape_id_t, std::string> names;
            for (view_id_t v = 0; v < d.db().num_views(); ++v) {
              const shape_id_t id = d.db().label(v).shape_id;
              if (!names.count(id)) names[id] = std::string(d.db().shape_name(id));
            }
            return names;
          },
          "{shape_id: name} of the shapes the views use")
      .def(
          "view",
          [](py::object self, py::ssize_t i) {
            return py::cast<const PyDatabase&>(self).View(self, i);
          },
          py::arg("i"),
          "View i (negative counts from the end).")
      .def(
          "points",
          [](py::object self, py::ssize_t i) {
            const auto& d = py::cast<const PyDatabase&>(self);
            return PointsView(d.db().points(d.Index(i)), self);
          },
          py::arg("i"),
          "View i's points: (n, 2) int16, read-only, zero-copy (1/16 px).")
      .def(
          "label",
          [](const PyDatabase& d, py::ssize_t i) { return LabelDict(d.db().label(d.Index(i))); },
          py::arg("i"),
          "View i's label as a dict of numbers and numpy arrays.")
      .def(
          "read",
          [](py::object self, py::ssize_t start, std::optional<py::ssize_t> stop) {
            return py::cast<const PyDatabase&>(self).Read(self, start, stop);
          },
          py::arg("start") = 0,
          py::arg("stop") = py::none(),
          "Views [start, stop) as numpy columns: points (P, 2) int16 (read-only; zero-copy when "
          "the range lies in one shard, else one copy) with point_offsets (n + 1,) int64 (view "
          "k is points[point_offsets[k]:point_offsets[k+1]]), and one array per label field "
          "(render_id, shape_id, dir_id, joint_angles (n, 20), view_direction (n, 3), "
          "view_theta, view_phi, camera_roll, keypoints (n, 21, 3), source_diameter_px, scale, "
          "source_centre_px (n, 2)).")
      .def("__len__", [](const PyDatabase& d) { return d.db().num_views(); })
      .def(
          "__getitem__",
          [](py::object self, py::object key) -> py::object {
            const auto& d = py::cast<const PyDatabase&>(self);
            if (py::isinstance<py::slice>(key)) {
              size_t start = 0, stop = 0, step = 0, length = 0;
              if (!py::cast<py::slice>(key).compute(
                      d.db().num_views(), &start, &stop, &step, &length)) {
                throw py::error_already_set();
              }
              py::list out;
              for (size_t k = 0; k < length; ++k) {
                out.append(d.View(self, static_cast<py::ssize_t>(start + k * step)));
              }
              return out;
            }
            // An index is an int (or has __index__); one too large for the platform's index
            // type is out of range, not a failed cast.
            if (!PyIndex_Check(key.ptr())) {
              throw py::type_error("database indices must be integers or slices, not " +
                                   py::str(py::type::of(key).attr("__name__")).cast<std::string>());
            }
            const Py_ssize_t i = PyNumber_AsSsize_t(key.ptr(), PyExc_OverflowError);
            if (i == -1 && PyErr_Occurred()) {
              if (!PyErr_ExceptionMatches(PyExc_OverflowError)) throw py::error_already_set();
              PyErr_Clear();
              throw py::index_error(d.path().string() + ": view " +
                                    py::str(key).cast<std::string>() +
                                    " out of range (database has " +
                                    std::to_string(d.db().num_views()) + " canonical views)");
            }
            return py::cast(d.View(self, i));
          })
      .def(
          "search",
          &Search,
          py::arg("query"),
          py::arg("top_k") = 10,
          py::arg("threads") = -1,
          py::arg("hand") = "either",
          py::arg("brute_force") = false,
          py::arg("kdtree") = "nanoflann",
          py::arg("dt_cell_px") = 1.0f,
          py::arg("coarse_bound") = true,
          py::arg("return_stats") = false,
          py::arg("per_shape") = 0,
          py::arg("landmark_weight") = LandmarkRankOptions{}.weight,
          py::arg("landmark_handedness") = LandmarkRankOptions{}.handedness,
          py::arg("fit") = "auto",
          py::arg("fit_matches") = MatchFitOptions{}.max_matches,
          "Exact top-k (view, roll) by the chamfer distance (docs/query.md), best first, as a list "
          "of Match; the GIL is released while searching.\n\n"
          "query: an image path (photo, edge image or label EXR: converted like `handdb query "
          "DB IMAGE`, label EXRs with the database's recorded edge options; keyword options as "
          "in query_edges()), a QueryEdges, or an (n, 2) array of normalised points (float: px; "
          "int16: 1/16 px, e.g. a View's points).\n"
          "hand: 'either' (default, as `handdb query`), 'right' or 'left'. threads: -1 = all "
          "cores. return_stats=True returns (matches, stats) with the stats of `handdb query "
          "--json`. per_shape: at most this many matches per basic shape (0: no limit; 1: the "
          "top_k nearest shapes, each by its best view, as `handdb query --per-shape 1`). A photo "
          "whose QueryEdges carry hand landmarks (query_edges(landmarks='auto'), the default) is "
          "re-ranked by them as `handdb query` does (Match.score; landmark_weight as "
          "--landmark-weight; with hand='either', landmark_handedness as --landmark-handedness "
          "searches only the hand the network names). fit: for an image path, 'auto' (default) "
          "fits the pose of the "
          "first fit_matches matches to the photo's landmarks (or, without them, to the "
          "picture's silhouette) as `handdb query --fit` does "
          "(Match.fit; 'on' raises if the database carries no rig, 'off' skips it).")
      .def("track",
           &Track,
           py::arg("path"),
           py::arg("top_k") = 10,
           py::arg("threads") = -1,
           py::arg("hand") = "either",
           py::arg("smooth") = std::string(SmoothingName(TrackOptions{}.smoothing)),
           py::arg("local_search") = true,
           py::arg("landmark_tracking") = TrackOptions{}.landmark_tracking,
           py::arg("full_every") = TrackOptions{}.full_every,
           py::arg("fps") = FrameSourceOptions{}.folder_fps,
           py::arg("fit") = "auto",
           "Tracks a hand through a video file or a folder of frames, as `handdb track DB "
           "PATH` does (docs/track.md): a list with one dict per frame, in order, with the "
           "fields of its JSON lines (schemas/track_frame.schema.json): frame, time_s, source, "
           "found ('full', 'local', 'carried' or 'none' with 'error'), matches, and pose (the "
           "chosen match, its keypoints in the frame's px) when one was found. smooth: "
           "'online' (default), 'offline' or 'off'; local_search=False searches the whole "
           "database every frame; landmark_tracking=False finds each frame's landmarks as a "
           "picture alone's (by default the network looks around the last frame's joints); "
           "full_every: a full search at least every this many frames; "
           "fps: a folder's frame rate. Photo options as in search().")
      .def("search_many",
           &SearchMany,
           py::arg("pictures"),
           py::arg("top_k") = 10,
           py::arg("threads") = -1,
           py::arg("hand") = "either",
           py::arg("brute_force") = false,
           py::arg("kdtree") = "nanoflann",
           py::arg("dt_cell_px") = 1.0f,
           py::arg("coarse_bound") = true,
           py::arg("return_stats") = false,
           py::arg("per_shape") = 0,
           py::arg("landmark_weight") = LandmarkRankOptions{}.weight,
           py::arg("landmark_handedness") = LandmarkRankOptions{}.handedness,
           py::arg("fit") = "auto",
           py::arg("fit_matches") = MatchFitOptions{}.max_matches,
           py::arg("return_exceptions") = false,
           "search() for many picture paths in one call, as `handdb query DB IMAGE...`: the "
           "image options and the landmark model are resolved once and the pictures searched "
           "in parallel (threads bounds the whole call, -1: all cores) with the GIL released. "
           "Returns a list in the order of `pictures`, each item what search() returns for that "
           "picture (a list of Match, or (matches, stats) with return_stats=True).\n\n"
           "A picture that fails (no hand, an unreadable file) does not stop the others: every "
           "picture runs, then the first failure in order raises its handdb.Error; with "
           "return_exceptions=True (as asyncio.gather) its handdb.Error takes its place in the "
           "list instead. Keyword options as in search() and query_edges().")
      .def("__repr__",
           [](const PyDatabase& d) {
             return "<handdb.Database '" + d.path().string() +
                    "': " + std::to_string(d.db().num_views()) + " views x " +
                    std::to_string(d.db().num_rolls()) + " rolls>";
           })
      .def(py::pickle(
          // Absolute: a spawned worker may start in another directory.
          [](const PyDatabase& d) {
            return py::make_tuple(fs::absolute(d.path()).string(), d.verify(), d.search());
          },
          [](const py::tuple& t) {
            if (t.size() != 2 && t.size() != 3) throw py::value_error("bad handdb.Database pickle");
            return PyDatabase(py::cast<fs::path>(t[0]),
                              py::cast<bool>(t[1]),
                              t.size() == 3 ? py::cast<std::string>(t[2]) : "auto");
          }));
}

// validate(): `handdb validate` as a list of problems.
void BindValidate(py::module_& m) {
  m.def(
      "validate",
      [](py::object path, bool verify_checksums, size_t max_problems) {
        return Validate(PathArg(path, "path"), verify_checksums, max_problems);
      },
      py::arg("path"),
      py::arg("verify_checksums") = true,
      py::arg("max_problems") = ValidateOptions{}.max_problems_per_check,
      "Checks a shard file or a database directory completely (`handdb validate`) and returns "
      "the problems as dicts {code, file, offset, message} (the --json report's); [] when it "
      "is valid. max_problems per file and kind of check, 0 = all (if more were found, a last "
      "entry with code 'kSuppressed' counts them).");
}

}  // namespace

PYBIND11_MODULE(_handdb, m) {
  m.doc() =
      "handdb: read and search databases of synthetic hand views (docs/python.md).\n\n"
      "  db = handdb.Database('db')        # manifest + every shard, memory-mapped read-only\n"
      "  v = db[0]                         # a View: points (zero-copy int16, 1/16 px), labels\n"
      "  cols = db.read()                  # every view as numpy columns\n"
      "  matches = db.search('hand.jpg')   # top-k (view, roll) by chamfer distance\n"
      "  problems = handdb.validate('db')  # [] when the database is valid\n";
  m.attr("__version__") = HANDDB_VERSION;
  m.attr("POINT_SCALE") = kPointScale;
  m.attr("NUM_JOINT_ANGLES") = kNumJointAngles;
  m.attr("NUM_KEYPOINTS") = kNumKeypoints;

  BindError(m);
  BindQueryEdges(m);
  BindView(m);
  BindMatch(m);
  BindDatabase(m);
  BindValidate(m);
}

}  // namespace handdb::python
