// The refinement of the frame pipeline's centres (session._weighted_centres). Internal.
#pragma once

#include "hmlvs/image/frame_buffers.h"
#include "hmlvs/image/image.h"

namespace hmlvs::scan {

// session._weighted_centres: Steger's found centres of `st` refined (RefineStripeCentres) on
// the difference against the laser-off frame denoised by a bilateral filter (one frame's
// noise: `noise` / sqrt 2), normalised (by the laser-off level plus `offset`, the mean level
// `mean`), corrected at albedo steps (`blur_var`) and smoothed along the stripe at
// `sigma_along`. False when no scan line had a centre to refine.
template <typename T>
bool WeightedCentres(const Frames<T>& f, bool normalize, double offset, double mean, double noise,
                     double sigma_along, double blur_var, StripeResult* st);

}  // namespace hmlvs::scan
