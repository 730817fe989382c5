// The per-scan-line work of the stripe extraction, shared by ExtractStripe, AssessStripe and
// RefineStripeCentres (image.cpp, on whole images) and StripeFromFrames (frames.cpp, on
// images computed only where a scan line reads them). Internal: not part of the library's
// interface.
//
// A "view" is anything with the members of ScanView: n_scan and n_prof, at(s, p) (the value
// of scan line s at profile coordinate p), clamped(s, p) (the same with both clamped to the
// image), Pixel (its pixel type) and Deriv (Steger's smoothed derivatives at (s, p)).
//
// scan_view.h: the view, Steger's kernels, runs; scan_centres.h: one scan line's peaks and
// centre (ScanLine); scan_checks.h: its quality checks (AssessLine) and refinement
// (RefineLine); difference_rule.h: the difference image's value at a pixel.
#pragma once

#include "hmlvs/image/difference_rule.h"
#include "hmlvs/image/scan_centres.h"
#include "hmlvs/image/scan_checks.h"
#include "hmlvs/image/scan_view.h"
