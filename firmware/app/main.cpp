// mirrorcal: IMU-camera self-calibration in front of a plane mirror. One file per command
// (cmd_*.cpp); this table is the only place that lists them.
#include <cstdio>
#include <string>

#include "build_tools.hpp"
#include "cli.hpp"
#include "mirrorcal/io/files.hpp"
#include "mirrorcal/io/version.hpp"

namespace mirrorcal::app {

using namespace calibration;

int cmd_record(int argc, char** argv);
int cmd_calibrate(int argc, char** argv);
int cmd_run(int argc, char** argv);
int cmd_export(int argc, char** argv);
int cmd_imu_noise(int argc, char** argv);

const std::vector<Command>& commands() {
  static const std::vector<Command> table = {
      {"sim",
       "  sim         calibrate a simulated rig in front of a mirror\n"
       "              [--scenario paper|random|mems] [--seed N] [--out DIR] [--no-plots]\n"
       "              (mems: a random rig whose IMU has a MEMS part's scale factors and\n"
       "              non-orthogonal axes)\n"
       "              [--markers M]  (the random rig's number of markers, a count this build\n"
       "              has; default 3, the paper's rig has 3)\n"
       "              [--imu-model calibrated|scale-misalignment|...]  (the IMU's intrinsics\n"
       "              the calibration estimates, docs/estimator.md; default the scenario's IMU's:\n"
       "              scale-misalignment for mems, calibrated for the ideal IMU of the others)\n"
       "              [--timeshift S]  (the camera's stamps S seconds before the IMU's clock:\n"
       "              t_imu = t_cam + S; default 0, the random family draws one in +-30 ms)\n"
       "              [--distortion radtan|equidistant]  (the camera's lens: EuRoC cam0's\n"
       "              radtan, or a fisheye; default none)\n"
       "              [--line-delay S]  (a rolling shutter reading each row S seconds after the\n"
       "              one above, camchain.yaml's line_delay; default 0: a global shutter)\n"
       "              [--duration S]  (S seconds of the simulated motion, 1..600; default 60)\n"
       "              [--outliers P]  (in the share P of frames, 0.02 or 2%, one marker's pixel\n"
       "              is a random one: a detector that took a room light for an LED)\n"
       "              [--label-swaps P]  (in the share P of frames markers 0 and 1 swapped)\n"
       "              [--intrinsics [--hold-skew] [--one-stage]]  (stage 2: Table III;\n"
       "              --hold-skew: skew 0; --one-stage: everything at once from one minute)\n"
       "              [--estimate-distortion]  (with --intrinsics and --distortion: stage 2\n"
       "              estimates the lens's coefficients too, skew held: OpenVINS's eight)\n"
       "              [--frames [--format grey|yuyv]]  (markers detected in rendered frames)\n"
       "              [--spot-noise PX] [--pixel-sigma PX]  (with --frames: the pixel noise drawn\n"
       "              into the frames and the one the filter assumes; default the scenario's)\n"
       "              [--identical-leds]  (with --frames: every LED equally bright, no brightness\n"
       "              code; the labels come from the rig's shape fitted to tracked reflections)\n"
       "              [--blink PERIOD]  (with --frames: LEDs that blink their names, marker i\n"
       "              dark in frame i + 1 of every PERIOD, as run's LED lines drive them)\n"
       "              [--room]  (with --frames: a real room: two lights and each LED's ghost\n"
       "              in the mirror, an exposure that clips the brightest LEDs, motion blur)\n"
       "              [--passes N]  (exactly N passes over the data; default 2, up to 6 while the\n"
       "              last gates over 0.5 % of the markers; the last pass is reported)\n"
       "              [--estimate-noise]  (the IMU's noise densities and the pixel noise from\n"
       "              the data, not imu.yaml's; writes imu.yaml with them)\n"
       "              [--profile [--budget-imu-us N] [--budget-frame-us N]]\n"
       "              [--rt-priority P] [--mlock] [--cpu C]\n",
       cmd_sim},
      {"montecarlo",
       "  montecarlo  N independent simulated calibrations, statistics against the paper\n"
       "              --runs N [--jobs J] [--seed S] [--scenario paper|random|mems] [--out DIR]\n"
       "              [--no-plots] [--markers M] [--timeshift S] [--distortion MODEL]\n"
       "              [--line-delay S] [--outliers P] [--label-swaps P]\n"
       "              (as sim) [--filter-line-delay S]  (the line delay the filter is told;\n"
       "              default the true one: what an unmodelled rolling shutter does)\n"
       "              [--intrinsics [--hold-skew] [--one-stage]]  (stage 2: Table III)\n"
       "              [--estimate-distortion]  (as sim)\n"
       "              [--passes N] [--frames [--format grey|yuyv]] [--spot-noise PX]\n"
       "              [--pixel-sigma PX] [--identical-leds] [--blink PERIOD] [--room]  (as sim)\n"
       "              [--rig SEED]  (random: every run the rig sim --seed SEED draws, with\n"
       "              noise and prior guesses of its own: how well that one rig calibrates)\n"
       "              [--imu-model MODEL]  (as sim; --scenario mems for MEMS IMUs)\n"
       "              [--estimate-noise]  (as sim)\n"
       "              [--batch]  (stage 1: the batch maximum-likelihood solution of every run's\n"
       "              data and priors beside it, each group's RMS as filter over batch, the\n"
       "              batch's own NEES; batch.csv)\n",
       cmd_montecarlo},
      {"record",
       "  record      write the simulated rig's data and priors as a EuRoC recording\n"
       "              --out DIR [--scenario paper|random] [--seed N] [--markers M]\n"
       "              [--timeshift S] [--distortion MODEL] [--line-delay S] [--outliers P]\n"
       "              [--label-swaps P]\n"
       "              (as sim)\n"
       "              [--intrinsics [--hold-skew]]\n"
       "              [--two-stage [--hold-skew]]  (DIR/stage1 and DIR/stage2 of sim "
       "--intrinsics)\n"
       "              [--estimate-distortion]  (with either and --distortion: mirrorcal.yaml\n"
       "              asks for the lens's coefficients too, camchain.yaml holds their guess)\n"
       "              [--images]  (the camera frames too, as PNG in mav0/cam0/data/: the\n"
       "              markers of features.csv drawn as sim --frames draws them)\n"
       "              [--bag]  (DIR a ROS 2 bag instead: metadata.yaml and DIR_0.mcap of\n"
       "              sensor_msgs/msg/Imu and the same images as mono8 sensor_msgs/msg/Image,\n"
       "              zstd chunks; the yaml files beside them; calibrate DIR reads it)\n"
       "              [--identical-leds]  (with --images or --bag: every LED drawn equally\n"
       "              bright, and mirrorcal.yaml's led_brightness says so)\n"
       "              [--duration S]  (as sim)\n"
       "              or the board's devices: --out DIR --imu SPEC [--camera DEV [--images]]\n"
       "              [--sensors DIR | --markers M]  (the markers to detect: as many as the\n"
       "              sensors' mirrorcal.yaml lists, else M, default 3)\n"
       "              [--duration S] [--drdy CHIP:LINE] [--trigger CHIP:LINE [--trigger-every N]]\n"
       "              [--config FILE]\n"
       "              written whole into DIR when complete; --force replaces a recording there\n",
       cmd_record},
      {"calibrate",
       "  calibrate   calibrate a EuRoC recording (mav0/, imu.yaml, camchain.yaml, "
       "mirrorcal.yaml)\n"
       "              or a ROS bag (.bag, .mcap, a ROS 2 bag's folder; its images' markers found\n"
       "              as --from-images finds them)\n"
       "              DIR|BAG [--intrinsics [--hold-skew]] [--from RESULT [--from-same-data]]\n"
       "              [--sensors DIR] [--imu-topic T] [--camera-topic T]  (a bag's: where its\n"
       "              yaml files are, default beside it; its topics, default the yaml files')\n"
       "              [--out OUT] [--from-images] [--estimate-noise]  (the IMU's noise\n"
       "              densities and the pixel noise from the data; writes imu.yaml with them)\n"
       "              [--no-plots]  (report.html without its figures: no gnuplot)\n"
       "              (the markers: mav0/cam0/features.csv; a recording without it, whose\n"
       "              images are in mav0/cam0/data/ (8-bit PNG or PGM, as cam0/data.csv names\n"
       "              them), has them detected in its images by the board's detection and\n"
       "              labelled with the filter's prediction; --from-images does so even\n"
       "              beside a features.csv)\n"
       "              (--from: start the camera pose and markers from an earlier calibration's\n"
       "              mirrorcal-result.yaml, or its folder: stage 2 after a stage 1; one of\n"
       "              this same recording is refused unless --from-same-data)\n"
       "              (--hold-skew: skew stays at camchain.yaml's intrinsics_skew, 0 if absent)\n"
       "              [--imu-model calibrated|scale-misalignment|...]  (the IMU's intrinsics\n"
       "              estimated too; default imu.yaml's imu_model, else scale-misalignment, a\n"
       "              MEMS part's; its tolerances from imu.yaml: docs/recordings.md)\n",
       cmd_calibrate},
      {"run",
       "  run         calibrate on the board's devices\n"
       "              --imu spi:/dev/spidevB.C  (TDK ICM-42688-P)\n"
       "                  | i2c:/dev/i2c-N[:ADDR]  (InvenSense MPU-6050 family; default 0x68)\n"
       "                  | can:IFACE  (Bosch MM7.10, 500 kbit/s)\n"
       "              (another part: log it with its own tool as a EuRoC folder or a ROS bag and\n"
       "              calibrate that; docs/board.md, \"Another IMU part\")\n"
       "              --sensors DIR (imu.yaml, camchain.yaml, mirrorcal.yaml: its features_c\n"
       "              say how many markers) [--drdy CHIP:LINE]\n"
       "              [--camera /dev/videoN] [--trigger CHIP:LINE [--trigger-every N]]\n"
       "              (drive the camera's trigger input on every Nth IMU sample; by default\n"
       "              the fewest samples that span the camera's frame interval)\n"
       "              [--out DIR] [--duration S] [--rate HZ]\n"
       "              [--gyro-range DPS] [--accel-range G] [--config FILE] [--profile]\n"
       "              [--from RESULT]  (start from an earlier calibration, as calibrate --from)\n"
       "              [--imu-model MODEL]  (as calibrate; default imu.yaml's imu_model: the\n"
       "              live feedback then also names the motion the IMU's intrinsics need)\n"
       "              [--rt-priority P] [--mlock] [--cpu C]\n",
       cmd_run},
      {"export",
       "  export      write a calibration for another tool to read directly\n"
       "              --format openvins|vins-fusion|ros-camera-info RESULT OUT\n"
       "              (RESULT: a mirrorcal-result.yaml, or its folder; openvins: OpenVINS's\n"
       "              kalibr_imucam_chain.yaml; vins-fusion: the camera-IMU keys of its config, "
       "and\n"
       "              its camera file OUT's stem + _cam0.yaml beside it; ros-camera-info: a ROS\n"
       "              camera_info YAML) [--force]  (a result that says consistent: false is\n"
       "              refused, exit status 3, unless --force)\n",
       cmd_export},
      {"batch",
       "  batch       the batch maximum-likelihood solution of a recording: the reference\n"
       "              the filter is measured against (host only; Ceres)\n"
       "              DIR [--out OUT] [--intrinsics [--hold-skew]] [--imu-model MODEL]\n"
       "              (DIR: a recording folder with features.csv; the same model, priors and\n"
       "              output files as calibrate, the IMU model as calibrate chooses it;\n"
       "              default --out out/batch)\n",
       cmd_batch},
      {"imu-noise",
       "  imu-noise   an IMU's noise from a still recording, as Kalibr's imu.yaml\n"
       "              PATH [--out DIR]  (PATH: a recording's folder, whose mav0/imu0/data.csv\n"
       "              is read, or such a data.csv itself; default --out out/imu-noise)\n"
       "              (the overlapping Allan deviation of each axis; its white-noise density,\n"
       "              bias instability and bias random walk with their uncertainties, and how\n"
       "              long to record for those not resolved; writes imu.yaml, allan.csv and,\n"
       "              in the host's build, allan.png. The IMU must stay still: a recording\n"
       "              that moves, is shorter than a minute or drops samples is refused)\n",
       cmd_imu_noise},
  };
  return table;
}

}  // namespace mirrorcal::app

int main(int argc, char** argv) {
  namespace app = mirrorcal::app;
  const std::string first = argc < 2 ? "" : argv[1];
  if (first == "--version") {
    std::printf("%s\n", mirrorcal::io::written_by().c_str());
    return 0;
  }
  if (argc < 2 || first == "--help" || first == "-h") {
    std::fputs(app::usage().c_str(), argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  for (const auto& c : app::commands()) {
    if (first != c.name) continue;
    // --help (or -h) anywhere among a command's arguments: its usage, and nothing else.
    if (app::asks_for_help(argc, argv, 2)) {
      std::fputs(app::usage(first).c_str(), stdout);
      return 0;
    }
    try {
      return c.run(argc, argv);
    } catch (const mirrorcal::io::StoreError& e) {
      // A calibration's temporary store that could not be written (a full $TMPDIR): as a
      // result file that could not be written, code 1 and the file named.
      return app::refuse(e.what(), 1);
    }
  }
  return app::refuse("unknown command '" + first + "'\n" + app::usage());
}
