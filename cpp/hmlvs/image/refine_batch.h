// RefineLine on several scan lines at once (WeightedCentres, frame_refine.cpp): the same
// operations lane by lane in vector registers, so the same values as one line at a time.
// Internal.
#pragma once

#include <algorithm>
#include <cstddef>
#include <utility>
#include <vector>

#include "hmlvs/image/frame_buffers.h"
#include "hmlvs/image/image.h"
#include "hmlvs/image/scan_checks.h"

namespace hmlvs::scan {

// Scan line s of a view read once over rows [first, last] (those RefineLine reads unless its
// centre wanders off), the view itself beyond: the same values, each looked up once.
template <class V>
class LineWindow {
 public:
  using Pixel = float;
  LineWindow() = default;
  LineWindow(const V& v, int s, std::pair<int, int> rows, std::vector<double>* buffer)
      : n_scan(v.n_scan),
        n_prof(v.n_prof),
        v_(&v),
        first_(std::max(rows.first, 0)),
        last_(std::min(rows.second, v.n_prof - 1)) {
    buffer->resize(static_cast<size_t>(std::max(0, last_ - first_ + 1)));
    for (int p = first_; p <= last_; ++p) (*buffer)[static_cast<size_t>(p - first_)] = v.at(s, p);
    values_ = buffer->data();
  }
  double at(int s, int p) const {
    return p >= first_ && p <= last_ ? values_[p - first_] : v_->at(s, p);
  }
  int n_scan = 0, n_prof = 0;

 private:
  const V* v_ = nullptr;
  int first_ = 0, last_ = -1;
  const double* values_ = nullptr;
};

// Up to kLanes scan lines refined together: Add each (its LineWindow), Flush at the end.
// Each lane runs RefineLine's iterations; the sums over a window run in vector registers,
// one lane per scan line, with RefineLine's operations in its order.
template <class V>
class RefineLines {
 public:
  static constexpr int kLanes = 4;
  RefineLines(const V& image, const StripeRefineOptions& o, StripeResult* res)
      : image_(image), o_(o), res_(res) {}

  // scan line s with additive noise `noise`, read over rows `rows` (RefineLine's window)
  void Add(int s, double noise, std::pair<int, int> rows) {
    Lane& lane = lanes_[n_];
    lane.s = s;
    lane.view = LineWindow<V>(image_, s, rows, &buffers_[n_]);
    lane.state = RefineState();
    if (!RefineStart(lane.view, s, noise, o_, res_, &lane.state)) return;
    if (++n_ == kLanes) Flush();
  }
  void Flush() {
    Run();
    for (int k = 0; k < n_; ++k) RefineFinish(lanes_[k].state, lanes_[k].s, res_);
    n_ = 0;
  }

 private:
  struct Lane {
    int s = 0;
    LineWindow<V> view;
    RefineState state;
    bool active = false;
    int m = 0;
    double g = 0.0, ratio = 0.0;
  };
  void Run();
  void Sums();

  const V& image_;
  const StripeRefineOptions& o_;
  StripeResult* res_;
  std::vector<double> buffers_[kLanes];
  Lane lanes_[kLanes];
  int n_ = 0;
};

// The lanes' vectors (GCC's vector extension: four doubles, two SSE2 registers or one AVX
// register, each lane's operations IEEE's)
typedef double RefineVector __attribute__((vector_size(32)));
typedef long long RefineMask __attribute__((vector_size(32)));

// The sums of RefineLine's window of each active lane, its pixels in vector registers
template <class Lane>
__attribute__((always_inline)) inline void RefineSums(Lane* lanes, int n) {
  constexpr int kLanes = 4;
  RefineVector c, g, ratio, shrink, inv_s2, a2, k2, base;
  int len[kLanes], first[kLanes];
  for (int k = 0; k < kLanes; ++k) {
    const bool on = k < n && lanes[k].active;
    const RefineState& st = lanes[k].state;
    c[k] = on ? st.c : 0.0;  // idle lanes: harmless values, their sums unused
    g[k] = on ? lanes[k].g : 0.0;
    ratio[k] = on ? lanes[k].ratio : 0.0;
    shrink[k] = on ? st.shrink : 0.0;
    inv_s2[k] = on ? st.inv_s2 : 1.0;
    a2[k] = on ? st.a2 : 1.0;
    k2[k] = on ? st.k2 : 0.0;
    first[k] = on ? lanes[k].m - st.hw : 0;
    base[k] = static_cast<double>(first[k]);
    len[k] = on ? 2 * st.hw + 1 : 0;
  }
  const int steps = *std::max_element(len, len + kLanes);
  RefineVector f = {0.0, 0.0, 0.0, 0.0}, df = f, var = f;
  for (int j = 0; j < steps; ++j, g *= ratio, ratio *= shrink) {
    RefineVector y;
    RefineMask in;
    for (int k = 0; k < kLanes; ++k) {
      in[k] = j < len[k] ? -1 : 0;
      y[k] = j < len[k] ? lanes[k].view.at(lanes[k].s, first[k] + j) : 0.0;
    }
    const RefineVector x = (base + static_cast<double>(j)) - c;
    RefineVector w, dw, den;
    ProfileWeight(x, g, inv_s2, a2, k2, &w, &dw, &den);
    f = in ? f + w * y : f;
    df = in ? df - dw * y : df;  // d/dc of w(p - c) y
    var = in ? var + w * w * den : var;
  }
  for (int k = 0; k < n; ++k) {
    if (!lanes[k].active) continue;
    lanes[k].state.f_sum = f[k];
    lanes[k].state.df_sum = df[k];
    lanes[k].state.var_sum = var[k];
  }
}

#if defined(HMLVS_AVX2)
template <class Lane>
__attribute__((target("avx2"))) void RefineSumsAvx2(Lane* lanes, int n) {
  RefineSums(lanes, n);
}
#endif

template <class V>
void RefineLines<V>::Sums() {
#if defined(HMLVS_AVX2)
  if (UseAvx2()) {
    RefineSumsAvx2(lanes_, n_);
    return;
  }
#endif
  RefineSums(lanes_, n_);
}

// RefineLine's iterations, the lanes in step: a lane leaves when its own loop would end
template <class V>
void RefineLines<V>::Run() {
  for (int k = 0; k < n_; ++k) lanes_[k].active = true;
  for (int it = 0; it < o_.max_iterations; ++it) {
    bool any = false;
    for (int k = 0; k < n_; ++k) {
      Lane& l = lanes_[k];
      if (l.active && !RefineWindow(l.state, image_.n_prof, &l.m, &l.g, &l.ratio)) {
        l.active = false;
      }
      any = any || l.active;
    }
    if (!any) return;
    Sums();
    for (int k = 0; k < n_; ++k) {
      Lane& l = lanes_[k];
      if (l.active && !RefineStep(&l.state, o_)) l.active = false;
    }
  }
}

}  // namespace hmlvs::scan
