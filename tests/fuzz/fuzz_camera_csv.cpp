// libFuzzer target: mav0/cam0/data.csv and features.csv. The input is the two files separated by
// a line "---"; any input gives frames or a message, never a crash.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "mirrorcal/io/recording.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const std::size_t cut = text.find("\n---\n");
  const std::string_view frames_csv = text.substr(0, cut);
  const std::string_view features_csv =
      cut == std::string_view::npos ? std::string_view() : text.substr(cut + 5);
  constexpr int kMarkers = 3;
  std::vector<mirrorcal::io::ObservedFrame> frames;
  std::string error;
  if (!mirrorcal::io::parse_frames_csv(frames_csv, "data.csv", frames, error)) {
    if (error.empty()) std::abort();
    return 0;
  }
  const bool ok =
      mirrorcal::io::parse_features_csv(features_csv, "features.csv", kMarkers, frames, error);
  if (ok != error.empty()) std::abort();
  if (ok)
    for (std::size_t k = 0; k < frames.size(); ++k) {
      if (k > 0 && frames[k].t_ns <= frames[k - 1].t_ns) std::abort();
      for (const auto& m : frames[k].markers)
        if (m.id < 0 || m.id >= kMarkers || !std::isfinite(m.u) || !std::isfinite(m.v))
          std::abort();
    }
  return 0;
}
