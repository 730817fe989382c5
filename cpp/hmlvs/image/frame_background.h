// The opening EstimateBackground computes (frames.h), with a call as its rows are done: the
// statistics of a laser-on frame alone against its background are gathered while the
// background's rows are still in the cache (frames.cpp). Internal.
#pragma once

#include <functional>

#include "hmlvs/image/image.h"

namespace hmlvs::scan {

// EstimateBackground(on, width, out), calling `rows(r0, r1)` (if set) as soon as rows
// r0 .. r1 - 1 of `out` are final, in order.
template <typename T>
void OpenColumns(const ImageView<T>& on, double width, T* out,
                 const std::function<void(int, int)>& rows);

}  // namespace hmlvs::scan
