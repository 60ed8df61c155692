// mirrorcal export: a calibration's result in the files OpenVINS, VINS-Fusion and ROS read.
#include <cstdio>
#include <string>

#include "cli.hpp"
#include "mirrorcal/calibration/result.hpp"
#include "mirrorcal/sim_host/recording.hpp"

namespace mirrorcal::app {

using namespace calibration;

namespace {

// What the export writers need of a result, as mirrorcal-result.yaml holds it.
CalibrationResult result_of(const sim::CalibrationStart& file) {
  CalibrationResult r;
  r.p_b_c = file.p_b_c;
  r.q_b_c = file.q_b_c;
  r.t_d = file.t_d;
  r.intrinsics = file.camera.intrinsics;
  r.width = file.camera.width;
  r.height = file.camera.height;
  r.rostopic = file.camera.rostopic;
  return r;
}

}  // namespace

int cmd_export(int argc, char** argv) {
  Options o;
  std::string err;
  if (!parse(argc, argv, 2, {"format"}, {}, o, err, 2)) fail(err);
  if (o.positional.size() != 2 || !o.flag("format"))
    fail("export needs --format FORMAT, a RESULT and an OUT file\n" + usage("export"));
  ExportFormat format{};
  const std::string name = o.get("format", "");
  if (!export_format_from_string(name, format))
    fail("--format: '" + name + "' is not a format (openvins, vins-fusion or ros-camera-info)");
  const std::string& in = o.positional[0];
  const std::string& out = o.positional[1];
  sim::CalibrationStart file;
  if (!sim::read_calibration_result(in, file, err)) fail(err, 1);
  if (!file.has_camera) fail(in + ": holds no camera (intrinsics, resolution) to export", 1);
  if (!write_export(format, out, result_of(file), err)) fail(err, 1);
  std::printf("wrote %s", out.c_str());
  if (format == ExportFormat::kVinsFusion) std::printf(" and %s", vins_camera_file(out).c_str());
  std::printf("\n");
  return 0;
}

}  // namespace mirrorcal::app
