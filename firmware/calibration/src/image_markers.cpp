#include "mirrorcal/calibration/image_markers.hpp"

#include <chrono>

namespace mirrorcal::calibration {

namespace {

// The detection of LEDs named by their tracks' names (none yet: the look that finds them).
template <int M>
detection::DetectionConfig<M> named_detection_config(const io::MarkerLeds& leds,
                                                     const LedNaming* naming) {
  detection::DetectionConfig<M> c = marker_detection_config<M>(leds);
  if (naming == nullptr) return c;
  c.bootstrap_shape = true;
  for (int i = 0; i < M; ++i) {
    c.prior.markers_c[std::size_t(i)] = naming->markers_c[std::size_t(i)];
    if (naming->track_of_label.size() == std::size_t(M))
      c.names_ahead.track_of_label[std::size_t(i)] = naming->track_of_label[std::size_t(i)];
  }
  for (std::size_t k = 0; k < naming->name_spans.size() && k < c.names_ahead.spans.size(); ++k)
    c.names_ahead.spans[k] = naming->name_spans[k];
  c.names_ahead.shaped = naming->shape_c.size() == std::size_t(M);
  for (std::size_t i = 0; i < naming->shape_c.size() && c.names_ahead.shaped; ++i)
    c.names_ahead.shape_c[i] = naming->shape_c[i];
  c.prior.marker_sigma_m = naming->marker_sigma_m;
  c.prior.camera = naming->camera;
  c.prior.pixel_sigma = naming->pixel_sigma;
  return c;
}

}  // namespace

template <int M>
LedNaming name_leds_by_shape(hal::FrameSource& frames, const io::MarkerLeds& leds,
                             const detection::RigGeometry<M>& geometry, int width, int height) {
  LedNaming naming;
  naming.markers_c.assign(geometry.markers_c.begin(), geometry.markers_c.end());
  naming.marker_sigma_m = geometry.marker_sigma_m;
  naming.camera = geometry.camera;
  naming.pixel_sigma = geometry.pixel_sigma;
  detection::DetectingMarkerSource<M> look(frames, named_detection_config<M>(leds, &naming), width,
                                           height);
  MarkerFrame<M> frame;
  while (!look.bootstrap().named() && look.poll(frame) == hal::SourceStatus::kOk) {
  }
  const detection::TrackNames<M>& names = look.bootstrap().names();
  naming.track_of_label.assign(names.track_of_label.begin(), names.track_of_label.end());
  naming.name_spans.assign(names.spans.begin(), names.spans.end());
  const detection::RigShape<M>& shape = look.bootstrap().shape();
  if (shape.made)
    naming.shape_c.assign(shape.geometry.markers_c.begin(), shape.geometry.markers_c.end());
  return naming;
}

template <int M>
ImageMarkers<M>::ImageMarkers(std::unique_ptr<hal::FrameSource> frames, int width, int height,
                              DetectionReport* report, const io::MarkerLeds& leds,
                              ImageBlobs* blobs, const LedNaming* naming)
    : frames_(std::move(frames)),
      detect_(*frames_, named_detection_config<M>(leds, naming), width, height),
      report_(report),
      blobs_(blobs),
      replayed_(blobs != nullptr && blobs->complete() > 0) {
  detect_.replay_with(blobs);
}

template <int M>
ImageMarkers<M>::~ImageMarkers() {
  if (report_ == nullptr || frames_seen_ < report_->frames) return;
  DetectionReport r;
  r.frames = frames_seen_;
  r.markers_labelled = labelled_;
  double detect = detect_.counters().detect_seconds, read = read_seconds_;
  // Reading and detecting as the pass that read the images took them (a replay skips both).
  if (blobs_ != nullptr && !replayed_ && blobs_->complete() > 0) {
    blobs_->read_seconds = read;
    blobs_->detect_seconds = detect;
  } else if (replayed_) {
    read = blobs_->read_seconds;
    detect = blobs_->detect_seconds;
  }
  const double n = frames_seen_ > 0 ? static_cast<double>(frames_seen_) : 1.0;
  r.ms_per_frame = 1e3 * detect / n;
  r.read_ms_per_frame = 1e3 * read / n;
  const detection::IdentifierCounters& id = detect_.identifier_counters();
  r.dropped_in_doubt = id.ambiguous + id.crossing + id.refused;
  r.unlabelled_blobs = id.unassigned;
  *report_ = r;
}

template <int M>
hal::SourceStatus ImageMarkers<M>::poll(MarkerFrame<M>& frame) {
  const double detecting = detect_.counters().detect_seconds;
  const auto t0 = std::chrono::steady_clock::now();
  const hal::SourceStatus st = detect_.poll(frame);
  // The poll's time less detection's share of it: reading the image.
  read_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() -
                   (detect_.counters().detect_seconds - detecting);
  if (st == hal::SourceStatus::kOk) ++frames_seen_;
  return st;
}

template <int M>
void ImageMarkers<M>::relabel(const hal::MarkerPrediction<M>& prediction, MarkerFrame<M>& frame) {
  detect_.relabel(prediction, frame);
  for (const bool seen : frame.seen) labelled_ += seen ? 1 : 0;
}

#define MIRRORCAL_IMAGE_MARKERS_(M)                                                  \
  template class ImageMarkers<M>;                                                    \
  template LedNaming name_leds_by_shape<M>(hal::FrameSource&, const io::MarkerLeds&, \
                                           const detection::RigGeometry<M>&, int, int);
MIRRORCAL_FOR_EACH_MARKER_COUNT(MIRRORCAL_IMAGE_MARKERS_)
#undef MIRRORCAL_IMAGE_MARKERS_

}  // namespace mirrorcal::calibration
