// A recording's camera images (mav0/cam0/data/): PNG as EuRoC and Kalibr's bag tools keep them,
// and binary PGM. A strict, bounded reader: 8- and 16-bit PNG (grey; RGB, RGBA and grey with alpha
// read as their luma, alpha ignored; 16 bits as their upper 8) and P5 PGM of any maxval (scaled
// to 0..255); every chunk's CRC and the image data's
// size checked; nothing sized from a file beyond the bounds given up front. And the PNG writer of
// `record --images` (grey, 8-bit). Both allocate their buffers when made and nothing afterwards, so
// a loop can read or write an image per frame without the heap (zlib gets its memory from them
// too).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace mirrorcal::io {

// An 8-bit grey image, row-major, stride = width.
struct GrayImage {
  int width = 0, height = 0;
  const std::uint8_t* pixels = nullptr;
};

// ITU-R BT.601 luma of an 8-bit colour, as V4L2's and OpenCV's grey: colour images are read as it.
inline std::uint8_t bt601_luma(unsigned r, unsigned g, unsigned b) {
  return std::uint8_t((77u * r + 150u * g + 29u * b + 128u) >> 8);
}

// The largest image side any reader accepts, whatever it is asked for.
inline constexpr int kMaxImageSide = 16384;

// Reads images of at most max_width x max_height pixels. Its messages name the file and what is
// wrong with it ("data/1.png: bit depth 4: only 8- and 16-bit images are read").
class ImageReader {
 public:
  ImageReader(int max_width, int max_height);
  ~ImageReader();
  ImageReader(const ImageReader&) = delete;
  ImageReader& operator=(const ImageReader&) = delete;

  // The regular file at path (PNG or PGM, told by its first bytes) into image, whose pixels stay
  // valid until the next call. False with error() set otherwise.
  bool read(const char* path, GrayImage& image);
  // The same on bytes in memory; name stands for the file in messages.
  bool decode(const std::uint8_t* data, std::size_t size, const char* name, GrayImage& image);
  // What the last failed call found wrong, naming its file.
  const char* error() const { return error_; }
  // The largest file read() takes: the largest image's bytes with generous room for overhead.
  std::size_t max_file_bytes() const { return file_.size(); }

 private:
  struct Zlib;
  bool fail(const char* name, const char* format, ...) __attribute__((format(printf, 3, 4)));
  bool decode_png(const std::uint8_t* data, std::size_t size, const char* name, GrayImage& image);
  bool decode_pgm(const std::uint8_t* data, std::size_t size, const char* name, GrayImage& image);

  int max_width_, max_height_;
  std::vector<std::uint8_t> file_;    // read()'s file
  std::vector<std::uint8_t> raw_;     // PNG: the inflated, filtered scanlines
  std::vector<std::uint8_t> pixels_;  // the grey image delivered
  std::unique_ptr<Zlib> zlib_;
  char error_[512] = "";
};

// Writes 8-bit grey PNG files of images up to max_width x max_height (each row filtered with
// PNG's Sub filter, zlib at its fastest level).
class PngWriter {
 public:
  PngWriter(int max_width, int max_height);
  ~PngWriter();
  PngWriter(const PngWriter&) = delete;
  PngWriter& operator=(const PngWriter&) = delete;

  // The PNG file of image, valid until the next call; null if the image is larger than this
  // writer was made for or zlib fails (error() says which).
  const std::uint8_t* encode(const GrayImage& image, std::size_t& size);
  const char* error() const { return error_; }

 private:
  struct Zlib;
  int max_width_, max_height_;
  std::vector<std::uint8_t> filtered_, out_;
  std::unique_ptr<Zlib> zlib_;
  char error_[256] = "";
};

}  // namespace mirrorcal::io
