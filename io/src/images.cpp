// PNG (8- and 16-bit, not interlaced) and binary PGM images read strictly, and grey PNG written;
// zlib does the (de)compression with memory from a fixed arena each object allocates when made.
#include "mirrorcal/io/images.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

namespace mirrorcal::io {

namespace {

constexpr std::uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

// zlib's memory: carved from a block allocated once; freeing is a no-op (inflateReset and
// deflateReset keep what they have, and the stream lives as long as its arena).
struct Arena {
  explicit Arena(std::size_t bytes) : block(bytes) {}
  static voidpf alloc(voidpf opaque, uInt items, uInt size) {
    Arena& a = *static_cast<Arena*>(opaque);
    const std::size_t n = (std::size_t(items) * std::size_t(size) + 15) & ~std::size_t(15);
    if (n > a.block.size() - a.used) return Z_NULL;
    void* p = a.block.data() + a.used;
    a.used += n;
    return p;
  }
  static void free(voidpf, voidpf) {}
  std::vector<unsigned char> block;
  std::size_t used = 0;
};

std::uint32_t big_endian(const std::uint8_t* p) {
  return std::uint32_t(p[0]) << 24 | std::uint32_t(p[1]) << 16 | std::uint32_t(p[2]) << 8 |
         std::uint32_t(p[3]);
}

void put_big_endian(std::uint8_t* p, std::uint32_t v) {
  p[0] = std::uint8_t(v >> 24);
  p[1] = std::uint8_t(v >> 16);
  p[2] = std::uint8_t(v >> 8);
  p[3] = std::uint8_t(v);
}

int paeth(int a, int b, int c) {
  const int p = a + b - c;
  const int pa = p > a ? p - a : a - p, pb = p > b ? p - b : b - p, pc = p > c ? p - c : c - p;
  return pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
}

}  // namespace

// --- ImageReader --------------------------------------------------------------------------------

struct ImageReader::Zlib {
  Arena arena{64 * 1024};  // inflate's state and its 32 KiB window
  z_stream stream{};
  bool ok = false;
  Zlib() {
    stream.zalloc = Arena::alloc;
    stream.zfree = Arena::free;
    stream.opaque = &arena;
    ok = inflateInit(&stream) == Z_OK;
  }
  ~Zlib() {
    if (ok) inflateEnd(&stream);
  }
};

ImageReader::ImageReader(int max_width, int max_height)
    : max_width_(std::clamp(max_width, 1, kMaxImageSide)),
      max_height_(std::clamp(max_height, 1, kMaxImageSide)),
      zlib_(std::make_unique<Zlib>()) {
  const std::size_t w = std::size_t(max_width_), h = std::size_t(max_height_);
  raw_.resize((8 * w + 1) * h + 1);  // 16-bit RGBA, a filter byte per row; one to see excess data
  pixels_.resize(w * h);
  // A PNG holds its data in chunks of any size, compressed or stored: twice the largest raw
  // image and a MiB of other chunks is more than any encoder writes.
  file_.resize(2 * raw_.size() + (std::size_t(1) << 20));
}

ImageReader::~ImageReader() = default;

bool ImageReader::fail(const char* name, const char* format, ...) {
  int n = std::snprintf(error_, sizeof error_, "%s: ", name);
  if (n < 0 || std::size_t(n) >= sizeof error_) return false;
  va_list args;
  va_start(args, format);
  std::vsnprintf(error_ + n, sizeof error_ - std::size_t(n), format, args);
  va_end(args);
  return false;
}

bool ImageReader::read(const char* path, GrayImage& image) {
  const int fd = ::open(path, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) return fail(path, "cannot open: %s", std::strerror(errno));
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return fail(path, "not a regular file");
  }
  if (std::uint64_t(st.st_size) > file_.size()) {
    ::close(fd);
    return fail(path, "%lld bytes: larger than any image of at most %dx%d pixels can be",
                static_cast<long long>(st.st_size), max_width_, max_height_);
  }
  std::size_t have = 0;
  for (;;) {
    const ssize_t r = ::read(fd, file_.data() + have, file_.size() - have);
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) {
      const int e = errno;
      ::close(fd);
      return fail(path, "cannot read: %s", std::strerror(e));
    }
    if (r == 0) break;
    have += std::size_t(r);
    if (have == file_.size()) {  // it grew since fstat
      ::close(fd);
      return fail(path, "larger than any image of at most %dx%d pixels can be", max_width_,
                  max_height_);
    }
  }
  ::close(fd);
  return decode(file_.data(), have, path, image);
}

bool ImageReader::decode(const std::uint8_t* data, std::size_t size, const char* name,
                         GrayImage& image) {
  if (size >= 8 && std::memcmp(data, kPngSignature, 8) == 0)
    return decode_png(data, size, name, image);
  if (size >= 2 && data[0] == 'P' && data[1] == '5') return decode_pgm(data, size, name, image);
  if (size >= 2 && data[0] == 'P' && data[1] == '2')
    return fail(name, "a plain (ASCII) PGM: only binary PGM (P5) and PNG are read");
  if (size == 0) return fail(name, "empty");
  if (size < 8 && std::memcmp(data, kPngSignature, size) == 0)
    return fail(name, "truncated: %zu bytes, not even a PNG signature", size);
  return fail(name, "neither a PNG nor a binary PGM (P5) image");
}

bool ImageReader::decode_pgm(const std::uint8_t* data, std::size_t size, const char* name,
                             GrayImage& image) {
  std::size_t at = 2;
  long long value[3] = {0, 0, 0};
  for (long long& v : value) {
    for (;;) {  // whitespace and comments
      if (at < size && (data[at] == ' ' || data[at] == '\t' || data[at] == '\n' ||
                        data[at] == '\r' || data[at] == '\v' || data[at] == '\f')) {
        ++at;
      } else if (at < size && data[at] == '#') {
        while (at < size && data[at] != '\n') ++at;
      } else {
        break;
      }
    }
    if (at == size) return fail(name, "truncated: the PGM header ends early");
    if (data[at] < '0' || data[at] > '9') return fail(name, "the PGM header is not a number");
    for (; at < size && data[at] >= '0' && data[at] <= '9'; ++at) {
      v = 10 * v + (data[at] - '0');
      if (v > 1'000'000'000) return fail(name, "a number of the PGM header is too large");
    }
  }
  if (at == size) return fail(name, "truncated: the PGM header ends early");
  ++at;  // the single whitespace before the pixels
  const long long w = value[0], h = value[1], maxval = value[2];
  if (w == 0 || h == 0) return fail(name, "%lldx%lld pixels: an image without pixels", w, h);
  if (w > max_width_ || h > max_height_)
    return fail(name, "%lldx%lld pixels: larger than the %dx%d this reads", w, h, max_width_,
                max_height_);
  if (maxval < 1 || maxval > 65535) return fail(name, "maxval %lld: PGM's is 1..65535", maxval);
  // Two bytes a sample (most significant first) beyond 255, one up to it.
  const std::size_t bytes = maxval > 255 ? 2 : 1;
  const std::size_t need = std::size_t(w) * std::size_t(h) * bytes;
  if (size - at < need)
    return fail(name, "truncated: %zu of the %zu pixel bytes of %lldx%lld", size - at, need, w, h);
  if (size - at > need)
    return fail(name, "%zu bytes follow the %lldx%lld pixels", size - at - need, w, h);
  image.width = int(w);
  image.height = int(h);
  if (maxval == 255) {
    image.pixels = data + at;
    return true;
  }
  // Another range: scaled to 0..255, rounded, as the detection's thresholds expect.
  const std::uint8_t* in = data + at;
  for (std::size_t k = 0; k < std::size_t(w) * std::size_t(h); ++k) {
    const long long v =
        bytes == 2 ? (static_cast<long long>(in[2 * k]) << 8 | in[2 * k + 1]) : in[k];
    if (v > maxval)
      return fail(name, "pixel %zu is %lld, above the maxval %lld of its header", k, v, maxval);
    pixels_[k] = std::uint8_t((v * 255 + maxval / 2) / maxval);
  }
  image.pixels = pixels_.data();
  return true;
}

bool ImageReader::decode_png(const std::uint8_t* data, std::size_t size, const char* name,
                             GrayImage& image) {
  if (!zlib_->ok) return fail(name, "zlib could not be set up");
  z_stream& z = zlib_->stream;
  inflateReset(&z);
  int width = 0, height = 0, channels = 0, sample_bytes = 1;
  std::size_t raw_size = 0;
  bool header = false, in_idat = false, idat_done = false, stream_end = false;
  std::size_t at = 8;
  for (;;) {
    if (size - at < 12)
      return fail(name, "truncated: the file ends at byte %zu, before its IEND chunk", size);
    const std::uint32_t length = big_endian(data + at);
    const std::uint8_t* type = data + at + 4;
    for (int k = 0; k < 4; ++k)
      if (!((type[k] >= 'A' && type[k] <= 'Z') || (type[k] >= 'a' && type[k] <= 'z')))
        return fail(name, "byte %zu: not a PNG chunk type", at + 4);
    if (length > 0x7fffffffu)
      return fail(name, "the %.4s chunk at byte %zu has an invalid length", type, at);
    if (size - at - 12 < length)
      return fail(name, "truncated: the %.4s chunk at byte %zu needs %u bytes, the file has %zu",
                  type, at, length, size - at - 12);
    const std::uint8_t* payload = data + at + 8;
    const std::uint32_t stored = big_endian(payload + length);
    const std::uint32_t crc = std::uint32_t(crc32(crc32(0L, Z_NULL, 0), type, length + 4));
    if (crc != stored)
      return fail(name, "CRC error in the %.4s chunk at byte %zu (stored %08x, computed %08x)",
                  type, at, stored, crc);
    const bool is_idat = std::memcmp(type, "IDAT", 4) == 0;
    if (in_idat && !is_idat) idat_done = true;
    if (!header && std::memcmp(type, "IHDR", 4) != 0)
      return fail(name, "its first chunk is %.4s, not IHDR", type);
    if (std::memcmp(type, "IHDR", 4) == 0) {
      if (header) return fail(name, "a second IHDR chunk at byte %zu", at);
      if (length != 13) return fail(name, "its IHDR chunk has %u bytes, not 13", length);
      header = true;
      const std::uint32_t w = big_endian(payload), h = big_endian(payload + 4);
      const int depth = payload[8], colour = payload[9];
      if (w == 0 || h == 0) return fail(name, "%ux%u pixels: an image without pixels", w, h);
      if (w > std::uint32_t(max_width_) || h > std::uint32_t(max_height_))
        return fail(name, "%ux%u pixels: larger than the %dx%d this reads", w, h, max_width_,
                    max_height_);
      channels = colour == 0 ? 1 : colour == 2 ? 3 : colour == 4 ? 2 : colour == 6 ? 4 : 0;
      if (colour == 3)
        return fail(name, "a palette image (colour type 3): only grey, RGB and RGBA are read");
      if (channels == 0) return fail(name, "colour type %d is not PNG's", colour);
      if (depth != 8 && depth != 16)
        return fail(name, "bit depth %d: only 8- and 16-bit images are read", depth);
      sample_bytes = depth / 8;
      if (payload[10] != 0) return fail(name, "compression method %d is not PNG's", payload[10]);
      if (payload[11] != 0) return fail(name, "filter method %d is not PNG's", payload[11]);
      if (payload[12] == 1)
        return fail(name, "interlaced (Adam7): only non-interlaced images are read");
      if (payload[12] != 0) return fail(name, "interlace method %d is not PNG's", payload[12]);
      width = int(w);
      height = int(h);
      raw_size =
          (std::size_t(width) * std::size_t(channels * sample_bytes) + 1) * std::size_t(height);
      z.next_out = raw_.data();
      z.avail_out = uInt(raw_size + 1);  // room for one byte too many
    } else if (is_idat) {
      if (idat_done) return fail(name, "its IDAT chunks are not consecutive");
      in_idat = true;
      z.next_in = const_cast<std::uint8_t*>(payload);
      z.avail_in = length;
      while (z.avail_in > 0) {
        if (stream_end) return fail(name, "image data follow the end of their zlib stream");
        const int r = inflate(&z, Z_NO_FLUSH);
        if (z.total_out > raw_size)
          return fail(name, "its image data inflate to more than %dx%d pixels hold", width, height);
        if (r == Z_STREAM_END) {
          stream_end = true;
        } else if (r != Z_OK) {
          return fail(name, "corrupt image data (zlib: %s)", z.msg != nullptr ? z.msg : "error");
        }
      }
    } else if (std::memcmp(type, "IEND", 4) == 0) {
      break;
    } else if (type[0] >= 'A' && type[0] <= 'Z' && std::memcmp(type, "PLTE", 4) != 0) {
      return fail(name, "an unknown critical chunk %.4s at byte %zu", type, at);
    }
    at += 12 + std::size_t(length);
  }
  if (!in_idat) return fail(name, "no image data (IDAT chunk)");
  if (!stream_end)
    return fail(name, "truncated image data: the zlib stream is cut off after %lu of %zu bytes",
                z.total_out, raw_size);
  if (z.total_out != raw_size)
    return fail(name, "its image data inflate to %lu bytes; %dx%d pixels need %zu", z.total_out,
                width, height, raw_size);
  // Undo each row's filter in place (the row above is undone already), then take the luma. A
  // 16-bit sample's first byte is its most significant: the 8-bit value (v >> 8, as OpenCV's
  // IMREAD_GRAYSCALE reduces it); the filters work on whole pixels' bytes either way.
  const std::size_t bpp = std::size_t(channels * sample_bytes);
  const std::size_t stride = std::size_t(width) * bpp;
  for (std::size_t y = 0; y < std::size_t(height); ++y) {
    std::uint8_t* row = raw_.data() + y * (stride + 1);
    const int filter = row[0];
    std::uint8_t* p = row + 1;
    const std::uint8_t* up = y > 0 ? p - (stride + 1) : nullptr;
    switch (filter) {
      case 0:
        break;
      case 1:
        for (std::size_t x = bpp; x < stride; ++x) p[x] = std::uint8_t(p[x] + p[x - bpp]);
        break;
      case 2:
        if (up != nullptr)
          for (std::size_t x = 0; x < stride; ++x) p[x] = std::uint8_t(p[x] + up[x]);
        break;
      case 3:
        for (std::size_t x = 0; x < stride; ++x) {
          const int a = x >= bpp ? p[x - bpp] : 0, b = up != nullptr ? up[x] : 0;
          p[x] = std::uint8_t(p[x] + (a + b) / 2);
        }
        break;
      case 4:
        for (std::size_t x = 0; x < stride; ++x) {
          const int a = x >= bpp ? p[x - bpp] : 0, b = up != nullptr ? up[x] : 0;
          const int c = up != nullptr && x >= bpp ? up[x - bpp] : 0;
          p[x] = std::uint8_t(p[x] + paeth(a, b, c));
        }
        break;
      default:
        return fail(name, "row %zu has filter type %d, which PNG does not have", y, filter);
    }
    std::uint8_t* out = pixels_.data() + y * std::size_t(width);
    if (channels <= 2) {  // grey, or grey and alpha
      for (std::size_t x = 0; x < std::size_t(width); ++x) out[x] = p[x * bpp];
    } else {  // RGB(A): its luma
      for (std::size_t x = 0; x < std::size_t(width); ++x) {
        const std::uint8_t* c = p + x * bpp;
        out[x] = bt601_luma(c[0], c[sample_bytes], c[2 * sample_bytes]);
      }
    }
  }
  image.width = width;
  image.height = height;
  image.pixels = pixels_.data();
  return true;
}

// --- PngWriter ----------------------------------------------------------------------------------

struct PngWriter::Zlib {
  Arena arena{512 * 1024};  // deflate's state, window, hash chains and pending buffer
  z_stream stream{};
  bool ok = false;
  Zlib() {
    stream.zalloc = Arena::alloc;
    stream.zfree = Arena::free;
    stream.opaque = &arena;
    ok = deflateInit2(&stream, Z_BEST_SPEED, Z_DEFLATED, 15, 8, Z_DEFAULT_STRATEGY) == Z_OK;
  }
  ~Zlib() {
    if (ok) deflateEnd(&stream);
  }
};

namespace {
constexpr std::size_t kIdatAt = 8 + 25;  // signature, IHDR chunk
}

PngWriter::PngWriter(int max_width, int max_height)
    : max_width_(std::clamp(max_width, 1, kMaxImageSide)),
      max_height_(std::clamp(max_height, 1, kMaxImageSide)),
      zlib_(std::make_unique<Zlib>()) {
  filtered_.resize((std::size_t(max_width_) + 1) * std::size_t(max_height_));
  const std::size_t bound =
      zlib_->ok ? deflateBound(&zlib_->stream, uLong(filtered_.size())) : filtered_.size();
  out_.resize(kIdatAt + 12 + bound + 12);
}

PngWriter::~PngWriter() = default;

const std::uint8_t* PngWriter::encode(const GrayImage& image, std::size_t& size) {
  size = 0;
  if (!zlib_->ok) {
    std::snprintf(error_, sizeof error_, "zlib could not be set up");
    return nullptr;
  }
  if (image.width < 1 || image.height < 1 || image.width > max_width_ ||
      image.height > max_height_) {
    std::snprintf(error_, sizeof error_, "a %dx%d image: this writer takes 1x1 to %dx%d",
                  image.width, image.height, max_width_, max_height_);
    return nullptr;
  }
  const std::size_t w = std::size_t(image.width), h = std::size_t(image.height);
  for (std::size_t y = 0; y < h; ++y) {  // PNG's Sub filter: each byte less the one to its left
    const std::uint8_t* in = image.pixels + y * w;
    std::uint8_t* out = filtered_.data() + y * (w + 1);
    out[0] = 1;
    out[1] = in[0];
    for (std::size_t x = 1; x < w; ++x) out[x + 1] = std::uint8_t(in[x] - in[x - 1]);
  }
  std::uint8_t* o = out_.data();
  std::memcpy(o, kPngSignature, 8);
  put_big_endian(o + 8, 13);
  std::memcpy(o + 12, "IHDR", 4);
  put_big_endian(o + 16, std::uint32_t(w));
  put_big_endian(o + 20, std::uint32_t(h));
  const std::uint8_t rest[5] = {8, 0, 0, 0, 0};  // 8-bit grey, deflate, filter 0, progressive
  std::memcpy(o + 24, rest, 5);
  put_big_endian(o + 29, std::uint32_t(crc32(crc32(0L, Z_NULL, 0), o + 12, 17)));

  z_stream& z = zlib_->stream;
  deflateReset(&z);
  z.next_in = filtered_.data();
  z.avail_in = uInt((w + 1) * h);
  z.next_out = o + kIdatAt + 8;
  z.avail_out = uInt(out_.size() - kIdatAt - 8 - 4 - 12);
  if (deflate(&z, Z_FINISH) != Z_STREAM_END) {
    std::snprintf(error_, sizeof error_, "zlib: %s", z.msg != nullptr ? z.msg : "deflate failed");
    return nullptr;
  }
  const std::size_t n = std::size_t(z.total_out);
  put_big_endian(o + kIdatAt, std::uint32_t(n));
  std::memcpy(o + kIdatAt + 4, "IDAT", 4);
  put_big_endian(o + kIdatAt + 8 + n,
                 std::uint32_t(crc32(crc32(0L, Z_NULL, 0), o + kIdatAt + 4, uInt(n + 4))));
  std::uint8_t* end = o + kIdatAt + 12 + n;
  put_big_endian(end, 0);
  std::memcpy(end + 4, "IEND", 4);
  put_big_endian(end + 8, std::uint32_t(crc32(crc32(0L, Z_NULL, 0), end + 4, 4)));
  size = kIdatAt + 12 + n + 12;
  return out_.data();
}

}  // namespace mirrorcal::io
