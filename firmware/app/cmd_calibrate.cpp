// mirrorcal calibrate: the deterministic loop on a EuRoC recording, with Kalibr output.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>

#include "build_tools.hpp"
#include "cli.hpp"
#include "mirrorcal/calibration/recording_run.hpp"
#include "mirrorcal/calibration/report.hpp"
#include "mirrorcal/calibration/statistics.hpp"
#include "mirrorcal/io/bags.hpp"
#include "mirrorcal/io/recording.hpp"

namespace mirrorcal::app {

using namespace calibration;

namespace {

// A bag as a recording, in a build that reads bags (MIRRORCAL_BAGS: the host's).
bool open_bag(const std::string& path, const io::BagOptions& options, int markers,
              io::Recording& out, std::string& error) {
#ifdef MIRRORCAL_BAGS
  return io::open_bag_recording(path, options, markers, out, error);
#else
  (void)options, (void)markers, (void)out;
  error = path +
          ": a ROS bag; this build of mirrorcal (a board's) reads recording folders only, which "
          "record writes. Calibrate the bag with the host's build (docs/usage.md)";
  return false;
#endif
}

template <int M, int NK, int NI = 0>
int calibrate(const io::Recording& rec, const std::string& in, const std::string& out,
              const io::CalibrationStart* from, const Passes& passes, bool plots) {
  if constexpr (NI > 0)
    std::printf("mirrorcal calibrate: the IMU's intrinsics estimated too (model %s)\n",
                to_string(imu_model_of_dim(NI)));
  std::printf("mirrorcal calibrate: %s: %zu IMU samples (%.0f Hz), %zu frames, %s\n", in.c_str(),
              std::size_t(rec.stats.imu_samples), rec.sensors.imu_rate_hz,
              std::size_t(rec.stats.frames),
              NK == 8   ? "camera intrinsics and the lens's distortion coefficients estimated too, "
                          "skew held at camchain.yaml's"
              : NK == 5 ? "camera intrinsics estimated too"
              : NK == 4 ? "camera intrinsics estimated too, skew held at camchain.yaml's"
                        : "camera intrinsics from camchain.yaml");
  const std::uint64_t burn_in = recording_config(rec).gate_after_frames;
  if (rec.stats.frames < burn_in)
    std::fprintf(stderr,
                 "mirrorcal: note: only %zu frames; the filter gates markers only after %llu, and "
                 "the calibration will hardly have converged\n",
                 std::size_t(rec.stats.frames), static_cast<unsigned long long>(burn_in));
  std::string err;
  CalibrationRun<M, NK, NI> run;
  const auto t0 = std::chrono::steady_clock::now();
  if (!calibrate_recording<M, NK, NI>(
          rec, run, err, [](double f) { print_progress("calibrating", f); }, from, passes))
    return refuse(err, 1);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  end_progress("calibrating done");

  const CalibrationResult& r = run.result;
  const auto& first = run.first_frame;
  const auto& last = run.history.back();
  const Eigen::Vector3d angles = display_angles(r.q_b_c);
  const Eigen::Vector3d angles_first = display_angles(first.state.q_b_c);
  std::printf("\n%-17s %-5s %20s %20s%s\n", "param", "unit", "after 1st frame +-1s",
              "final +-1sigma", rec.has_truth ? "  error/sig (truth.yaml)" : "");
  constexpr CalibrationLayout kLayout = CalibrationRun<M, NK, NI>::State::kCalibration;
  for (std::size_t j = 0; j < r.params.size(); ++j) {
    const ParamInfo& p = r.params[j];
    const int i = int(j) - kLayout[p.group].begin;  // within its group
    // Rotations are shown as the final estimate's angles (Rz Ry Rx, as the scenarios state them);
    // their sigma is of the rotation error vector's components.
    double value = 0.0, value_first = 0.0;
    if (p.group == CalibrationGroup::kCameraPosition) {
      value = r.p_b_c(i) * p.scale;
      value_first = double(first.state.p_b_c(i)) * p.scale;
    } else if (p.group == CalibrationGroup::kCameraRotation) {
      value = angles(i);
      value_first = angles_first(i);
    } else if (p.group == CalibrationGroup::kMarkers) {
      value = double(last.state.markers(i)) * p.scale;
      value_first = double(first.state.markers(i)) * p.scale;
    } else if (p.group == CalibrationGroup::kTimeOffset) {
      value = double(last.state.t_d) * p.scale;
      value_first = double(first.state.t_d) * p.scale;
    } else {  // the intrinsics, and the lens's coefficients after them
      const int k = int(j) - kLayout[CalibrationGroup::kIntrinsics].begin;
      value = double(last.state.intrinsics(k));
      value_first = double(first.state.intrinsics(k));
    }
    std::printf("%-17s %-5s %12.4f +-%-6.3f %12.4f +-%-6.4f", p.name.c_str(), p.unit.c_str(),
                value_first, first.sigma(int(j)) * p.scale, value, last.sigma(int(j)) * p.scale);
    if (rec.has_truth) std::printf(" %+10.2f", last.error(int(j)) / last.sigma(int(j)));
    std::printf("\n");
  }
  if (rec.has_truth) print_final_nees(r.params.size(), last.nees, " against truth.yaml");
  const auto& lc = run.loop_counters;
  const auto& fc = run.filter_counters;
  std::printf(
      "loop, last of %d passes: %llu IMU samples, %llu frames (%llu without markers, %llu "
      "outside the IMU data "
      "skipped), %llu IMU gaps (%llu too long to cross: motion restarted), %llu frames behind the "
      "filter skipped, %llu markers used, %llu gated, %llu filter failures; %.2f s wall\n",
      run.result.passes, (unsigned long long)lc.imu_samples, (unsigned long long)lc.frames,
      (unsigned long long)lc.frames_without_markers, (unsigned long long)rec.frames_outside_imu,
      (unsigned long long)lc.imu_gaps, (unsigned long long)lc.imu_restarts,
      (unsigned long long)lc.frames_before_filter, (unsigned long long)fc.markers_used,
      (unsigned long long)fc.markers_gated, (unsigned long long)fc.failures, wall);
  if (rec.from_images) {
    const DetectionReport& d = run.detection;
    std::printf(
        "detection in the images, last pass: %llu frames, %llu markers labelled, %llu withheld "
        "in doubt, %llu blobs unlabelled; %.2f ms per frame reading the image, %.2f ms detecting "
        "and labelling\n",
        (unsigned long long)d.frames, (unsigned long long)d.markers_labelled,
        (unsigned long long)d.dropped_in_doubt, (unsigned long long)d.unlabelled_blobs,
        d.read_ms_per_frame, d.ms_per_frame);
    if (const io::ImageLog* log = rec.streams->image_log(); log && log->unreadable > 0) {
      std::fprintf(stderr, "mirrorcal: WARNING: %llu images could not be read and were skipped:\n",
                   (unsigned long long)log->unreadable);
      for (int k = 0; k < log->kept; ++k)
        std::fprintf(stderr, "  %s\n", log->messages[std::size_t(k)].data());
      if (log->unreadable > std::uint64_t(log->kept)) std::fprintf(stderr, "  ...\n");
    }
  }
  print_result_warnings(run.result);
  if (!write_run_outputs_and_report(out, run, "mirrorcal calibrate " + in, from != nullptr,
                                    report_plots(plots), err, rec.warnings))
    return refuse(err, 1);
  std::printf(
      "wrote %s/camchain-imucam.yaml, mirrorcal-result.yaml, estimates.csv, report.txt, "
      "report.html, residuals.csv, imu_residuals.csv%s%s%s\n",
      out.c_str(), run.features_found ? ", features.csv (the markers found in the images)" : "",
      NI > 0 ? ", kalibr_imu_chain.yaml (the IMU's intrinsics, as OpenVINS reads them)" : "",
      run.result.noise.estimated ? ", imu.yaml (the noise densities estimated)" : "");
  return calibration_exit_status(run.result);
}

}  // namespace

int cmd_calibrate(int argc, char** argv) {
  Options o;
  std::string err;
  if (!parse(argc, argv, 2, {"out", "from", "imu-model", "sensors", "imu-topic", "camera-topic"},
             {"intrinsics", "hold-skew", "from-same-data", "from-images", "estimate-noise",
              "no-plots"},
             o, err, 1))
    return refuse(err);
  if (o.positional.size() != 1)
    return refuse("calibrate needs a recording folder DIR or a bag\n" + usage("calibrate"));
  const std::string in = o.positional[0];
  const bool bag = io::is_bag(in);
  const io::BagOptions bag_options{o.get("sensors", ""), o.get("imu-topic", ""),
                                   o.get("camera-topic", "")};
  if (!bag && (o.flag("sensors") || o.flag("imu-topic") || o.flag("camera-topic")))
    return refuse(
        in + " is a recording folder: --sensors, --imu-topic and --camera-topic apply to bags");
  // The filter of the recording's number of markers (mirrorcal.yaml's features_c). Where the
  // files cannot tell, open_recording says what is wrong with them, checking them in order.
  const std::string yaml_dir = bag ? io::bag_sensors_dir(in, bag_options) : in;
  int markers = kDefaultMarkerCount;
  std::string unread;
  io::recording_marker_count(yaml_dir, markers, unread);
  return with_markers(markers, [&](auto m) {
    constexpr int M = decltype(m)::value;
    io::Recording rec;
    // The markers: features.csv, or found in the images where there is none (or when asked); a
    // bag's are always found in its images.
    const bool from_images =
        bag || o.flag("from-images") || (!io::has_features_csv(in) && io::has_images(in));
    // Streamed from its files in each pass: memory does not grow with the recording.
    if (bag) {
      if (!open_bag(in, bag_options, M, rec, err)) return refuse(err, 1);
      std::printf("mirrorcal calibrate: the markers are detected in the images of the bag %s\n",
                  in.c_str());
    } else {
      if (!io::open_recording(in, M, rec, err, from_images)) return refuse(err, 1);
      if (from_images)
        std::printf(
            "mirrorcal calibrate: the markers are detected in the images of %s/mav0/cam0/data%s\n",
            in.c_str(),
            io::has_features_csv(in) ? " (--from-images: features.csv beside them is not read)"
                                     : " (no features.csv)");
    }
    for (const auto& note : rec.notes) std::fprintf(stderr, "mirrorcal: note: %s\n", note.c_str());
    for (const auto& w : rec.warnings) std::fprintf(stderr, "mirrorcal: WARNING: %s\n", w.c_str());
    // --from: the paper's stage 2 on recordings; the camera pose and markers start from an earlier
    // calibration (of another recording: the same data twice would count twice).
    io::CalibrationStart start;
    const io::CalibrationStart* from = nullptr;
    if (o.flag("from")) {
      if (!io::read_calibration_start(o.get("from", ""), M, start, err)) return refuse(err, 1);
      if (start.recording_fingerprint == rec.fingerprint && !o.flag("from-same-data"))
        return refuse(
            o.get("from", "") + " was calibrated from this recording's data (" + in +
                ", recording_fingerprint " + rec.fingerprint +
                "): calibrating it again would count the data twice and shrink every sigma. "
                "Calibrate another recording from it, or give --from-same-data if that is meant.",
            1);
      from = &start;
      std::printf(
          "mirrorcal calibrate: the camera pose and markers start from %s (estimate and "
          "covariance), not from mirrorcal.yaml's guesses\n",
          o.get("from", "").c_str());
    }
    std::string out;
    if (!make_out_dir(o, "out/calibrate", out, err)) return refuse(err, 1);
    const bool intrinsics = o.flag("intrinsics") || rec.priors.estimate_intrinsics;
    const bool hold_skew = o.flag("hold-skew") || rec.priors.hold_skew;
    if (o.flag("hold-skew") && !intrinsics)
      return refuse(
          "--hold-skew applies when the intrinsics are estimated (--intrinsics, or "
          "estimate_intrinsics: true in " +
          yaml_dir + "/mirrorcal.yaml)");
    if (rec.priors.hold_skew && !intrinsics)
      std::fprintf(
          stderr,
          "mirrorcal: note: %s/mirrorcal.yaml: hold_skew has no effect, the intrinsics are "
          "not estimated\n",
          yaml_dir.c_str());
    ImuModel imu_model = kDefaultImuModel;
    if (!calibration_imu_model(o, rec.sensors, yaml_dir, imu_model, err)) return refuse(err);
    if (from && imu_model != ImuModel::kCalibrated && from->imu_model == imu_model &&
        from->imu_covariance.rows() > 0)
      std::printf("mirrorcal calibrate: the IMU's intrinsics (%s) start from it too\n",
                  to_string(imu_model));
    // --estimate-noise: the noise densities and the pixel noise from the data, not imu.yaml's and
    // mirrorcal.yaml's (noise_estimate.hpp).
    Passes passes;
    passes.estimate_noise = o.flag("estimate-noise");
    // estimate_distortion (mirrorcal.yaml, which checked it needs estimate_intrinsics and a lens):
    // the lens's coefficients too, skew held.
    const int nk = camera_block(intrinsics, hold_skew, rec.priors.estimate_distortion);
    return with_filter_blocks(nk, imu_model, [&](auto k, auto imu) {
      return calibrate<M, decltype(k)::value, decltype(imu)::value>(rec, in, out, from, passes,
                                                                    !o.flag("no-plots"));
    });
  });
}

}  // namespace mirrorcal::app
