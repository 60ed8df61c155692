// mirrorcal imu-noise: an IMU's noise figures from a still recording, as Kalibr's imu.yaml.
#include <cstdio>
#include <string>
#include <vector>

#include "build_tools.hpp"
#include "cli.hpp"
#include "mirrorcal/calibration/imu_noise_files.hpp"

namespace mirrorcal::app {

using namespace calibration;

int cmd_imu_noise(int argc, char** argv) {
  Options o;
  std::string err;
  if (!parse(argc, argv, 2, {"out"}, {}, o, err, 1)) return refuse(err);
  if (o.positional.size() != 1)
    return refuse("imu-noise needs a still recording: its folder or its mav0/imu0/data.csv\n" +
                  usage("imu-noise"));
  ImuNoiseAnalysis a;
  {
    // The samples only while they are analysed: the analysis keeps the curves alone.
    std::vector<ImuSample> samples;
    std::string file;
    if (!read_imu_samples(o.positional[0], samples, file, err)) return refuse(err);
    if (!analyse_imu_noise(samples, file, a, err)) return refuse(err);
  }
  std::string out;
  if (!make_out_dir(o, "out/imu-noise", out, err)) return refuse(err, 1);
  std::fputs(imu_noise_summary(a).c_str(), stdout);
  std::string plot_note;
  if (!write_imu_noise(out, a, allan_plotter(), plot_note, err)) return refuse(err, 1);
  if (!plot_note.empty()) std::fprintf(stderr, "mirrorcal: note: %s\n", plot_note.c_str());
  std::printf(
      "wrote %s/imu.yaml, allan.csv%s (imu.yaml is what calibrate and run read: copy it "
      "into the recording or the --sensors folder)\n",
      out.c_str(), plot_note.empty() && allan_plotter() != nullptr ? ", allan.png" : "");
  return 0;
}

}  // namespace mirrorcal::app
