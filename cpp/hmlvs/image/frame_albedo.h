// The albedo offset of the frame pipeline (hmlvs.image.stripe.albedo_offset): how the laser's
// return follows the laser-off frame, fitted to the column peaks CollectStats found. Internal.
#pragma once

#include <vector>

#include "hmlvs/image/frame_buffers.h"
#include "hmlvs/image/frame_stats.h"

namespace hmlvs::scan {

// The offset a for which the stripe's peak is proportional to off + a (FitAlbedoOffset, with
// the statistics of the frames and the plain difference's noise).
template <typename T>
double FitOffset(const Frames<T>& f, const Stats<T>& st, double noise);

// cv2.getGaussianKernel(n, sigma) in single precision (its sums in double; OpenCV's own are
// in software double precision, which may differ in the last bit).
std::vector<float> GaussianKernel(int n, double sigma);

}  // namespace hmlvs::scan
