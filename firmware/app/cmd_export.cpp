// mirrorcal export: a calibration's result in the files OpenVINS, VINS-Fusion and ROS read.
#include <cstdio>
#include <string>

#include "cli.hpp"
#include "mirrorcal/calibration/result.hpp"
#include "mirrorcal/io/recording.hpp"

namespace mirrorcal::app {

using namespace calibration;

namespace {

// What the export writers need of a result, as mirrorcal-result.yaml holds it.
CalibrationResult result_of(const io::CalibrationStart& file) {
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
  if (!parse(argc, argv, 2, {"format"}, {"force"}, o, err, 2)) return refuse(err);
  if (o.positional.size() != 2 || !o.flag("format"))
    return refuse("export needs --format FORMAT, a RESULT and an OUT file\n" + usage("export"));
  ExportFormat format{};
  const std::string name = o.get("format", "");
  if (!export_format_from_string(name, format))
    return refuse("--format: '" + name +
                  "' is not a format (openvins, vins-fusion or ros-camera-info)");
  const std::string& in = o.positional[0];
  const std::string& out = o.positional[1];
  io::CalibrationStart file;
  if (!io::read_calibration_result(in, file, err)) return refuse(err, 1);
  if (!file.has_camera)
    return refuse(in + ": holds no camera (intrinsics, resolution) to export", 1);
  // A flagged calibration handed to another tool would be used as a good one.
  if (!file.trusted && !o.flag("force"))
    return refuse(
        in + ": says consistent: false (its self-check's WARNINGs and report.txt say why); "
             "exporting it would hand it to another tool as a good calibration. Calibrate again, "
             "or give --force to export it anyway (the file then says it is not to be trusted)",
        kExitNotConsistent);
  if (!file.trusted)
    std::fprintf(stderr,
                 "mirrorcal: WARNING: exporting a calibration that says consistent: "
                 "false (--force); the file says so\n");
  if (!write_export(format, out, result_of(file), err, !file.trusted)) return refuse(err, 1);
  std::printf("wrote %s", out.c_str());
  if (format == ExportFormat::kVinsFusion) std::printf(" and %s", vins_camera_file(out).c_str());
  std::printf("\n");
  return 0;
}

}  // namespace mirrorcal::app
