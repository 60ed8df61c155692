// Recordings in ROS bags, read without ROS: a ROS 1 .bag, an .mcap file, or a ROS 2 bag folder
// (metadata.yaml over sqlite3 .db3 or MCAP files). The IMU's sensor_msgs/Imu and the camera's
// sensor_msgs/Image or CompressedImage (PNG, PGM) are read; the markers are found in the images,
// as in a recording folder's (open_recording's from_images). The sensors' descriptions, imu.yaml,
// camchain.yaml and mirrorcal.yaml, lie beside the bag or in a folder named for them.
#pragma once

#include <string>

#include "mirrorcal/sim_host/recording.hpp"

namespace mirrorcal::sim {

struct BagOptions {
  std::string sensors_dir;   // the yaml files' folder; empty: the bag's own folder
  std::string imu_topic;     // empty: imu.yaml's rostopic (Kalibr's default /imu0)
  std::string camera_topic;  // empty: camchain.yaml's, or it with /compressed if only that is there
};

// Whether path names a bag by its form: a file ending in .bag, .mcap or .db3, or a folder holding
// metadata.yaml. (This and bag_sensors_dir are in every build; open_bag_recording only in the
// host's, with the libraries of the containers: mirrorcal_bags.)
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

}  // namespace mirrorcal::sim
