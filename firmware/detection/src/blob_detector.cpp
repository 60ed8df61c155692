#include "mirrorcal/detection/blob_detector.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace mirrorcal::detection {

namespace {

// Whether any of a row's w luma bytes (Step bytes apart) is above the threshold: a reduction the
// compiler vectorises, so that the dark rows, most of a frame, cost a few cycles per pixel.
template <int Step>
bool any_above(const std::uint8_t* row, int w, int threshold) {
  std::uint8_t brightest = 0;
  for (int x = 0; x < w; ++x) brightest = std::max(brightest, row[x * Step]);
  return brightest > threshold;
}

// The weighted mean and second moment of pixel offsets (du, dv) from a centre, and the second
// moment's eigenvalues: a blob's extent along its longest and its shortest axis.
struct Moments {
  double ws = 0.0, su = 0.0, sv = 0.0, suu = 0.0, svv = 0.0, suv = 0.0;
  void add(double wgt, double du, double dv) {
    ws += wgt;
    su += wgt * du;
    sv += wgt * dv;
    suu += wgt * du * du;
    svv += wgt * dv * dv;
    suv += wgt * du * dv;
  }
  double mu() const { return su / ws; }
  double mv() const { return sv / ws; }
  double cuu() const { return suu / ws - mu() * mu(); }
  double cvv() const { return svv / ws - mv() * mv(); }
  double cuv() const { return suv / ws - mu() * mv(); }
  // The eigenvalues: half the trace, plus (largest) or less (smallest) the root.
  double largest() const { return 0.5 * (cuu() + cvv()) + root(); }
  double smallest() const { return 0.5 * (cuu() + cvv()) - root(); }
  // The unit direction of the largest axis, (du, dv).
  void axis(double& du, double& dv) const {
    const double a = largest() - cuu(), b = cuv(), n = std::hypot(b, a);
    du = n > 0.0 ? b / n : 1.0;
    dv = n > 0.0 ? a / n : 0.0;
  }

 private:
  double root() const {
    const double d = cuu() - cvv(), c = cuv();
    return std::sqrt(std::max(0.0, 0.25 * d * d + c * c));
  }
};

}  // namespace

double BlobDetector::Smear::distance2(double u, double v) const {
  const double lu = u1 - u0, lv = v1 - v0, l2 = lu * lu + lv * lv;
  const double t = l2 > 0.0 ? std::clamp(((u - u0) * lu + (v - v0) * lv) / l2, 0.0, 1.0) : 0.0;
  const double eu = u - u0 - t * lu, ev = v - v0 - t * lv;
  return eu * eu + ev * ev;
}

BlobDetector::BlobDetector(const BlobConfig& config, int max_width, int max_height)
    : config_(config),
      max_width_(max_width),
      max_height_(max_height),
      visited_(static_cast<std::size_t>(max_width) * static_cast<std::size_t>(max_height)),
      queue_(static_cast<std::size_t>(max_width) * static_cast<std::size_t>(max_height)) {}

int BlobDetector::detect(const hal::FrameView& f, Blob* out, int capacity) {
  ++counters_.frames;
  if (f.width > max_width_ || f.height > max_height_ || f.data == nullptr) return 0;
  const int w = f.width, h = f.height;
  const int step = hal::bytes_per_pixel(f.format);
  const int threshold = config_.threshold;
  std::memset(visited_.data(), 0, static_cast<std::size_t>(w) * static_cast<std::size_t>(h));

  int found = 0;
  for (int y = 0; y < h; ++y) {
    const std::uint8_t* row =
        f.data + static_cast<std::size_t>(y) * static_cast<std::size_t>(f.bytes_per_line);
    if (!(step == 1 ? any_above<1>(row, w, threshold) : any_above<2>(row, w, threshold))) continue;
    for (int x = 0; x < w; ++x) {
      if (row[x * step] <= threshold || visited_[static_cast<std::size_t>(y * w + x)] != 0)
        continue;
      const Region r = fill(f, x, y);
      if (r.area < config_.min_area) {
        ++counters_.too_small;
        continue;
      }
      if (r.area > config_.max_area) {
        ++counters_.too_large;
        continue;
      }
      Blob b;
      b.area = r.area;
      b.peak = r.peak;
      b.width = r.width;
      b.wide = r.width > config_.max_width_px2;
      if (!measure(f, r, b)) {
        ++counters_.too_small;
        continue;
      }
      ++counters_.blobs;
      if (found >= capacity) {
        ++counters_.overflow;
        continue;
      }
      out[found++] = b;
    }
  }
  // A spot's tail reaches the centroid radius; a wide blob's (a lamp's) reaches its bright
  // region's radius and the margin beyond it.
  const auto reach = [this](const Blob& b) {
    return b.wide ? std::sqrt(b.area / M_PI) + config_.margin : config_.centroid_radius;
  };
  for (int i = 0; i < found; ++i)
    for (int j = i + 1; j < found; ++j)
      if (std::hypot(out[i].u - out[j].u, out[i].v - out[j].v) < reach(out[i]) + reach(out[j]))
        out[i].crowded = out[j].crowded = true;
  return found;
}

// Flood fill (4-connected) from the seed (x, y) over the pixels above the threshold, marking them
// visited. The queue holds every pixel at most once, and the region's pixels when done.
BlobDetector::Region BlobDetector::fill(const hal::FrameView& f, int x, int y) {
  const int w = f.width, h = f.height;
  const int step = hal::bytes_per_pixel(f.format);
  const int threshold = config_.threshold;
  const auto luma = [&](int u, int v) {
    return static_cast<int>(
        f.data[static_cast<std::size_t>(v) * static_cast<std::size_t>(f.bytes_per_line) +
               static_cast<std::size_t>(u * step)]);
  };
  int area = 0, queued = 0, peak = 0;
  int x0 = x, x1 = x, y0 = y, y1 = y;
  Moments excess;  // about the seed, each pixel weighted by its excess over the threshold
  queue_[static_cast<std::size_t>(queued++)] = y * w + x;
  visited_[static_cast<std::size_t>(y * w + x)] = 1;
  for (; area < queued; ++area) {
    const int p = queue_[static_cast<std::size_t>(area)];
    const int px = p % w, py = p / w;
    const int value = luma(px, py);
    peak = std::max(peak, value);
    excess.add(value - threshold, px - x, py - y);
    x0 = std::min(x0, px);
    x1 = std::max(x1, px);
    y0 = std::min(y0, py);
    y1 = std::max(y1, py);
    const int nx[4] = {px - 1, px + 1, px, px};
    const int ny[4] = {py, py, py - 1, py + 1};
    for (int k = 0; k < 4; ++k) {
      if (nx[k] < 0 || nx[k] >= w || ny[k] < 0 || ny[k] >= h) continue;
      const auto q = static_cast<std::size_t>(ny[k] * w + nx[k]);
      if (visited_[q] != 0 || luma(nx[k], ny[k]) <= threshold) continue;
      visited_[q] = 1;
      queue_[static_cast<std::size_t>(queued++)] = static_cast<std::int32_t>(q);
    }
  }
  double du = 0.0, dv = 0.0;
  excess.axis(du, dv);
  const Smear smear = smear_of(w, area, x + excess.mu(), y + excess.mv(), du, dv);
  return {area, peak, x0, y0, x1, y1, excess.smallest(), smear};
}

// The extent of the region's pixels (the queue's first `area`) along its longest axis (du, dv)
// through its centre (cu, cv). A still spot's is its width across, give or take a pixel; a smeared
// one's is longer by its path.
BlobDetector::Smear BlobDetector::smear_of(int w, int area, double cu, double cv, double du,
                                           double dv) const {
  double first = 0.0, last = 0.0, half_width = 0.0;
  for (int i = 0; i < area; ++i) {
    const int p = queue_[static_cast<std::size_t>(i)];
    const double ou = p % w - cu, ov = p / w - cv;
    const double along = ou * du + ov * dv;
    first = std::min(first, along);
    last = std::max(last, along);
    half_width = std::max(half_width, std::abs(ov * du - ou * dv));
  }
  return {cu + first * du, cv + first * dv, cu + last * du, cv + last * dv,
          last - first - 2.0 * half_width < 1.0};
}

// Centroid, flux and spread over the blob's box grown by the margin: the background is the mean
// of the window's outer ring, and every pixel weighs by its luma above it (clipped at zero), so
// the spot's tails below the threshold count too and the centroid is not pulled to the pixel grid.
bool BlobDetector::measure(const hal::FrameView& f, const Region& region, Blob& b) const {
  const int margin = config_.margin;
  const int wx0 = std::max(0, region.x0 - margin), wx1 = std::min(f.width - 1, region.x1 + margin);
  const int wy0 = std::max(0, region.y0 - margin), wy1 = std::min(f.height - 1, region.y1 + margin);
  const int step = hal::bytes_per_pixel(f.format);
  const auto luma = [&](int x, int y) {
    return static_cast<double>(
        f.data[static_cast<std::size_t>(y) * static_cast<std::size_t>(f.bytes_per_line) +
               static_cast<std::size_t>(x * step)]);
  };
  double ring = 0.0;
  int ring_n = 0;
  for (int x = wx0; x <= wx1; ++x) {
    ring += luma(x, wy0) + luma(x, wy1);
    ring_n += 2;
  }
  for (int y = wy0 + 1; y < wy1; ++y) {
    ring += luma(wx0, y) + luma(wx1, y);
    ring_n += 2;
  }
  const double background = ring / ring_n;

  // The moments about (cu, cv) of the window's pixels above the background that `counts`.
  const auto moments = [&](double cu, double cv, const auto& counts) {
    Moments mo;
    for (int y = wy0; y <= wy1; ++y)
      for (int x = wx0; x <= wx1; ++x) {
        if (!counts(x, y)) continue;
        const double wgt = luma(x, y) - background;
        if (wgt > 0.0) mo.add(wgt, x - cu, y - cv);
      }
    return mo;
  };
  const double r = config_.centroid_radius, r2 = r * r;
  const auto disc = [r2](double cu, double cv) {
    return [=](int x, int y) { return (x - cu) * (x - cu) + (y - cv) * (y - cv) <= r2; };
  };
  const Smear& smear = region.smear;
  double cu = 0.5 * (region.x0 + region.x1), cv = 0.5 * (region.y0 + region.y1);
  if (smear.still) {
    // First over the whole window, then on a disc re-centred on the estimate: a window symmetric
    // about the estimate makes the clipped noise and the truncated tails pull equally both ways.
    Moments m;
    for (int pass = 0; pass < 4; ++pass) {
      m = pass == 0 ? moments(cu, cv, [](int, int) { return true; })
                    : moments(cu, cv, disc(cu, cv));
      if (!(m.ws > 0.0)) return false;
      cu += m.mu();
      cv += m.mv();
    }
    b.flux = m.ws;
    b.spread = m.largest();
  } else {
    // A smear's centroid is the mean of the spot's place over the exposure, which the model
    // predicts (ExposedMirror): measured over the capsule about its bright pixels' extent, which
    // holds all of it. A disc re-centred on it walked along the smear to its densest piece.
    const Moments m = moments(cu, cv, [&](int x, int y) { return smear.distance2(x, y) <= r2; });
    if (!(m.ws > 0.0)) return false;
    cu += m.mu();
    cv += m.mv();
    b.flux = m.ws;
    // On the disc, as for a still spot: two spots merged spread beyond one, smeared or not.
    b.spread = moments(cu, cv, disc(cu, cv)).largest();
  }
  b.u = cu;
  b.v = cv;
  // The disc (the capsule) reaches past the image's edge: the spot is cut, the centroid biased.
  const bool still = smear.still;
  const double lo_u = (still ? cu : std::min(smear.u0, smear.u1)) - r,
               hi_u = (still ? cu : std::max(smear.u0, smear.u1)) + r,
               lo_v = (still ? cv : std::min(smear.v0, smear.v1)) - r,
               hi_v = (still ? cv : std::max(smear.v0, smear.v1)) + r;
  b.truncated = lo_u < -0.5 || lo_v < -0.5 || hi_u > f.width - 0.5 || hi_v > f.height - 0.5;
  return true;
}

}  // namespace mirrorcal::detection
