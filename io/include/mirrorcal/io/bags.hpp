// Recordings in ROS bags, read without ROS: a ROS 1 .bag, an .mcap file, or a ROS 2 bag folder
// (metadata.yaml over sqlite3 .db3 or MCAP files). The IMU's sensor_msgs/Imu and the camera's
// sensor_msgs/Image or CompressedImage (PNG, PGM) are read; the markers are found in the images,
// as in a recording folder's (open_recording's from_images). The sensors' descriptions, imu.yaml,
// camchain.yaml and mirrorcal.yaml, lie beside the bag or in a folder named for them.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "mirrorcal/io/images.hpp"
#include "mirrorcal/io/recording.hpp"

namespace mirrorcal::io {

struct BagOptions {
  std::string sensors_dir;   // the yaml files' folder; empty: the bag's own folder
  std::string imu_topic;     // empty: imu.yaml's rostopic (Kalibr's default /imu0)
  std::string camera_topic;  // empty: camchain.yaml's, or it with /compressed if only that is there
};

// Whether path names a bag by its form: a file ending in .bag, .mcap or .db3, or a folder holding
// metadata.yaml. (This and bag_sensors_dir are in every build; open_bag_recording only in the
// host's, with the libraries of the containers: mirrorcal_io_bags.)
bool is_bag(const std::string& path);

// The folder the yaml files of the bag at path are read from: options.sensors_dir, else the bag
// folder itself if it holds camchain.yaml, else the folder the bag lies in.
std::string bag_sensors_dir(const std::string& path, const BagOptions& options);

// The bag at path as a recording for a calibration with M = markers, its streams read from the
// bag in passes of bounded memory, with every check open_recording makes. On bad input false with
// a message naming the file, the topic and the byte or row where it went wrong, and for a topic
// that is not there, the topics that are.
bool open_bag_recording(const std::string& path, const BagOptions& options, int markers,
                        Recording& out, std::string& error);

// A recording's streams written as a ROS 2 bag folder, which `ros2 bag` and Foxglove read, and
// calibrate as any bag: FOLDER/metadata.yaml (rosbag2's) and FOLDER/NAME_0.mcap (NAME the bag's,
// rosbag2's name for its folder's first file), the IMU's samples as sensor_msgs/msg/Imu and the
// camera's frames as sensor_msgs/msg/Image (mono8), CDR, in zstd chunks of a few MB with their
// message indexes, and a summary indexing them (mcap.dev/spec). Memory holds one chunk. The files
// are renamed into place by close(); until then, and if anything failed, the folder holds neither.
// (Host builds only, as open_bag_recording.)
class BagWriter {
 public:
  BagWriter();
  ~BagWriter();
  BagWriter(const BagWriter&) = delete;
  BagWriter& operator=(const BagWriter&) = delete;

  // Creates folder if need be; false with a message naming the file if it cannot be written.
  bool open(const std::string& folder, const std::string& name, const std::string& imu_topic,
            const std::string& camera_topic, std::string& error);
  // Messages in the order they come (a recorder's): each stamped in its header and logged at its
  // stamp. False once anything failed; close() says what.
  bool add_imu(const ImuSample& sample);
  bool add_image(std::int64_t t_ns, const GrayImage& image);
  bool close(std::string& error);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace mirrorcal::io
