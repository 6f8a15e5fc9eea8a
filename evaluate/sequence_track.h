// The tracker (track/tracker.h) scored on test sequences (evaluate/sequence.h): each sequence is
// tracked from its first frame, as `handdb track` tracks a folder of frames.
#pragma once

#include "evaluate/sequence.h"
#include "query/searcher.h"
#include "track/tracker.h"

namespace handdb {

// A frame's prediction is the tracker's answer: found when it has a pose; the 3D keypoints and
// joint angles of the chosen match's fit (the match itself when unfitted); the 2D keypoints as
// the tracker reports them (filtered over time unless smoothing is off). The searcher must
// outlive the predictor.
SequencePredictor MakeTrackerPredictor(const Searcher& searcher, TrackOptions options);

// The prediction of one tracked frame (MakeTrackerPredictor's).
FramePrediction PredictionOfTrackFrame(const TrackFrame& frame);

}  // namespace handdb
