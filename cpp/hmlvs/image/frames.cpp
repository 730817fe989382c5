// StripeFromFrames: the session pipeline's stripe of one frame (see frames.h).
//
// The frames are worked on with scan lines as columns and rows contiguous (a kRows stripe is
// transposed first). One pass over the rows gathers what needs every pixel, in the pixel type:
// the laser-off frame's mean, histograms (the plain difference's noise, the normalised
// difference's noise and maximum, the gain's percentile), the column peaks the albedo fit
// starts from, and per row and 16 columns the largest plain difference and the smallest
// laser-off value. From those, a bound on the normalised difference (and on its smoothing along
// the stripe) per 16 columns of a row decides where a value could clear a threshold; only
// there, and where a scan line's peak, centre, refinement or check reads, are values computed,
// each once per call (Plane).
//
// Here the pipeline (PairStripe, the laser-on frame alone, DropJumps); its parts in
// frame_buffers.h (planes, marks, runs, the thread's workspace), frame_stats (the pass over
// every pixel), frame_albedo (the albedo offset's fit), frame_views.h (the difference and its
// smoothing where read), frame_detect (runs and scan lines), frame_refine with refine_batch.h
// (the refinement, four scan lines at a time) and frame_background (the opening, whose rows a
// laser-on frame alone gathers its statistics from as they come out).
#include "hmlvs/image/frames.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <utility>
#include <vector>

#include "hmlvs/image/frame_albedo.h"
#include "hmlvs/image/frame_background.h"
#include "hmlvs/image/frame_buffers.h"
#include "hmlvs/image/frame_detect.h"
#include "hmlvs/image/frame_refine.h"
#include "hmlvs/image/frame_stats.h"
#include "hmlvs/image/frame_views.h"
#include "hmlvs/image/scan_lines.h"

namespace hmlvs {

namespace {

using scan::AssessLine;
using scan::CollectStats;
using scan::Detector;
using scan::DetectRuns;
using scan::DifferenceRule;
using scan::DifferenceStats;
using scan::DView;
using scan::FitOffset;
using scan::Frames;
using scan::Kernels;
using scan::kNaN;
using scan::kSb;
using scan::MakeKernels;
using scan::NoiseFromHistogram;
using scan::OpenColumns;
using scan::Percentile;
using scan::RequireImage;
using scan::RequireSameSize;
using scan::ScanLines;
using scan::ScanView;
using scan::Stats;
using scan::StatsCollector;
using scan::SView;
using scan::ThreadWorkspace;
using scan::ValidateOptions;
using scan::ValidateQualityOptions;
using scan::WeightedCentres;
using scan::Working;
using scan::Workspace;

// The thresholds of a normalised difference (session._normalized_threshold): 5 x the plain
// difference's noise x the 95th percentile of the gain over the laser-off frame's every 4th
// row and column, lowered by the smoothing's gain for `along` > 0, and at least 0.15 x the
// difference's maximum over every 4th row.
template <typename T>
double NormalisedThreshold(const Stats<T>& st, double offset, double noise, double d_max,
                           double along) {
  const double mean = st.off_mean;
  const double floor = std::max(1.0, 0.1 * mean);
  // the gain falls with the laser-off value: its k-th smallest value is that of the k-th
  // largest laser-off value
  auto kth = [&](std::uint64_t k) {
    std::uint64_t want = st.off_n - 1 - k, cum = 0;
    size_t y = 0;
    for (; y < st.off_hist.size(); ++y) {
      cum += st.off_hist[y];
      if (cum > want) break;
    }
    return (mean + offset) / std::max(static_cast<double>(y) + offset, floor);
  };
  const double p95 = Percentile(st.off_n, 0.95, kth);
  const double noise_term = 5.0 * noise * p95;
  const double top = 0.15 * d_max;
  return std::max(noise_term * (along > 0.0 ? SmoothingNoiseGain(along) : 1.0), top);
}

// Steger's scale for a stripe of FWHM `width` px (the pipeline's rule: half of it, 3-20 px;
// 3 px when no width was measured).
double StegerSigmaOfWidth(double width) {
  return std::isnan(width) ? 3.0 : std::clamp(0.5 * width, 3.0, 20.0);
}

// The median of the widths of the found scan lines of `res`; NaN when none was found.
double MedianFoundWidth(const StripeResult& res) {
  std::vector<double> w;
  for (int s = 0; s < res.status.size(); ++s) {
    if (res.status[s] == static_cast<std::uint8_t>(StripeStatus::kFound)) w.push_back(res.width[s]);
  }
  if (w.empty()) return kNaN;
  const size_t h = w.size() / 2;
  std::nth_element(w.begin(), w.begin() + static_cast<std::ptrdiff_t>(h), w.end());
  if (w.size() % 2 == 1) return w[h];
  return (*std::max_element(w.begin(), w.begin() + static_cast<std::ptrdiff_t>(h)) + w[h]) / 2.0;
}

// The stripe of a pair of frames in the working orientation. Its steps, in order: the
// statistics and the albedo normalisation (Normalise), the options of the two extraction
// passes -- the first, on the unsmoothed difference, only to size Steger's scale -- and their
// thresholds (Options), the runs of both (DetectRuns), the centres (Extract), the check for a
// threshold above every pixel (NoPixel), the refinement and the quality checks (Assess).
template <typename T>
class PairStripe {
 public:
  PairStripe(const Frames<T>& f, const FrameStripeOptions& o)
      : f_(f), o_(o), ws_(ThreadWorkspace()) {}

  // the statistics of the frames, for a caller that gathers them (StatsCollector) before Run
  Stats<T>* stats() { return &st_; }

  // `alone`: a laser-on frame alone against its estimated background (AloneStripe), whose
  // statistics were gathered into stats() and whose scan lines with a centre that jumps from
  // its neighbours' are dropped (DropJumps, on Steger's centres) before the refinement (which
  // then skips them; the caller drops jumps again on the refined centres)
  FrameStripe Run(bool alone = false) {
    if (!alone) CollectStats(f_, &st_);
    plain_noise_ = NoiseFromHistogram(st_.diff_hist, st_.diff_n);
    Normalise();
    DifferenceOptions dopt;
    dopt.normalize = normalize_;
    dopt.offset = normalize_ ? offset_ : 0.0;
    rule_ = DifferenceRule<T>(dopt, st_.off_mean);
    DifferenceStats(f_, st_, rule_, &d_noise_, &d_max_);
    d_ = std::make_unique<DView<T>>(f_, rule_);
    Options();
    Detect();
    if (weighted_) StegerScale();
    StripeResult& res = out_.stripe;
    Extract(second_, &res, o_.residual);
    if (automatic_ && !(res.status.array() == 0).any() && NoPixel()) return std::move(out_);
    if (alone) DropJumps(&res);
    if (weighted_) {
      const double along =
          second_.steger_sigma_along > 0.0 ? second_.steger_sigma_along : second_.steger_sigma;
      out_.refined = WeightedCentres(f_, normalize_, offset_, st_.off_mean, plain_noise_, along,
                                     o_.blur_var, &res);
    }
    if (o_.assess) Assess();
    return std::move(out_);
  }

 private:
  // whether the difference is normalised, and the albedo offset (fitted or given)
  void Normalise() {
    normalize_ = o_.normalize;
    offset_ = 0.0;
    if (!normalize_) return;
    if (std::isnan(o_.albedo_offset)) {
      const double albedo_noise =
          f_.transposed ? NoiseFromHistogram(st_.albedo_hist, st_.albedo_n) : plain_noise_;
      out_.albedo_offset = FitOffset(f_, st_, albedo_noise);
      out_.offset_fitted = true;
      offset_ = std::isnan(out_.albedo_offset) ? 0.0 : out_.albedo_offset;
    } else {
      offset_ = o_.albedo_offset;
    }
    normalize_ = !std::isinf(offset_);
  }
  // the options of both passes, with their thresholds
  void Options() {
    second_ = o_.stripe;
    second_.direction = StripeDirection::kColumns;
    first_ = second_;
    automatic_ = second_.threshold < 0.0;
    if (normalize_ && automatic_) {
      // peaks found on the difference smoothed along the stripe, with a noise-aware threshold
      // (normalising raises the noise on dark squares); the width estimate's pass on the image
      if (!o_.detect_sigma_along_given) {
        second_.detect_sigma_along = FrameStripeOptions::kDetectAlong;
      }
      second_.threshold =
          NormalisedThreshold(st_, offset_, plain_noise_, d_max_, second_.detect_sigma_along);
      first_.threshold = NormalisedThreshold(st_, offset_, plain_noise_, d_max_, 0.0);
      first_.detect_sigma_along = 0.0;
    }
    weighted_ = !o_.method_given;
    if (weighted_) first_.method = StripeMethod::kCentroid;
    ValidateOptions(second_);
    ValidateOptions(first_);
    need_first_ = weighted_ && !o_.steger_sigma_given;
    for (StripeOptions* p : {&first_, &second_}) {
      if (p->detect_sigma_along > 0.0 && !smooth_kernel_) {
        smooth_kernel_ = std::make_unique<Kernels>(MakeKernels(p->detect_sigma_along));
        smooth_ = std::make_unique<SView<T>>(*d_, *smooth_kernel_, &ws_.a);
      }
    }
    // noise and automatic thresholds as ExtractStripe takes them
    for (StripeOptions* p : {&first_, &second_}) {
      p->threshold = AutoThreshold(*p, p->noise >= 0.0 ? p->noise : d_noise_);
    }
  }
  double AutoThreshold(const StripeOptions& p, double noise) const {
    if (p.threshold >= 0.0) return p.threshold;
    double mx = d_max_, gain = 1.0;
    if (p.detect_sigma_along > 0.0) {
      // every 4th value of the smoothed image in memory order (ExtractStripe's rule)
      gain = std::sqrt(smooth_kernel_->sum_sq0);
      mx = 0.0;
      const size_t total = static_cast<size_t>(d_->n_prof) * d_->n_scan;
      for (size_t i = 0; i < total; i += 4) {
        const int pp = static_cast<int>(i / d_->n_scan), ss = static_cast<int>(i % d_->n_scan);
        mx = std::max(mx, static_cast<double>(smooth_->Value(ss, pp)));
      }
    }
    return std::max(5.0 * noise * gain, 0.15 * mx);
  }
  // the runs of the passes (which share a detection image only with the same threshold: the
  // first pass is the second's copy unless it alone is on the unsmoothed image)
  void Detect() {
    Detector& det_plain = ws_.detectors[0];
    Detector& det_smooth = ws_.detectors[1];
    det_plain.threshold = det_smooth.threshold = -1.0;
    for (StripeOptions* p : {&first_, &second_}) {
      if (p == &first_ && !need_first_) continue;
      Detector& det = p->detect_sigma_along > 0.0 ? det_smooth : det_plain;
      det.threshold = p->threshold;
    }
    DetectRuns(st_, rule_, *d_, smooth_.get(), det_plain.threshold >= 0.0 ? &det_plain : nullptr,
               det_smooth.threshold >= 0.0 ? &det_smooth : nullptr);
  }
  void Extract(const StripeOptions& p, StripeResult* res, bool residual = true) const {
    res->threshold = p.threshold;
    res->noise = p.noise >= 0.0 ? p.noise : d_noise_;
    if (p.detect_sigma_along > 0.0) {
      ScanLines(*d_, *smooth_, ws_.detectors[1].runs, p, res, residual);
    } else {
      ScanLines(*d_, *d_, ws_.detectors[0].runs, p, res, residual);
    }
  }
  // the second pass by Steger's method, at half the median FWHM of the first pass's found
  // scan lines (at least 3 px) unless given
  void StegerScale() {
    second_.method = StripeMethod::kSteger;
    if (need_first_) {
      StripeResult r1;
      Extract(first_, &r1, false);  // only its found widths are read
      second_.steger_sigma = StegerSigmaOfWidth(MedianFoundWidth(r1));
    }
    if (!o_.steger_sigma_along_given && o_.smooth_along != 1.0) {
      second_.steger_sigma_along = std::min(o_.smooth_along * second_.steger_sigma, 40.0);
    }
    ValidateOptions(second_);
  }
  // whether the automatic threshold lies at or above the image's maximum (taken over the
  // blocks whose bound could hold it)
  bool NoPixel() {
    double mx = 0.0;
    for (int r = 0; r < f_.rows; ++r) {
      for (int b = 0; b < st_.blocks; ++b) {
        const size_t k = static_cast<size_t>(r) * st_.blocks + b;
        if (rule_.Bound(st_.max_diff[k], st_.min_off[k]) <= mx) continue;
        for (int c = b * kSb; c < std::min(f_.cols, (b + 1) * kSb); ++c) {
          mx = std::max(mx, d_->at(c, r));
        }
      }
    }
    if (out_.stripe.threshold < mx) return false;
    out_.no_pixel = true;
    out_.image_max = mx;
    return true;
  }
  void Assess() {
    StripeResult& res = out_.stripe;
    StripeQualityOptions q;
    q.albedo_step = std::isnan(o_.albedo_step) ? (normalize_ ? 0.0 : 1.5) : o_.albedo_step;
    q.albedo_offset = normalize_ ? std::max(offset_, 0.0) : 0.0;
    ValidateQualityOptions(q);
    const ScanView<T> von{f_.on, f_.cols, f_.rows, 1, f_.on_rs};
    const ScanView<T> voff{f_.off, f_.cols, f_.rows, 1, f_.off_rs};
    const bool with_off = q.albedo_step > 1.0;
    std::vector<double> y;
    for (int s = 0; s < res.status.size(); ++s) {
      if (res.status[s] != static_cast<std::uint8_t>(StripeStatus::kFound)) continue;
      res.status[s] = static_cast<std::uint8_t>(AssessLine(
          *d_, von, voff, with_off, q, s, res.centre[s], res.width[s], res.threshold, &y));
    }
  }

  const Frames<T>& f_;
  const FrameStripeOptions& o_;
  Workspace& ws_;
  FrameStripe out_;
  Stats<T> st_;
  double plain_noise_ = 0.0, offset_ = 0.0, d_noise_ = 0.0, d_max_ = 0.0;
  bool normalize_ = false, automatic_ = false, weighted_ = false, need_first_ = false;
  DifferenceRule<T> rule_;
  std::unique_ptr<DView<T>> d_;
  StripeOptions first_, second_;
  std::unique_ptr<Kernels> smooth_kernel_;
  std::unique_ptr<SView<T>> smooth_;
};

// Throws std::invalid_argument for empty or mismatched frames, invalid options, or a laser-on
// frame alone with a stripe along the rows.
template <typename T>
void CheckFrames(const ImageView<T>& on, const ImageView<T>& off, const FrameStripeOptions& o) {
  RequireImage(on, "the laser-on image");
  const bool alone = off.data == nullptr;
  if (!alone) {
    RequireImage(off, "the laser-off image");
    RequireSameSize(on, off);
  }
  ValidateOptions(o.stripe);
  if (!(o.smooth_along >= 1.0 && o.smooth_along <= 10.0) ||
      !(o.blur_var >= 0.0 && std::isfinite(o.blur_var))) {
    std::ostringstream msg;
    msg << "smooth_along must lie in [1, 10] and blur_var be a finite number >= 0, got "
        << o.smooth_along << " and " << o.blur_var;
    throw std::invalid_argument(msg.str());
  }
}

// ExtractStripe(image, o) with centroid centres along image columns: the widths of its found
// scan lines, for their median.
template <typename T>
StripeResult FoundWidths(const ImageView<T>& image, StripeOptions o) {
  o.direction = StripeDirection::kColumns;
  o.method = StripeMethod::kCentroid;
  o.detect_sigma_along = 0.0;
  return ExtractStripe(image, o);
}

// The first measure of the stripe's width on a laser-on frame `f` alone, to size the opening
// that estimates its background: the median FWHM of the scan lines ExtractStripe finds
// (centroid centres; the options' dominance, widths, threshold and noise) on the plain
// difference of every k-th column of the frame (at most kAloneFirstColumns of them) and its
// opening at a generous stripe width, kAloneFirstWidth (the opening works column by column:
// that of the columns taken alone). NaN when none is found.
template <typename T>
double FirstWidth(const Frames<T>& f, const StripeOptions& o) {
  const int rows = f.rows, cols = f.cols;
  const int step =
      (cols + FrameStripeOptions::kAloneFirstColumns - 1) / FrameStripeOptions::kAloneFirstColumns;
  const int n = (cols + step - 1) / step;
  const size_t size = static_cast<size_t>(rows) * n;
  Workspace& ws = ThreadWorkspace();
  T* on = ws.Of<T>().sample[0].Get(size);
  T* d = ws.Of<T>().sample[1].Get(size);
  for (int r = 0; r < rows; ++r) {
    const T* a = f.on + r * f.on_rs;
    T* to = on + static_cast<size_t>(r) * n;
    for (int j = 0; j < n; ++j) to[j] = a[static_cast<std::ptrdiff_t>(j) * step];
  }
  EstimateBackground(ImageView<T>{on, rows, n, n, 1}, FrameStripeOptions::kAloneFirstWidth, d);
  // the opening lies at or below the frame: the plain difference, in place of the opening
  for (size_t i = 0; i < size; ++i) d[i] = static_cast<T>(std::max(on[i], d[i]) - d[i]);
  return MedianFoundWidth(FoundWidths(ImageView<T>{d, rows, n, n, 1}, o));
}

// The laser-on frame of `f` alone: against its background (`f->off`), estimated at the
// stripe's width as first measured (FirstWidth; kAloneFirstWidth when none was found); copied
// to `background` if not null, in the image's layout (a kRows stripe's frame is worked on
// transposed, its scan lines as columns, so that the opening removes the stripe).
template <typename T>
FrameStripe AloneStripe(Frames<T>* f, const FrameStripeOptions& o, T* background) {
  FrameStripeOptions oa = o;
  if (!o.dominance_given) oa.stripe.dominance = FrameStripeOptions::kAloneDominance;
  const size_t n = static_cast<size_t>(f->rows) * f->cols;
  T* bg = ThreadWorkspace().Of<T>().background.Get(n);
  const ImageView<T> on_w{f->on, f->rows, f->cols, f->on_rs, 1};
  const double width = FirstWidth(*f, oa.stripe);
  if (!o.method_given && !o.steger_sigma_given) {
    oa.stripe.steger_sigma = StegerSigmaOfWidth(width);  // from the same width
    oa.steger_sigma_given = true;
  }
  f->off = bg;
  f->off_rs = f->cols;
  // the statistics gathered as the background's rows come out of the opening
  PairStripe<T> pass(*f, oa);
  {
    StatsCollector<T> stats(*f, pass.stats());
    OpenColumns(on_w, std::isnan(width) ? FrameStripeOptions::kAloneFirstWidth : width, bg,
                [&stats](int r0, int r1) { stats.Rows(r0, r1); });
    stats.Finish();
  }
  FrameStripe out = pass.Run(true);
  if (out.no_pixel) return out;
  out.offset_fitted = false;
  out.albedo_offset = kNaN;
  DropJumps(&out.stripe);  // again on the refined centres
  if (background != nullptr) {
    if (!f->transposed) {
      std::copy(bg, bg + n, background);
    } else {  // back to the image's layout: its rows are the working frame's columns
      for (int r = 0; r < f->rows; ++r) {
        for (int c = 0; c < f->cols; ++c) {
          background[static_cast<size_t>(c) * f->rows + r] =
              bg[static_cast<size_t>(r) * f->cols + c];
        }
      }
    }
  }
  return out;
}

// The median of each window of `size` (odd) values of c around each value, ends repeated
// (scipy.ndimage.median_filter, mode "nearest").
std::vector<double> WindowMedians(const std::vector<double>& c, int size) {
  const int n = static_cast<int>(c.size()), half = size / 2;
  std::vector<double> out(c.size()), win(static_cast<size_t>(size));
  for (int i = 0; i < n; ++i) {
    for (int k = -half; k <= half; ++k) win[k + half] = c[std::clamp(i + k, 0, n - 1)];
    std::nth_element(win.begin(), win.begin() + half, win.end());
    out[i] = win[half];
  }
  return out;
}

// WindowMedians of values without NaN, the window kept sorted as it slides (one value out,
// one in): the same medians.
std::vector<double> RunningMedian(const std::vector<double>& c, int size) {
  const int n = static_cast<int>(c.size()), half = size / 2;
  auto at = [&](int i) { return c[std::clamp(i, 0, n - 1)]; };
  std::vector<double> out(c.size()), win;
  for (int k = -half; k <= half; ++k) win.push_back(at(k));
  std::sort(win.begin(), win.end());
  for (int i = 0; i < n; ++i) {
    if (i > 0) {
      win.erase(std::lower_bound(win.begin(), win.end(), at(i - 1 - half)));
      const double in = at(i + half);
      win.insert(std::upper_bound(win.begin(), win.end(), in), in);
    }
    out[i] = win[half];
  }
  return out;
}

}  // namespace

template <typename T>
FrameStripe StripeFromFrames(const ImageView<T>& on, const ImageView<T>& off,
                             const FrameStripeOptions& o, T* background) {
  const bool alone = off.data == nullptr;
  CheckFrames(on, off, o);
  const bool transpose = o.stripe.direction == StripeDirection::kRows;
  Workspace& ws = ThreadWorkspace();
  const size_t n = static_cast<size_t>(on.rows) * on.cols;
  T* buffer = ws.Of<T>().frames.Get(2 * n);
  Frames<T> f;
  f.rows = transpose ? on.cols : on.rows;
  f.cols = transpose ? on.rows : on.cols;
  f.transposed = transpose;
  f.on = Working(on, transpose, buffer, &f.on_rs);
  if (alone) return AloneStripe(&f, o, background);
  f.off = Working(off, transpose, buffer + n, &f.off_rs);
  return PairStripe<T>(f, o).Run();
}

void DropJumps(StripeResult* stripe, int window, double jump) {
  std::vector<int> f;
  for (int s = 0; s < stripe->status.size(); ++s) {
    if (stripe->status[s] == static_cast<std::uint8_t>(StripeStatus::kFound)) f.push_back(s);
  }
  const int n = static_cast<int>(f.size());
  if (n < 5) return;
  // scipy.ndimage.median_filter(centres, size, mode="nearest"), size odd
  const int size = std::min(window, n | 1);
  std::vector<double> c(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) c[i] = stripe->centre[f[i]];
  const std::vector<double> median =
      std::all_of(c.begin(), c.end(), [](double x) { return !std::isnan(x); })
          ? RunningMedian(c, size)
          : WindowMedians(c, size);
  for (int i = 0; i < n; ++i) {
    if (std::abs(c[i] - median[i]) > jump) {
      stripe->status[f[i]] = static_cast<std::uint8_t>(StripeStatus::kMultiple);
    }
  }
}

template FrameStripe StripeFromFrames<std::uint8_t>(const ImageView<std::uint8_t>&,
                                                    const ImageView<std::uint8_t>&,
                                                    const FrameStripeOptions&, std::uint8_t*);
template FrameStripe StripeFromFrames<std::uint16_t>(const ImageView<std::uint16_t>&,
                                                     const ImageView<std::uint16_t>&,
                                                     const FrameStripeOptions&, std::uint16_t*);

}  // namespace hmlvs
