// libFuzzer target: an image of a recording's cam0/data/ (PNG or PGM) as calibrate from images
// reads it. Any input gives an image within the reader's bounds or a message naming the file,
// never a crash, an overrun or an allocation sized by the input.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>

#include <vector>

#include <zlib.h>

#include "mirrorcal/io/images.hpp"

namespace {

constexpr int kWidth = 64, kHeight = 48;

void check(const std::uint8_t* data, std::size_t size) {
  static mirrorcal::io::ImageReader reader(kWidth, kHeight);  // as a pass: made once
  mirrorcal::io::GrayImage image;
  if (!reader.decode(data, size, "cam0/data/1.png", image)) {
    if (std::strncmp(reader.error(), "cam0/data/1.png: ", 17) != 0) std::abort();
    return;
  }
  if (image.width < 1 || image.width > kWidth || image.height < 1 || image.height > kHeight ||
      image.pixels == nullptr)
    std::abort();
  unsigned sum = 0;  // every pixel is readable (ASan sees an overrun)
  for (int k = 0; k < image.width * image.height; ++k) sum += image.pixels[k];
  if (sum == 0xffffffffu) std::abort();  // cannot be: keeps the loop
}

std::uint32_t big_endian(const std::uint8_t* p) {
  return std::uint32_t(p[0]) << 24 | std::uint32_t(p[1]) << 16 | std::uint32_t(p[2]) << 8 | p[3];
}

}  // namespace

// Each input as it is, and with every PNG chunk's CRC made right, so that mutations reach past
// the CRC check into the header, inflate and the filters.
extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  check(data, size);
  if (size < 8 || data[0] != 0x89) return 0;
  std::vector<std::uint8_t> fixed(data, data + size);
  for (std::size_t at = 8; size - at >= 12;) {
    const std::uint32_t length = big_endian(&fixed[at]);
    if (length > size - at - 12) break;
    const std::uint32_t crc = std::uint32_t(crc32(0, &fixed[at + 4], length + 4));
    for (int k = 0; k < 4; ++k)
      fixed[at + 8 + length + std::size_t(k)] = std::uint8_t(crc >> (24 - 8 * k));
    at += 12 + length;
  }
  check(fixed.data(), fixed.size());
  return 0;
}
