// libFuzzer target: an image of a recording's cam0/data/ (PNG or PGM) as calibrate from images
// reads it. Any input gives an image within the reader's bounds or a message naming the file,
// never a crash, an overrun or an allocation sized by the input.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>

#include "mirrorcal/sim_host/images.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  constexpr int kWidth = 64, kHeight = 48;
  static mirrorcal::sim::ImageReader reader(kWidth, kHeight);  // as a pass: made once
  mirrorcal::sim::GrayImage image;
  if (!reader.decode(data, size, "cam0/data/1.png", image)) {
    if (std::strncmp(reader.error(), "cam0/data/1.png: ", 17) != 0) std::abort();
    return 0;
  }
  if (image.width < 1 || image.width > kWidth || image.height < 1 || image.height > kHeight ||
      image.pixels == nullptr)
    std::abort();
  unsigned sum = 0;  // every pixel is readable (ASan sees an overrun)
  for (int k = 0; k < image.width * image.height; ++k) sum += image.pixels[k];
  return sum == 0xffffffffu ? 1 : 0;
}
