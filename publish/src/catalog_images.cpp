#include "carousel/publish/catalog_images.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <set>

#include <webp/demux.h>
#include <webp/encode.h>
#include <webp/mux.h>
#include <zip.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"

namespace carousel::publish {

std::string CutoutBackdropName(CutoutBackdrop backdrop) {
  return backdrop == CutoutBackdrop::kWhite ? "white" : "transparent";
}

CutoutBackdrop ParseCutoutBackdrop(const std::string& name) {
  if (name == "white") return CutoutBackdrop::kWhite;
  if (name == "transparent") return CutoutBackdrop::kTransparent;
  throw InvalidArgument("cut-out backdrop must be 'white' or 'transparent', not '" + name + "'");
}

void CutoutOptions::Validate() const {
  CAROUSEL_THROW_IF(!(margin >= 0.0 && margin <= 0.45), InvalidArgument,
                    "cut-out margin must be in [0, 0.45], got " << margin);
  CAROUSEL_THROW_IF(size < 0 || size > 16384, InvalidArgument,
                    "cut-out size must be 0 (as cropped) or 1..16384 pixels, got " << size);
}

cv::Mat CutOut(const cv::Mat& photo, const cv::Mat& alpha, const CutoutOptions& options) {
  options.Validate();
  CAROUSEL_THROW_IF(photo.empty() || photo.type() != CV_8UC3, InvalidArgument,
                    "cut-out: the photo must be 8-bit BGR");
  CAROUSEL_THROW_IF(alpha.type() != CV_8UC1 || alpha.size() != photo.size(), InvalidArgument,
                    "cut-out: the mask must be 8-bit, " << photo.cols << " x " << photo.rows
                                                        << " like the photo");
  const cv::Rect box = cv::boundingRect(alpha >= 128);
  CAROUSEL_THROW_IF(box.area() == 0, InvalidArgument, "cut-out: the mask has no object pixel");
  // The square around the box's centre.
  const double long_side = std::max(box.width, box.height);
  const int side =
      std::max(1, static_cast<int>(std::lround(long_side / (1.0 - 2.0 * options.margin))));
  const int x0 = static_cast<int>(std::lround(box.x + 0.5 * box.width - 0.5 * side));
  const int y0 = static_cast<int>(std::lround(box.y + 0.5 * box.height - 0.5 * side));
  const cv::Rect square(x0, y0, side, side);
  const cv::Rect inside = square & cv::Rect(0, 0, photo.cols, photo.rows);
  const cv::Rect target(inside.x - x0, inside.y - y0, inside.width, inside.height);

  cv::Mat result;
  if (options.backdrop == CutoutBackdrop::kTransparent) {
    result = cv::Mat(side, side, CV_8UC4, cv::Scalar(255, 255, 255, 0));
    cv::Mat bgra;
    cv::cvtColor(photo(inside), bgra, cv::COLOR_BGR2BGRA);
    const int to_alpha[] = {0, 3};
    const cv::Mat a = alpha(inside);
    cv::mixChannels(&a, 1, &bgra, 1, to_alpha, 1);
    bgra.copyTo(result(target));
  } else {
    // photo x a + white x (1 - a), in 8-bit sRGB as the masks' soft edges were made.
    result = cv::Mat(side, side, CV_8UC3, cv::Scalar(255, 255, 255));
    cv::Mat a;
    cv::Mat a3;
    alpha(inside).convertTo(a, CV_32F, 1.0 / 255.0);
    cv::merge(std::vector<cv::Mat>{a, a, a}, a3);
    cv::Mat colour;
    photo(inside).convertTo(colour, CV_32FC3);
    cv::Mat blended = colour.mul(a3) + (cv::Scalar::all(1.0) - a3) * 255.0;
    blended.convertTo(result(target), CV_8UC3);
  }
  if (options.size > 0 && options.size != side) {
    cv::Mat scaled;
    cv::resize(result, scaled, cv::Size(options.size, options.size), 0, 0,
               options.size < side ? cv::INTER_AREA : cv::INTER_CUBIC);
    result = scaled;
  }
  return result;
}

std::vector<std::uint8_t> EncodeCatalogImage(const cv::Mat& image, int jpeg_quality,
                                             const std::filesystem::path& name) {
  std::vector<std::uint8_t> bytes;
  const bool ok =
      image.channels() == 4
          ? cv::imencode(".png", image, bytes, {cv::IMWRITE_PNG_COMPRESSION, 6})
          : cv::imencode(".jpg", image, bytes, {cv::IMWRITE_JPEG_QUALITY, jpeg_quality});
  if (!ok || bytes.empty()) throw IoError(name, "the image could not be encoded");
  return bytes;
}

std::vector<std::string> SpinSetNames(const std::string& stem_in, int frames,
                                      const std::string& extension) {
  std::string stem;
  for (const char c : stem_in) {
    const bool keep = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
                      c == '.' || c == '_' || c == '-';
    stem += keep ? c : '-';
  }
  if (stem.empty()) stem = "product";
  const int digits = frames >= 100 ? 3 : 2;
  std::vector<std::string> names;
  for (int i = 1; i <= frames; ++i) {
    char number[16];
    std::snprintf(number, sizeof number, "%0*d", digits, i);
    names.push_back(stem + "_" + number + extension);
  }
  return names;
}

namespace {

struct AnimEncoderDeleter {
  void operator()(WebPAnimEncoder* e) const { WebPAnimEncoderDelete(e); }
};
struct AnimDecoderDeleter {
  void operator()(WebPAnimDecoder* d) const { WebPAnimDecoderDelete(d); }
};

}  // namespace

std::vector<std::uint8_t> EncodeAnimatedWebp(const std::vector<cv::Mat>& frames, int frame_ms,
                                             int quality, const std::filesystem::path& name) {
  CAROUSEL_THROW_IF(frames.empty(), InvalidArgument, "animated WebP: no frames");
  CAROUSEL_THROW_IF(frame_ms <= 0, InvalidArgument, "animated WebP: frame time must be > 0 ms");
  CAROUSEL_THROW_IF(quality < 0 || quality > 100, InvalidArgument,
                    "animated WebP: quality must be 0..100, got " << quality);
  const cv::Size size = frames.front().size();
  const int type = frames.front().type();
  CAROUSEL_THROW_IF(type != CV_8UC3 && type != CV_8UC4, InvalidArgument,
                    "animated WebP: frames must be 8-bit BGR or BGRA");
  for (const cv::Mat& f : frames)
    CAROUSEL_THROW_IF(f.size() != size || f.type() != type, InvalidArgument,
                      "animated WebP: every frame must have the first one's size and type");
  WebPAnimEncoderOptions encoder_options;
  if (!WebPAnimEncoderOptionsInit(&encoder_options))
    throw IoError(name, "libwebp: version mismatch");
  encoder_options.anim_params.loop_count = 0;
  encoder_options.anim_params.bgcolor = 0xFFFFFFFF;
  std::unique_ptr<WebPAnimEncoder, AnimEncoderDeleter> encoder(
      WebPAnimEncoderNew(size.width, size.height, &encoder_options));
  if (!encoder) throw IoError(name, "libwebp: cannot create the animation encoder");
  WebPConfig config;
  if (!WebPConfigInit(&config)) throw IoError(name, "libwebp: version mismatch");
  config.quality = static_cast<float>(quality);
  config.method = 4;
  int timestamp = 0;
  for (const cv::Mat& frame : frames) {
    WebPPicture picture;
    if (!WebPPictureInit(&picture)) throw IoError(name, "libwebp: version mismatch");
    picture.use_argb = 1;
    picture.width = size.width;
    picture.height = size.height;
    const cv::Mat pixels = frame.isContinuous() ? frame : frame.clone();
    const int ok = type == CV_8UC4
                       ? WebPPictureImportBGRA(&picture, pixels.data, static_cast<int>(pixels.step))
                       : WebPPictureImportBGR(&picture, pixels.data, static_cast<int>(pixels.step));
    const bool added = ok && WebPAnimEncoderAdd(encoder.get(), &picture, timestamp, &config);
    WebPPictureFree(&picture);
    if (!added)
      throw IoError(name, std::string("libwebp: a frame could not be encoded: ") +
                              WebPAnimEncoderGetError(encoder.get()));
    timestamp += frame_ms;
  }
  if (!WebPAnimEncoderAdd(encoder.get(), nullptr, timestamp, nullptr))
    throw IoError(name, "libwebp: the animation could not be finished");
  WebPData data;
  WebPDataInit(&data);
  if (!WebPAnimEncoderAssemble(encoder.get(), &data))
    throw IoError(name, std::string("libwebp: the animation could not be assembled: ") +
                            WebPAnimEncoderGetError(encoder.get()));
  std::vector<std::uint8_t> bytes(data.bytes, data.bytes + data.size);
  WebPDataClear(&data);
  return bytes;
}

AnimatedImage DecodeAnimatedWebp(const std::vector<std::uint8_t>& bytes,
                                 const std::filesystem::path& name) {
  WebPData data{bytes.data(), bytes.size()};
  WebPAnimDecoderOptions options;
  if (!WebPAnimDecoderOptionsInit(&options)) throw FormatError(name, "libwebp: version mismatch");
  options.color_mode = MODE_BGRA;
  options.use_threads = 0;
  std::unique_ptr<WebPAnimDecoder, AnimDecoderDeleter> decoder(WebPAnimDecoderNew(&data, &options));
  if (!decoder) throw FormatError(name, "not a WebP image");
  WebPAnimInfo info;
  if (!WebPAnimDecoderGetInfo(decoder.get(), &info))
    throw FormatError(name, "the WebP animation's header cannot be read");
  AnimatedImage result;
  result.loop_count = static_cast<int>(info.loop_count);
  while (WebPAnimDecoderHasMoreFrames(decoder.get())) {
    std::uint8_t* pixels = nullptr;
    int timestamp = 0;
    if (!WebPAnimDecoderGetNext(decoder.get(), &pixels, &timestamp))
      throw FormatError(name, "frame " + std::to_string(result.frames.size() + 1) +
                                  " of the WebP animation cannot be decoded");
    result.frames.push_back(cv::Mat(static_cast<int>(info.canvas_height),
                                    static_cast<int>(info.canvas_width), CV_8UC4, pixels)
                                .clone());
    result.timestamps_ms.push_back(timestamp);
  }
  return result;
}

namespace {

struct ZipDiscarder {
  void operator()(zip_t* z) const { zip_discard(z); }
};
struct ZipFileCloser {
  void operator()(zip_file_t* f) const { zip_fclose(f); }
};

std::string ZipErrorText(int code) {
  zip_error_t error;
  zip_error_init_with_code(&error, code);
  std::string text = zip_error_strerror(&error);
  zip_error_fini(&error);
  return text;
}

}  // namespace

std::vector<std::uint8_t> ZipArchive(const std::vector<ZipEntry>& entries,
                                     const std::filesystem::path& name) {
  std::set<std::string> names;
  for (const ZipEntry& e : entries) {
    CAROUSEL_THROW_IF(e.name.empty(), InvalidArgument, "zip: an entry has no name");
    CAROUSEL_THROW_IF(!names.insert(e.name).second, InvalidArgument,
                      "zip: the entry name '" << e.name << "' appears twice");
  }
  zip_error_t error;
  zip_error_init(&error);
  zip_source_t* buffer = zip_source_buffer_create(nullptr, 0, 0, &error);
  if (!buffer) throw IoError(name, "libzip: " + std::string(zip_error_strerror(&error)));
  zip_t* archive_raw = zip_open_from_source(buffer, ZIP_TRUNCATE, &error);
  if (!archive_raw) {
    zip_source_free(buffer);
    throw IoError(name, "libzip: " + std::string(zip_error_strerror(&error)));
  }
  zip_error_fini(&error);
  // The buffer outlives the archive: its bytes are read after zip_close.
  zip_source_keep(buffer);
  std::unique_ptr<zip_t, ZipDiscarder> archive(archive_raw);
  constexpr time_t kFixedTime = 946684800;  // 2000-01-01T00:00:00Z
  auto fail = [&](const std::string& what) {
    archive.reset();
    zip_source_free(buffer);
    throw IoError(name, "libzip: " + what);
  };
  for (const ZipEntry& e : entries) {
    zip_source_t* source = zip_source_buffer(archive.get(), e.bytes.data(), e.bytes.size(), 0);
    if (!source) fail(zip_strerror(archive.get()));
    const zip_int64_t index =
        zip_file_add(archive.get(), e.name.c_str(), source, ZIP_FL_ENC_UTF_8 | ZIP_FL_OVERWRITE);
    if (index < 0) {
      zip_source_free(source);
      fail(zip_strerror(archive.get()));
    }
    const auto i = static_cast<zip_uint64_t>(index);
    if (zip_set_file_compression(archive.get(), i, ZIP_CM_STORE, 0) != 0 ||
        zip_file_set_mtime(archive.get(), i, kFixedTime, 0) != 0)
      fail(zip_strerror(archive.get()));
  }
  if (zip_close(archive.get()) != 0) fail(zip_strerror(archive.get()));
  (void)archive.release();  // closed
  std::vector<std::uint8_t> bytes;
  zip_stat_t stat;
  if (zip_source_stat(buffer, &stat) != 0 || zip_source_open(buffer) != 0) {
    zip_source_free(buffer);
    throw IoError(name, "libzip: the archive in memory cannot be read");
  }
  bytes.resize(static_cast<std::size_t>(stat.size));
  const zip_int64_t read = zip_source_read(buffer, bytes.data(), stat.size);
  zip_source_close(buffer);
  zip_source_free(buffer);
  if (read != static_cast<zip_int64_t>(stat.size))
    throw IoError(name, "libzip: the archive in memory is short");
  return bytes;
}

std::vector<ZipEntry> ReadZip(const std::filesystem::path& path) {
  RequireReadableFile(path);
  int code = 0;
  std::unique_ptr<zip_t, ZipDiscarder> archive(zip_open(path.c_str(), ZIP_RDONLY, &code));
  if (!archive) throw FormatError(path, "not a readable zip archive: " + ZipErrorText(code));
  std::vector<ZipEntry> entries;
  const zip_int64_t count = zip_get_num_entries(archive.get(), 0);
  for (zip_int64_t i = 0; i < count; ++i) {
    const auto index = static_cast<zip_uint64_t>(i);
    zip_stat_t stat;
    if (zip_stat_index(archive.get(), index, 0, &stat) != 0)
      throw FormatError(path, "entry " + std::to_string(i) + ": " + zip_strerror(archive.get()));
    std::unique_ptr<zip_file_t, ZipFileCloser> file(zip_fopen_index(archive.get(), index, 0));
    if (!file) throw FormatError(path, std::string(stat.name) + ": " + zip_strerror(archive.get()));
    ZipEntry entry;
    entry.name = stat.name;
    entry.bytes.resize(static_cast<std::size_t>(stat.size));
    if (zip_fread(file.get(), entry.bytes.data(), stat.size) != static_cast<zip_int64_t>(stat.size))
      throw FormatError(path, entry.name + ": the entry is damaged");
    entries.push_back(std::move(entry));
  }
  return entries;
}

}  // namespace carousel::publish
