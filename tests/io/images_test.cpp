// The image reader and writer of recordings (io/images.hpp): round trips through the PNG
// writer, PNG files put together here with zlib (each colour type and filter), binary PGM, and
// every kind of damaged or unsupported file, each refused with a message naming it.
#include <gtest/gtest.h>
#include <zlib.h>

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "mirrorcal/io/images.hpp"
#include "recording_support.hpp"

using namespace rectest;

namespace {

using Bytes = std::vector<std::uint8_t>;

void put32(Bytes& b, std::uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) b.push_back(std::uint8_t(v >> s));
}

// A chunk with its length and CRC (crc_delta added to the right CRC: a damaged one).
void chunk(Bytes& png, const char* type, const Bytes& data, std::uint32_t crc_delta = 0) {
  put32(png, std::uint32_t(data.size()));
  Bytes body(type, type + 4);
  body.insert(body.end(), data.begin(), data.end());
  png.insert(png.end(), body.begin(), body.end());
  put32(png, std::uint32_t(crc32(0, body.data(), uInt(body.size()))) + crc_delta);
}

Bytes compress_all(const Bytes& raw) {
  uLongf n = compressBound(uLong(raw.size()));
  Bytes out(n);
  EXPECT_EQ(compress2(out.data(), &n, raw.data(), uLong(raw.size()), 9), Z_OK);
  out.resize(n);
  return out;
}

struct PngSpec {
  std::uint32_t width = 4, height = 3;
  int depth = 8, colour = 0, interlace = 0;
};

// A PNG of the given header around the given raw (filtered) scanlines, split over idat_parts
// IDAT chunks.
Bytes make_png(const PngSpec& h, const Bytes& raw, int idat_parts = 1) {
  Bytes png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  Bytes ihdr;
  put32(ihdr, h.width);
  put32(ihdr, h.height);
  ihdr.insert(ihdr.end(),
              {std::uint8_t(h.depth), std::uint8_t(h.colour), 0, 0, std::uint8_t(h.interlace)});
  chunk(png, "IHDR", ihdr);
  chunk(png, "tEXt", Bytes{'C', 'o', 'm', 'm', 'e', 'n', 't', 0, 'h', 'i'});  // ancillary: skipped
  const Bytes z = compress_all(raw);
  const std::size_t part = z.size() / std::size_t(idat_parts) + 1;
  for (std::size_t at = 0; at < z.size(); at += part)
    chunk(png, "IDAT",
          Bytes(z.begin() + long(at), z.begin() + long(std::min(z.size(), at + part))));
  chunk(png, "IEND", {});
  return png;
}

Bytes random_bytes(std::size_t n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  Bytes b(n);
  for (auto& x : b) x = std::uint8_t(rng() & 0xff);
  return b;
}

// PNG's filters applied as the standard defines them, to each row of pixels (bpp bytes each).
Bytes filter_rows(const Bytes& pixels, std::size_t stride, std::size_t rows, std::size_t bpp,
                  int filter_of_row(std::size_t)) {
  Bytes raw;
  for (std::size_t y = 0; y < rows; ++y) {
    const int f = filter_of_row(y);
    raw.push_back(std::uint8_t(f));
    for (std::size_t x = 0; x < stride; ++x) {
      const int a = x >= bpp ? pixels[y * stride + x - bpp] : 0;
      const int b = y > 0 ? pixels[(y - 1) * stride + x] : 0;
      const int c = x >= bpp && y > 0 ? pixels[(y - 1) * stride + x - bpp] : 0;
      const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
      const int paeth = pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
      const int pred = f == 0 ? 0 : f == 1 ? a : f == 2 ? b : f == 3 ? (a + b) / 2 : paeth;
      raw.push_back(std::uint8_t(pixels[y * stride + x] - pred));
    }
  }
  return raw;
}

// Decodes bytes as file "name"; the error message, or "" on success (image then holds it).
std::string decode(mc::io::ImageReader& r, const Bytes& b, mc::io::GrayImage& image,
                   const char* name = "cam0/data/42.png") {
  return r.decode(b.data(), b.size(), name, image) ? "" : r.error();
}

::testing::AssertionResult refused(mc::io::ImageReader& r, const Bytes& b, const std::string& why) {
  mc::io::GrayImage image;
  const std::string e = decode(r, b, image);
  if (e.empty()) return ::testing::AssertionFailure() << "decoded";
  if (e.rfind("cam0/data/42.png: ", 0) != 0)
    return ::testing::AssertionFailure() << "does not name the file: " << e;
  if (e.find(why) == std::string::npos)
    return ::testing::AssertionFailure() << "says '" << e << "', not '" << why << "'";
  return ::testing::AssertionSuccess() << e;
}

}  // namespace

TEST(Images, PngWriterRoundTripsThroughTheReader) {
  mc::io::PngWriter writer(641, 480);
  mc::io::ImageReader reader(641, 480);
  for (const auto& [w, h] : {std::pair{1, 1}, {641, 3}, {640, 480}, {7, 300}}) {
    const Bytes pixels = random_bytes(std::size_t(w) * std::size_t(h), std::uint32_t(w * h));
    std::size_t n = 0;
    const std::uint8_t* png = writer.encode({w, h, pixels.data()}, n);
    ASSERT_NE(png, nullptr) << writer.error();
    mc::io::GrayImage back;
    ASSERT_TRUE(reader.decode(png, n, "x.png", back)) << reader.error();
    ASSERT_EQ(back.width, w);
    ASSERT_EQ(back.height, h);
    EXPECT_TRUE(std::equal(pixels.begin(), pixels.end(), back.pixels)) << w << "x" << h;
  }
  // Larger than it was made for: refused, not overrun.
  const Bytes big(642 * 2, 0);
  std::size_t n = 0;
  EXPECT_EQ(writer.encode({642, 2, big.data()}, n), nullptr);
  EXPECT_NE(std::string(writer.error()).find("642x2"), std::string::npos) << writer.error();
}

TEST(Images, ReadsEveryFilterAndColourTypeAsLuma) {
  const std::size_t w = 9, h = 10;
  mc::io::ImageReader reader(16, 16);
  // channels per colour type: grey 1, grey+alpha 2, RGB 3, RGBA 4; 8 or 16 bits a sample (the
  // first byte of a 16-bit sample is its upper one, the 8-bit value read).
  for (const int depth : {8, 16})
    for (const auto& [colour, channels] : {std::pair{0, 1}, {4, 2}, {2, 3}, {6, 4}}) {
      const std::size_t sample = std::size_t(depth / 8), bpp = std::size_t(channels) * sample;
      const Bytes pixels = random_bytes(w * h * bpp, std::uint32_t(colour + 7 + depth));
      const Bytes raw =
          filter_rows(pixels, w * bpp, h, bpp, [](std::size_t y) { return int(y % 5); });
      PngSpec spec;
      spec.width = w;
      spec.height = h;
      spec.colour = colour;
      spec.depth = depth;
      mc::io::GrayImage image;
      ASSERT_EQ(decode(reader, make_png(spec, raw, 3), image), "")
          << "colour type " << colour << ", " << depth << " bits";
      ASSERT_EQ(image.width, int(w));
      ASSERT_EQ(image.height, int(h));
      for (std::size_t k = 0; k < w * h; ++k) {
        const std::uint8_t* p = &pixels[k * bpp];
        // Luma by the BT.601 weights in floating point: the reader's integer weights are within
        // 1.
        const double luma =
            channels >= 3 ? 0.299 * p[0] + 0.587 * p[sample] + 0.114 * p[2 * sample] : p[0];
        ASSERT_NEAR(image.pixels[k], luma, channels >= 3 ? 1.0 : 0.0)
            << "colour " << colour << ", " << depth << " bits, at " << k;
      }
    }
}

TEST(Images, ReadsBinaryPgm) {
  mc::io::ImageReader reader(8, 8);
  const std::string text = "P5\n# a comment\n3 2 # another\n255\n";
  Bytes pgm(text.begin(), text.end());
  for (std::uint8_t v : {0, 1, 2, 128, 254, 255}) pgm.push_back(v);
  mc::io::GrayImage image;
  ASSERT_EQ(decode(reader, pgm, image, "a.pgm"), "");
  ASSERT_EQ(image.width, 3);
  ASSERT_EQ(image.height, 2);
  EXPECT_EQ(image.pixels[3], 128);
  EXPECT_EQ(image.pixels[5], 255);
  // 16 bits a sample (upper byte first) and other ranges: scaled to 0..255, rounded.
  const std::string t16 = "P5 3 2 65535\n";
  Bytes sixteen(t16.begin(), t16.end());
  for (const std::uint16_t v : {0, 65535, 32768, 0x1234, 257, 65278}) {
    sixteen.push_back(std::uint8_t(v >> 8));
    sixteen.push_back(std::uint8_t(v & 0xff));
  }
  ASSERT_EQ(decode(reader, sixteen, image, "b.pgm"), "");
  const int expect16[] = {0, 255, 128, 18, 1, 254};  // round(v * 255 / 65535)
  for (int k = 0; k < 6; ++k) EXPECT_EQ(image.pixels[k], expect16[k]) << k;
  const std::string t15 = "P5 3 1 15\n";
  Bytes fifteen(t15.begin(), t15.end());
  for (std::uint8_t v : {0, 7, 15}) fifteen.push_back(v);
  ASSERT_EQ(decode(reader, fifteen, image, "c.pgm"), "");
  EXPECT_EQ(image.pixels[1], 119);  // round(7 * 255 / 15)
  EXPECT_EQ(image.pixels[2], 255);
  fifteen.back() = 16;
  EXPECT_TRUE(refused(reader, fifteen, "pixel 2 is 16, above the maxval 15"));
  const std::string t0 = "P5 1 1 0\n";
  EXPECT_TRUE(refused(reader, Bytes(t0.begin(), t0.end()), "maxval 0"));
  Bytes cut(pgm.begin(), pgm.end() - 1);
  EXPECT_TRUE(refused(reader, cut, "truncated: 5 of the 6 pixel bytes"));
  const std::string plain = "P2 1 1 255 7\n";
  EXPECT_TRUE(refused(reader, Bytes(plain.begin(), plain.end()), "plain (ASCII) PGM"));
  const std::string huge = "P5 100000 100000 255\n";
  EXPECT_TRUE(refused(reader, Bytes(huge.begin(), huge.end()), "larger than the 8x8"));
}

TEST(Images, DamagedAndUnsupportedPngsAreRefusedNamingTheFile) {
  mc::io::ImageReader reader(640, 480);
  const PngSpec good_spec;
  const Bytes pixels = random_bytes(4 * 3, 3);
  const Bytes raw = filter_rows(pixels, 4, 3, 1, [](std::size_t) { return 0; });
  const Bytes good = make_png(good_spec, raw);
  mc::io::GrayImage image;
  ASSERT_EQ(decode(reader, good, image), "");

  // Cut anywhere: within the signature, a chunk's header, its data, or before IEND.
  for (std::size_t keep :
       {std::size_t(5), std::size_t(20), std::size_t(40), good.size() - 12, good.size() - 1})
    EXPECT_TRUE(refused(reader, Bytes(good.begin(), good.begin() + long(keep)), "truncated"))
        << keep;
  // A flipped bit in the image data: its chunk's CRC says so.
  Bytes flipped = good;
  flipped[good.size() - 12 - 4 - 2] ^= 0x10;
  EXPECT_TRUE(refused(reader, flipped, "CRC error in the IDAT chunk"));
  // A wrong CRC on the header.
  Bytes bad_crc = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  Bytes ihdr(good.begin() + 16, good.begin() + 29);
  chunk(bad_crc, "IHDR", ihdr, 1);
  EXPECT_TRUE(refused(reader, bad_crc, "CRC error in the IHDR chunk"));

  PngSpec spec = good_spec;
  spec.depth = 4;
  EXPECT_TRUE(
      refused(reader, make_png(spec, raw), "bit depth 4: only 8- and 16-bit images are read"));
  spec = good_spec;
  spec.interlace = 1;
  EXPECT_TRUE(refused(reader, make_png(spec, raw), "interlaced (Adam7)"));
  spec = good_spec;
  spec.colour = 3;
  EXPECT_TRUE(refused(reader, make_png(spec, raw), "palette"));
  // Huge dimensions: refused from the header, before anything is inflated or allocated.
  spec = good_spec;
  spec.width = spec.height = 0x7fffffff;
  EXPECT_TRUE(refused(reader, make_png(spec, raw),
                      "2147483647x2147483647 pixels: larger than "
                      "the 640x480"));
  spec = good_spec;
  spec.width = 641;
  EXPECT_TRUE(refused(reader, make_png(spec, raw), "larger than the 640x480"));
  // Fewer or more pixels in the data than the header says.
  spec = good_spec;
  spec.height = 4;
  EXPECT_TRUE(refused(reader, make_png(spec, raw), "inflate to 15 bytes; 4x4 pixels need 20"));
  spec.height = 2;
  EXPECT_TRUE(refused(reader, make_png(spec, raw), "inflate to more than 4x2 pixels hold"));
  // A filter type PNG does not have.
  Bytes bad_filter = raw;
  bad_filter[5] = 7;
  EXPECT_TRUE(refused(reader, make_png(good_spec, bad_filter), "row 1 has filter type 7"));
  // Not an image at all.
  const std::string text = "#timestamp [ns],filename\n";
  EXPECT_TRUE(refused(reader, Bytes(text.begin(), text.end()), "neither a PNG nor"));
}

TEST(Images, ReadFilesNamesThemAndBoundsTheirSize) {
  const TempDir tmp("images-read");
  mc::io::ImageReader reader(4, 3);
  mc::io::GrayImage image;
  const std::string missing = tmp.path + "/1.png";
  EXPECT_FALSE(reader.read(missing.c_str(), image));
  EXPECT_EQ(std::string(reader.error()).rfind(missing + ": cannot open", 0), 0u) << reader.error();
  const std::string big = tmp.path + "/2.png";
  spit(big, std::string(reader.max_file_bytes() + 1, 'x'));
  EXPECT_FALSE(reader.read(big.c_str(), image));
  EXPECT_NE(std::string(reader.error()).find(big + ": "), std::string::npos);
  EXPECT_NE(std::string(reader.error()).find("larger than any image of at most 4x3"),
            std::string::npos)
      << reader.error();
  const std::string dir = tmp.path;
  EXPECT_FALSE(reader.read(dir.c_str(), image));
  EXPECT_NE(std::string(reader.error()).find("not a regular file"), std::string::npos);
  mc::io::PngWriter writer(4, 3);
  const Bytes pixels = random_bytes(12, 9);
  std::size_t n = 0;
  const std::uint8_t* png = writer.encode({4, 3, pixels.data()}, n);
  ASSERT_NE(png, nullptr);
  const std::string good = tmp.path + "/3.png";
  spit(good, std::string(reinterpret_cast<const char*>(png), n));
  ASSERT_TRUE(reader.read(good.c_str(), image)) << reader.error();
  EXPECT_TRUE(std::equal(pixels.begin(), pixels.end(), image.pixels));
}

// A recording's images as calibrate reads them: without cam0/data/ it says so; an image that cannot
// be read, or has another size than camchain.yaml's, is skipped and named, and the rest go on.
TEST(Images, UnreadableImagesOfARecordingAreNamedAndSkipped) {
  const TempDir tmp("images-recording");
  const mc::sim::Scenario s = short_scenario(0.5);
  const mc::sim::SimData data = mc::sim::simulate(s, 5);
  write_recording(tmp.path, s, data, 5);
  mc::io::Recording rec;
  std::string err;
  EXPECT_FALSE(mc::io::open_recording(tmp.path, mc::sim::kPaperMarkers, rec, err, true));
  EXPECT_EQ(err.rfind(tmp.path + "/mav0/cam0/data: no such folder", 0), 0u) << err;

  // Every frame's image: grey PNG, but frame 3 a 4-bit one, frame 5 of 320x240, frame 7 missing.
  const std::string images = tmp.path + "/mav0/cam0/data";
  fs::create_directories(images);
  mc::io::PngWriter writer(640, 480);
  const Bytes pixels = random_bytes(640 * 480, 11);
  std::string deep;
  for (std::size_t k = 0; k < data.frames.size(); ++k) {
    const std::string path = images + "/" + std::to_string(data.frames[k].t_ns) + ".png";
    if (k == 7) continue;
    if (k == 3) {
      PngSpec spec;
      spec.depth = 4;
      const Bytes png =
          make_png(spec, filter_rows(random_bytes(6, 1), 2, 3, 1, [](std::size_t) { return 0; }));
      spit(path, std::string(png.begin(), png.end()));
      deep = path;
      continue;
    }
    const int w = k == 5 ? 320 : 640, h = k == 5 ? 240 : 480;
    std::size_t n = 0;
    const std::uint8_t* png = writer.encode({w, h, pixels.data()}, n);
    ASSERT_NE(png, nullptr);
    spit(path, std::string(reinterpret_cast<const char*>(png), n));
  }
  ASSERT_TRUE(mc::io::open_recording(tmp.path, mc::sim::kPaperMarkers, rec, err, true)) << err;
  {
    const auto source = rec.streams->open_images();
    ASSERT_NE(source, nullptr);
    mc::hal::FrameView view;
    std::size_t delivered = 0;
    while (source->poll(view) == mc::hal::SourceStatus::kOk) {
      ++delivered;
      ASSERT_EQ(view.width, 640);
      EXPECT_TRUE(std::equal(pixels.begin(), pixels.end(), view.data));
    }
    EXPECT_EQ(delivered, data.frames.size() - 3);
    EXPECT_STREQ(source->error(), "");
  }
  const mc::io::ImageLog* log = rec.streams->image_log();
  ASSERT_NE(log, nullptr);
  EXPECT_EQ(log->unreadable, 3u);
  ASSERT_EQ(log->kept, 3);
  const std::string name5 = images + "/" + std::to_string(data.frames[5].t_ns) + ".png";
  const std::string name7 = images + "/" + std::to_string(data.frames[7].t_ns) + ".png";
  EXPECT_EQ(std::string(log->messages[0].data()),
            deep + ": bit depth 4: only 8- and 16-bit images are read");
  EXPECT_EQ(std::string(log->messages[1].data()),
            name5 + ": 320x240 pixels; camchain.yaml's camera has 640x480");
  EXPECT_EQ(std::string(log->messages[2].data()).rfind(name7 + ": cannot open", 0), 0u);
}
