// Bright-blob detection: the marker reflections are small blurred bright spots on a darker scene.
// Pixels above a threshold are grouped into 4-connected blobs; a blob of plausible size gets a
// sub-pixel centroid weighted by its intensity above the local background, its flux (the summed
// intensity above background, which tells markers of different brightness apart) and its spread
// (a second moment that tells one spot from two merged ones). Buffers are sized at construction;
// detect() does not allocate.
#pragma once

#include <cstdint>
#include <vector>

#include "mirrorcal/hal/frames.hpp"

namespace mirrorcal::detection {

struct BlobConfig {
  int threshold = 60;  // luma (0-255) above which a pixel belongs to a blob
  int min_area = 2;    // pixels above threshold: fewer is noise or a hot pixel
  int max_area = 400;  // more is a lamp or a window, not a marker
  // The window for the background and the centroid extends the blob's box by this many pixels:
  // enough to hold the spot's tails (about 3 PSF sigmas).
  int margin = 4;
  // Radius of the disc the centroid is refined on (px): the spot's core, about 3 PSF sigmas. A spot
  // smeared by motion is measured once on the capsule of this radius about its smear.
  double centroid_radius = 3.5;
  // A blob whose bright pixels spread more than this (px^2) across their widest extent's
  // perpendicular (Blob::width) is wider than a spot in every direction: a lamp, a window, a lit
  // surface. A focused LED's is about 1 even where it saturates, and motion smears it along one
  // direction only; a soft lens's spots need more.
  double max_width_px2 = 4.0;
};

struct Blob {
  double u = 0.0, v = 0.0;  // intensity-weighted centroid (px, origin at the top-left pixel centre)
  double flux = 0.0;        // summed luma above the local background
  double spread = 0.0;      // largest eigenvalue of the weighted second moment (px^2)
  int area = 0;             // pixels above threshold
  int peak = 0;             // brightest luma
  // Another blob lies within twice the centroid radius (a wide one's tail reaches further): its
  // tail may pull this centroid.
  bool crowded = false;
  // The centroid's disc (a smear's capsule) reaches past the image's edge: the spot is cut, the
  // centroid biased.
  bool truncated = false;
  // The second moment of the pixels above the threshold (weighted by their excess) across their
  // widest extent (px^2, its smaller eigenvalue), and whether it exceeds max_width_px2.
  double width = 0.0;
  bool wide = false;
};

// A blob that may hold two spots (spread beyond max_spread_px2), whose centroid a neighbour's tail
// can pull, whose spot the image's edge cuts, or that is wider than a spot is no marker's to
// measure: a frame without it costs less than a biased or swapped position.
inline bool single_spot(const Blob& b, double max_spread_px2) {
  return !b.crowded && !b.truncated && !b.wide && b.spread <= max_spread_px2;
}

struct BlobCounters {
  std::uint64_t frames = 0;
  std::uint64_t blobs = 0;
  std::uint64_t too_small = 0;
  std::uint64_t too_large = 0;  // includes blobs cut off by the edge of the fill
  std::uint64_t overflow = 0;   // blobs beyond the caller's capacity
};

class BlobDetector {
 public:
  BlobDetector(const BlobConfig& config, int max_width, int max_height);

  // Finds the blobs of a frame, in scan order (top to bottom); returns how many were written to
  // out (at most capacity), each flagged if crowded. A frame larger than the size given at
  // construction yields none.
  int detect(const hal::FrameView& frame, Blob* out, int capacity);

  const BlobConfig& config() const { return config_; }
  const BlobCounters& counters() const { return counters_; }

 private:
  // The segment a spot's bright pixels span along their longest axis, from (u0, v0) to (u1, v1):
  // the path it took over the exposure, and its core's reach at each end. Still: no longer than
  // the spot is wide.
  struct Smear {
    double u0 = 0.0, v0 = 0.0, u1 = 0.0, v1 = 0.0;
    bool still = true;
    // The squared distance of the pixel (u, v) from the segment.
    double distance2(double u, double v) const;
  };
  // A connected region of bright pixels: its area, brightest luma, bounding box, width and smear.
  struct Region {
    int area, peak, x0, y0, x1, y1;
    double width;
    Smear smear;
  };
  Region fill(const hal::FrameView& f, int x, int y);
  Smear smear_of(int w, int area, double cu, double cv, double du, double dv) const;
  bool measure(const hal::FrameView& f, const Region& region, Blob& b) const;

  BlobConfig config_;
  int max_width_, max_height_;
  std::vector<std::uint8_t> visited_;  // one flag per pixel
  std::vector<std::int32_t> queue_;    // flood-fill work list (pixel indices), then the region
  BlobCounters counters_{};
};

}  // namespace mirrorcal::detection
