// For images_vs_opencv.py: `decode IN OUT` reads IN (PNG or PGM) with the recordings' reader and
// writes its grey pixels as a binary PGM; `encode IN OUT` reads IN and writes it with the
// recordings' PNG writer. Exit 1 with the reader's message on stderr.
#include <cstdio>
#include <cstring>
#include <string>

#include "mirrorcal/io/images.hpp"

int main(int argc, char** argv) {
  if (argc != 4 || (std::strcmp(argv[1], "decode") != 0 && std::strcmp(argv[1], "encode") != 0)) {
    std::fprintf(stderr, "usage: %s decode|encode IN OUT\n", argv[0]);
    return 2;
  }
  constexpr int kSide = 2048;
  mirrorcal::io::ImageReader reader(kSide, kSide);
  mirrorcal::io::GrayImage image;
  if (!reader.read(argv[2], image)) {
    std::fprintf(stderr, "%s\n", reader.error());
    return 1;
  }
  std::FILE* out = std::fopen(argv[3], "wb");
  if (out == nullptr) return 2;
  if (std::strcmp(argv[1], "decode") == 0) {
    std::fprintf(out, "P5\n%d %d\n255\n", image.width, image.height);
    std::fwrite(image.pixels, 1, std::size_t(image.width) * std::size_t(image.height), out);
  } else {
    mirrorcal::io::PngWriter writer(image.width, image.height);
    std::size_t n = 0;
    const std::uint8_t* png = writer.encode(image, n);
    if (png == nullptr) {
      std::fprintf(stderr, "%s\n", writer.error());
      return 1;
    }
    std::fwrite(png, 1, n, out);
  }
  return std::fclose(out) == 0 ? 0 : 2;
}
