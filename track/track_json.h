// A tracked frame as JSON (schemas/track_frame.schema.json): one object per frame, the same for
// `handdb track` and Python's Database.track.
#pragma once

#include <nlohmann/json.hpp>

#include "track/tracker.h"

namespace handdb {

nlohmann::json TrackFrameToJson(const TrackFrame& frame);

}  // namespace handdb
