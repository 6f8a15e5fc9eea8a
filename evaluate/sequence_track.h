// The tracker (track/tracker.h) scored on test sequences (evaluate/sequence.h): each sequence is
// tracked from its first frame, as `handdb track` tracks a folder of frames.
#pragma once

#include "evaluate/sequence.h"
#include "query/searcher.h"
#include "track/tracker.h"

namespace handdb {

// A frame's prediction is the tracker's answer: found when it has a pose; its 2D and 3D keypoints
// as the tracker reports them (the chosen match's fit, or the match when unfitted, filtered over
// time unless smoothing is off); the fit's (or the match's) joint angles. The searcher must
// outlive the predictor.
SequencePredictor MakeTrackerPredictor(const Searcher& searcher, TrackOptions options);

// The prediction of one tracked frame (MakeTrackerPredictor's).
FramePrediction PredictionOfTrackFrame(const TrackFrame& frame);

}  // namespace handdb
