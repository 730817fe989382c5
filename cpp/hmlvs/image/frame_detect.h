// The runs above a threshold of the difference image and of its smoothing along the stripe,
// streamed over the rows with values computed only where a bound allows (DetectRuns), and
// ExtractStripe's scan lines from them (ScanLines). Internal.
#pragma once

#include "hmlvs/image/difference_rule.h"
#include "hmlvs/image/frame_buffers.h"
#include "hmlvs/image/frame_stats.h"
#include "hmlvs/image/frame_views.h"
#include "hmlvs/image/image.h"

namespace hmlvs::scan {

// Runs of the difference (`plain`) and of its smoothing (`smooth`) above their thresholds;
// either may be null.
template <typename T>
void DetectRuns(const Stats<T>& st, const DifferenceRule<T>& rule, const DView<T>& d,
                const SView<T>* s, Detector* plain, Detector* smooth);

// ExtractStripe's scan lines from their runs: v the difference, dv the detection view; the
// residuals unless `residual` is false (a pass that only sizes the stripe).
template <class V, class DV>
void ScanLines(const V& v, const DV& dv, const Runs& runs, const StripeOptions& o,
               StripeResult* res, bool residual = true);

}  // namespace hmlvs::scan
