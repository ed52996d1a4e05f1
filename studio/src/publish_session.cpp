#include "carousel/studio/publish_session.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <set>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/image_io.h"
#include "carousel/core/json.h"
#include "carousel/core/options_json.h"
#include "carousel/core/timer.h"
#include "carousel/publish/renders.h"
#include "carousel/publish/report_page.h"
#include "carousel/publish/site.h"
#include "carousel/publish/viewer_page.h"

#include "held_out_reference.h"

namespace carousel::studio {

const OptionTable<PublishSessionOptions>& PublishSessionOptions::Fields() {
  using O = PublishSessionOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Include(&O::web, publish::WebGlbOptions::Fields());
    t.Add(&O::poster_size, {.name = "poster-size",
                            .help = "side of the viewer page's poster (the hero shot, smaller)",
                            .unit = "px",
                            .min = 64,
                            .max = 4096,
                            .advanced = true});
    t.Add(&O::hero_size, {.name = "hero-size",
                          .help = "side of the hero shot",
                          .unit = "px",
                          .min = 64,
                          .max = 8192});
    t.Add(&O::cutouts, {.name = "cutouts",
                        .help = "cut out every photo through its mask (model/cutouts/)",
                        .negative_name = "no-cutouts"});
    t.AddChoice(&O::backdrop,
                {.name = "cutout-backdrop", .help = "what the cut-outs and the 360° set stand on"},
                {{"white", publish::CutoutBackdrop::kWhite},
                 {"transparent", publish::CutoutBackdrop::kTransparent}});
    t.Add(&O::cutout_size, {.name = "cutout-size",
                            .help = "side of the square cut-outs",
                            .unit = "px",
                            .min = 64,
                            .max = 16384,
                            .special = 0.0,
                            .special_meaning = "as cropped"});
    t.Add(&O::cutout_margin, {.name = "cutout-margin",
                              .help = "gap around the object, a fraction of the image side",
                              .min = 0.0,
                              .max = 0.45,
                              .advanced = true});
    t.Add(&O::spin_frames, {.name = "spin-frames",
                            .help = "images of the 360° set and the spin: 24, 48 or 72",
                            .min = 24,
                            .max = 72,
                            .special = 0.0,
                            .special_meaning = "none"});
    t.Add(&O::spin_size, {.name = "spin-size",
                          .help = "side of the 360° set's images and the spin",
                          .unit = "px",
                          .min = 64,
                          .max = 4096});
    t.Add(&O::spin_frame_ms, {.name = "spin-frame-time",
                              .help = "how long the spin shows each frame",
                              .unit = "ms",
                              .min = 10,
                              .max = 5000,
                              .advanced = true});
    t.Add(&O::webp_quality, {.name = "spin-webp-quality",
                             .help = "WebP quality of the spin",
                             .min = 0,
                             .max = 100,
                             .advanced = true});
    t.Add(&O::jpeg_quality, {.name = "catalog-jpeg-quality",
                             .help = "JPEG quality of the hero shot, cut-outs and 360° set",
                             .min = 1,
                             .max = 100,
                             .advanced = true});
    t.Add(&O::report, {.name = "report-page",
                       .help = "the report page model/report.html",
                       .negative_name = "no-report-page"});
    return t;
  }();
  return table;
}

void PublishSessionOptions::Validate() const {
  Fields().Check(*this);
  web.Validate();
  CAROUSEL_THROW_IF(spin_frames != 0 && spin_frames != 24 && spin_frames != 48 && spin_frames != 72,
                    InvalidArgument,
                    "--spin-frames must be 24, 48 or 72 (or 0 = none), got " << spin_frames);
}

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// Writes `bytes` into model/`name` unless it holds them already; records the name.
void Emit(const std::filesystem::path& model_folder, const std::string& name,
          std::span<const std::uint8_t> bytes, std::vector<std::string>* files) {
  std::error_code ec;
  std::filesystem::create_directories((model_folder / name).parent_path(), ec);
  if (ec) throw IoError((model_folder / name).parent_path(), "cannot create: " + ec.message());
  publish::WriteIfDifferent(model_folder / name, bytes);
  files->push_back(name);
}

void Emit(const std::filesystem::path& model_folder, const std::string& name,
          const std::vector<std::uint8_t>& bytes, std::vector<std::string>* files) {
  Emit(model_folder, name, std::span<const std::uint8_t>(bytes.data(), bytes.size()), files);
}

// Removes the files of model/`sub`/ that this run did not write.
void RemoveStale(const std::filesystem::path& model_folder, const std::string& sub,
                 const std::vector<std::string>& files) {
  const std::set<std::string> kept(files.begin(), files.end());
  std::error_code ec;
  std::vector<std::filesystem::path> stale;
  for (const auto& entry : std::filesystem::directory_iterator(model_folder / sub, ec))
    if (entry.is_regular_file() && !kept.count(sub + "/" + entry.path().filename().string()))
      stale.push_back(entry.path());
  for (const auto& p : stale) std::filesystem::remove(p, ec);
}

// Whether the session's +Z is up: the turntable's frame, or a dataset the import stood upright.
bool ZIsUp(const Session& session) {
  return session.frame == "turntable" || session.world_from_dataset.has_value();
}

// The elevation of the session's first camera above the centre of the model's `box`, degrees; 15
// when the session's frame has no up (ZIsUp).
double CameraElevationDeg(const Session& session, const Eigen::AlignedBox3d& box) {
  if (!ZIsUp(session) || session.views.empty()) return 15.0;
  const int camera = session.views.front().camera;
  double sum = 0.0;
  int n = 0;
  for (const SessionView& v : session.views) {
    if (v.camera != camera) continue;
    const Eigen::Vector3d d = v.camera_model.Centre() - box.center();
    sum += std::atan2(d.z(), std::hypot(d.x(), d.y())) / kDeg;
    ++n;
  }
  return std::clamp(sum / std::max(n, 1), -80.0, 80.0);
}

// The views of one camera that make a 360° set of `frames` by themselves (that many stops at
// equal steps, every one with a mask), in table-angle order; empty when no camera has them.
std::vector<int> PhotoSpin(const Session& session, int frames, int* camera_out) {
  // The product as it stands (the first pass): a later pass shows it laid down.
  std::map<int, std::vector<int>> by_camera;
  for (std::size_t i = 0; i < session.views.size(); ++i)
    if (session.views[i].pass == 0)
      by_camera[session.views[i].camera].push_back(static_cast<int>(i));
  for (auto& [camera, views] : by_camera) {
    if (static_cast<int>(views.size()) != frames) continue;
    std::sort(views.begin(), views.end(), [&](int a, int b) {
      return session.views[a].table_angle_deg < session.views[b].table_angle_deg;
    });
    bool even = true;
    const double step = 360.0 / frames;
    for (int k = 0; k < frames && even; ++k) {
      const SessionView& v = session.views[views[k]];
      const double next = k + 1 < frames ? session.views[views[k + 1]].table_angle_deg
                                         : session.views[views[0]].table_angle_deg + 360.0;
      even = !v.mask.empty() && std::abs(next - v.table_angle_deg - step) < 0.25 * step;
    }
    if (even) {
      *camera_out = camera;
      return views;
    }
  }
  return {};
}

// The photo of `camera` turned by quarter turns so that the world's up at the model's centre
// points up in it: a camera mounted on its side (or upside down) gives upright cut-outs. Photos
// looking nearly straight down, and sessions without an up, are left as they are.
cv::Mat Upright(const cv::Mat& image, const Session& session, const CameraModel& camera,
                const Eigen::AlignedBox3d& box, int* turned) {
  if (!ZIsUp(session)) return image;
  const Eigen::Matrix3d& r = camera.cam_from_world.rotation;
  if (std::abs(r(2, 2)) > std::cos(20.0 * kDeg)) return image;  // looking down (or up) along Z
  const auto a = camera.Project(box.center());
  const auto b = camera.Project(box.center() + 0.25 * box.sizes().z() * Eigen::Vector3d::UnitZ());
  if (!a || !b || (*b - *a).norm() < 1e-6) return image;
  const Eigen::Vector2d up = *b - *a;  // the world's up in the photo (image y points down)
  cv::Mat out;
  if (-up.y() >= std::abs(up.x())) return image;
  if (up.y() >= std::abs(up.x())) {
    cv::rotate(image, out, cv::ROTATE_180);
  } else if (up.x() > 0.0) {
    cv::rotate(image, out, cv::ROTATE_90_COUNTERCLOCKWISE);  // up points right: turn it up
  } else {
    cv::rotate(image, out, cv::ROTATE_90_CLOCKWISE);
  }
  ++*turned;
  return out;
}

cv::Mat ToBgra(const texture::ModelRendering& r) {
  cv::Mat bgra;
  cv::cvtColor(r.image, bgra, cv::COLOR_BGR2BGRA);
  const int to_alpha[] = {0, 3};
  cv::mixChannels(&r.mask, 1, &bgra, 1, to_alpha, 1);
  return bgra;
}

texture::ModelRendering RenderOnWhite(const texture::TexturedModel& model,
                                      const publish::OrbitShot& shot) {
  texture::ModelRenderOptions options;
  options.backdrop_top_bgr = {255, 255, 255};
  options.backdrop_bottom_bgr = {255, 255, 255};
  return texture::RenderTexturedModel(model, publish::OrbitCamera(model, shot), options);
}

// A held-out photo beside its render, cropped to the object (both silhouettes and a margin),
// `height` pixels high.
cv::Mat SideBySide(const cv::Mat& photo, const texture::ModelRendering& rendering,
                   const cv::Mat& reference, int height) {
  cv::Rect box = cv::boundingRect(reference >= 128) | cv::boundingRect(rendering.mask);
  if (box.area() == 0) box = cv::Rect(0, 0, photo.cols, photo.rows);
  const int pad = static_cast<int>(0.08 * std::max(box.width, box.height));
  box = cv::Rect(box.x - pad, box.y - pad, box.width + 2 * pad, box.height + 2 * pad) &
        cv::Rect(0, 0, photo.cols, photo.rows);
  const double scale = static_cast<double>(height) / box.height;
  const cv::Size size(std::max(1, static_cast<int>(std::lround(box.width * scale))), height);
  cv::Mat left, right, both;
  cv::resize(photo(box), left, size, 0, 0, scale < 1.0 ? cv::INTER_AREA : cv::INTER_LINEAR);
  cv::resize(rendering.image(box), right, size, 0, 0,
             scale < 1.0 ? cv::INTER_AREA : cv::INTER_LINEAR);
  cv::hconcat(
      std::vector<cv::Mat>{left, cv::Mat(height, 4, CV_8UC3, cv::Scalar(255, 255, 255)), right},
      both);
  return both;
}

// `model` with its texture replaced by one colour per triangle, rendered from two sides.
cv::Mat TwoSides(const texture::TexturedModel& model, const std::vector<cv::Vec3b>& colours,
                 int side) {
  texture::TexturedModel painted = model;
  painted.texture = publish::PaintTriangles(model, colours, 1024);
  painted.wrap = texture::TexturedModel::Wrap::kClampToEdge;
  publish::OrbitShot shot;
  shot.width = shot.height = side;
  shot.framing = publish::OrbitShot::Framing::kFit;
  cv::Mat front = RenderOnWhite(painted, shot).image;
  shot.azimuth_deg += 180.0;
  cv::Mat back = RenderOnWhite(painted, shot).image;
  cv::Mat both;
  cv::hconcat(front, back, both);
  return both;
}

}  // namespace

PublishSessionResult PublishSession(const std::filesystem::path& session_folder,
                                    const Session& session, const PublishSessionOptions& options,
                                    Progress& progress) {
  options.Validate();
  Stopwatch total, watch;
  // Seconds per part, in publish.json.
  nlohmann::ordered_json part_seconds;
  const auto phase = [&](const char* name) {
    part_seconds[name] = watch.ElapsedSeconds();
    watch.Restart();
  };
  const std::filesystem::path model_folder = session_folder / "model";
  const std::filesystem::path lossless = model_folder / "model.glb";
  std::error_code ec;
  if (!std::filesystem::is_regular_file(lossless, ec))
    throw IoError(lossless, "no textured model to publish (run `carousel texture` first)");
  const publish::WebRuntime runtime = publish::FindWebRuntime();
  PublishSessionResult result;
  std::vector<std::string>& files = result.files;
  result.lossless_bytes = std::filesystem::file_size(lossless);
  const texture::TexturedModel model = texture::ReadTexturedModel(lossless);
  progress.Report(0.05);
  phase("read");

  const std::filesystem::path web_path = model_folder / "model.web.glb";
  result.web = publish::WriteWebGlb(model, web_path, options.web);
  files.push_back("model.web.glb");
  progress.Report(0.15);
  phase("web_glb");

  // The texture stage's report (held-out views, histogram, density).
  const std::filesystem::path report_path = model_folder / "report.json";
  nlohmann::json report = nlohmann::json::object();
  if (std::filesystem::is_regular_file(report_path, ec)) report = ParseJsonFile(report_path);
  const JsonReader report_reader(report, report_path);
  std::vector<int> excluded;
  if (report_reader.Has("excluded_views"))
    excluded = report_reader.Member("excluded_views").AsInts();

  std::map<int, texture::HeldOutScore> lossless_scores;
  if (const std::optional<JsonReader> held = report_reader.OptionalObject("held_out")) {
    for (const JsonReader& row : held->Array("views")) {
      texture::HeldOutScore score;
      score.view = row.Int("view");
      score.psnr_db = row.Number("psnr_db");
      score.ssim = row.Number("ssim");
      score.mask_agreement = row.OptionalNumber("silhouette_iou").value_or(0.0);
      lossless_scores[score.view] = score;
    }
  }
  const std::vector<View> views = SessionViews(session_folder, session);
  std::vector<publish::ReportHeldOutRow> held_out_rows;
  if (!excluded.empty()) {
    const texture::TexturedModel web = publish::ReadWebGlb(web_path);
    for (const int v : excluded) {
      if (v < 0 || static_cast<std::size_t>(v) >= views.size())
        throw FormatError(report_path,
                          "excluded view " + std::to_string(v) + " is not a view of the session");
      const cv::Mat reference = HeldOutReferenceMask(session_folder, session, views, v);
      // The lossless file's score is the texture stage's (report.json: the same file, renderer
      // and reference), else rendered here.
      const auto scored = lossless_scores.find(v);
      result.held_out_lossless.push_back(
          scored != lossless_scores.end()
              ? scored->second
              : texture::ScoreHeldOutView(model, views[v], v, reference));
      result.held_out_web.push_back(texture::ScoreHeldOutView(web, views[v], v, reference));
      if (options.report) {
        char name[32];
        std::snprintf(name, sizeof name, "report/heldout_%02d.jpg", v);
        // The side-by-side needs no full-size rendering: at most 1280 pixels on the long side.
        const CameraModel& camera = views[v].camera();
        const double scale = std::min(1.0, 1280.0 / std::max(camera.width, camera.height));
        const CameraModel small = scale < 1.0 ? camera.Scaled(scale) : camera;
        cv::Mat photo = views[v].Image(), ref = reference;
        if (scale < 1.0) {
          cv::resize(photo, photo, cv::Size(small.width, small.height), 0, 0, cv::INTER_AREA);
          cv::resize(reference, ref, cv::Size(small.width, small.height), 0, 0, cv::INTER_AREA);
        }
        const texture::ModelRendering rendering = texture::RenderTexturedModel(model, small);
        Emit(model_folder, name,
             publish::EncodeCatalogImage(SideBySide(photo, rendering, ref, 420), 88,
                                         model_folder / name),
             &files);
        held_out_rows.push_back({.view = v,
                                 .image = name,
                                 .psnr_db = result.held_out_lossless.back().psnr_db,
                                 .ssim = result.held_out_lossless.back().ssim,
                                 .psnr_db_web = result.held_out_web.back().psnr_db,
                                 .ssim_web = result.held_out_web.back().ssim});
      }
      progress.CheckCancelled();
    }
    result.mean_psnr_lossless_db = texture::MeanPsnrDb(result.held_out_lossless);
    result.mean_psnr_web_db = texture::MeanPsnrDb(result.held_out_web);
  }
  progress.Report(0.35);
  phase("held_out");

  // The hero shot and the poster (the hero, smaller).
  publish::OrbitShot hero;
  hero.width = hero.height = options.hero_size;
  hero.framing = publish::OrbitShot::Framing::kFit;
  const cv::Mat hero_image = RenderOnWhite(model, hero).image;
  Emit(model_folder, "hero.jpg",
       publish::EncodeCatalogImage(hero_image, options.jpeg_quality, model_folder / "hero.jpg"),
       &files);
  cv::Mat poster;
  cv::resize(hero_image, poster, cv::Size(options.poster_size, options.poster_size), 0, 0,
             options.poster_size < options.hero_size ? cv::INTER_AREA : cv::INTER_LINEAR);
  Emit(model_folder, "poster.jpg",
       publish::EncodeCatalogImage(poster, 88, model_folder / "poster.jpg"), &files);
  progress.Report(0.45);
  phase("hero");

  // Cut-outs of every photo with a mask, standing upright.
  Eigen::AlignedBox3d model_box;
  for (const Eigen::Vector3d& p : model.positions) model_box.extend(p);
  const bool transparent = options.backdrop == publish::CutoutBackdrop::kTransparent;
  const std::string extension = transparent ? ".png" : ".jpg";
  publish::CutoutOptions cut{
      .backdrop = options.backdrop, .margin = options.cutout_margin, .size = options.cutout_size};
  if (options.cutouts) {
    for (std::size_t i = 0; i < views.size(); ++i) {
      if (!views[i].HasMask()) continue;
      const std::string name =
          "cutouts/" + std::filesystem::path(session.views[i].image).stem().string() + extension;
      try {
        const cv::Mat image =
            Upright(publish::CutOut(views[i].Image(), views[i].Mask(), cut), session,
                    views[i].camera(), model_box, &result.cutouts_turned);
        Emit(model_folder, name,
             publish::EncodeCatalogImage(image, options.jpeg_quality, model_folder / name), &files);
        ++result.cutouts;
      } catch (const InvalidArgument&) {
        // A photo whose mask holds no object (the product out of frame) has no cut-out.
      }
      progress.Report(0.45 + 0.2 * static_cast<double>(i + 1) / static_cast<double>(views.size()));
      progress.CheckCancelled();
    }
  }
  RemoveStale(model_folder, "cutouts", files);
  phase("cutouts");

  // The 360° set and the spin.
  if (options.spin_frames > 0) {
    const std::vector<int> photo_views =
        PhotoSpin(session, options.spin_frames, &result.spin_camera);
    result.spin_from_photos = !photo_views.empty();
    std::vector<cv::Mat> frames;
    publish::OrbitShot shot;
    shot.width = shot.height = options.spin_size;
    shot.framing = publish::OrbitShot::Framing::kCylinder;
    shot.elevation_deg = result.spin_elevation_deg = CameraElevationDeg(session, model_box);
    cut.size = options.spin_size;
    for (int k = 0; k < options.spin_frames; ++k) {
      if (result.spin_from_photos) {
        const View& v = views[photo_views[k]];
        int turned = 0;
        frames.push_back(Upright(publish::CutOut(v.Image(), v.Mask(), cut), session, v.camera(),
                                 model_box, &turned));
      } else {
        // The camera goes round against the table's turn, as the photos see it.
        shot.azimuth_deg = hero.azimuth_deg - k * 360.0 / options.spin_frames;
        const texture::ModelRendering r = RenderOnWhite(model, shot);
        frames.push_back(transparent ? ToBgra(r) : r.image);
      }
      progress.Report(0.65 + 0.2 * (k + 1) / options.spin_frames);
      progress.CheckCancelled();
    }
    result.spin_frames = options.spin_frames;
    const std::vector<std::string> names =
        publish::SpinSetNames(session.product, options.spin_frames, extension);
    std::vector<publish::ZipEntry> entries;
    entries.reserve(static_cast<std::size_t>(options.spin_frames));
    for (int k = 0; k < options.spin_frames; ++k)
      entries.push_back({names[k], publish::EncodeCatalogImage(frames[k], options.jpeg_quality,
                                                               model_folder / "360.zip")});
    Emit(model_folder, "360.zip", publish::ZipArchive(entries, model_folder / "360.zip"), &files);
    Emit(model_folder, "spin.webp",
         publish::EncodeAnimatedWebp(frames, options.spin_frame_ms, options.webp_quality,
                                     model_folder / "spin.webp"),
         &files);
  }
  progress.Report(0.88);
  phase("spin");

  // The report page.
  std::vector<std::pair<std::string, std::string>> links;
  if (options.report) {
    publish::ReportPageContent page;
    page.title = session.product;
    page.faces = model.triangles.size();
    page.views = static_cast<int>(views.size());
    page.atlas_size = model.texture.cols;
    page.lossless_bytes = result.lossless_bytes;
    page.web_bytes = result.web.bytes;
    page.held_out = held_out_rows;
    const std::vector<int> charts = publish::ChartOfTriangle(model);
    page.islands = charts.empty() ? 0 : *std::max_element(charts.begin(), charts.end()) + 1;
    page.charts = report_reader.Has("charts") ? report_reader.Int("charts") : page.islands;
    Emit(model_folder, "report/charts.jpg",
         publish::EncodeCatalogImage(TwoSides(model, publish::ChartColours(charts), 480), 88,
                                     model_folder / "report/charts.jpg"),
         &files);
    page.charts_image = "report/charts.jpg";
    const cv::Mat atlas = publish::PaintTriangles(model, publish::ChartColours(charts),
                                                  std::min(1024, std::max(8, model.texture.cols)));
    Emit(model_folder, "report/charts_atlas.png",
         publish::EncodeCatalogImage(cv::Mat(atlas), 88, model_folder / "report/charts_atlas.png"),
         &files);
    page.charts_atlas_image = "report/charts_atlas.png";
    if (report_reader.Has("histogram")) {
      const JsonReader h = report_reader.Object("histogram");
      page.histogram_edges = h.Member("texels_per_face_bin_starts").AsInts();
      page.histogram_counts = h.Member("faces").AsInts();
      if (page.histogram_edges.size() != page.histogram_counts.size())
        h.Fail("the histogram's bin starts and counts disagree in number");
    }
    if (report_reader.Has("texel_density")) {
      const JsonReader d = report_reader.Object("texel_density");
      page.dense_fraction = d.Number("faces_with_at_least_one_texel_per_photo_pixel");
      const std::vector<double> per_face = d.Member("per_face").AsNumbers();
      if (per_face.size() == model.triangles.size()) {
        Emit(model_folder, "report/density.jpg",
             publish::EncodeCatalogImage(
                 TwoSides(model,
                          publish::DensityColours(per_face, page.density_lo, page.density_hi), 480),
                 88, model_folder / "report/density.jpg"),
             &files);
        page.density_image = "report/density.jpg";
        Emit(model_folder, "report/density_legend.png",
             publish::EncodeCatalogImage(publish::DensityLegend(320, 16), 88,
                                         model_folder / "report/density_legend.png"),
             &files);
        page.density_legend_image = "report/density_legend.png";
      }
    }
    const auto seconds = [&](const std::string& key) {
      const auto it = session.stage_seconds.find(key);
      if (it != session.stage_seconds.end()) page.stage_seconds.emplace_back(key, it->second);
    };
    for (const char* key : {"capture", "reconstruct", "reconstruct/silhouettes", "reconstruct/hull",
                            "reconstruct/mesh", "reconstruct/agreement", "texture"})
      seconds(key);
    if (report_reader.Has("seconds")) {
      const JsonReader s = report_reader.Object("seconds");
      for (const char* key : {"grouping", "atlas", "transfer", "export", "evaluation"})
        if (s.Has(key))
          page.stage_seconds.emplace_back(std::string("texture/") + key, s.Number(key));
    }
    // The publish stage as the pipeline last recorded it: this run's own time would make the
    // page differ on every run, and publishing twice must change nothing.
    seconds("publish");
    publish::WriteIfDifferent(model_folder / "report.html", publish::ReportPageHtml(page));
    files.push_back("report.html");
    RemoveStale(model_folder, "report", files);
    links.emplace_back("Report", "report.html");
  } else {
    RemoveStale(model_folder, "report", files);
  }
  // What an earlier run made and this one was told not to (no spin, no report page) goes.
  for (const char* name : {"360.zip", "spin.webp", "report.html"}) {
    if (std::find(files.begin(), files.end(), name) != files.end()) continue;
    std::filesystem::remove(model_folder / name, ec);
  }
  if (result.spin_frames > 0) {
    links.emplace_back("Spin", "spin.webp");
    links.emplace_back("360° set", "360.zip");
  }
  publish::WriteViewerPage(
      model_folder,
      {.title = session.product, .glb = "model.web.glb", .poster = "poster.jpg", .links = links},
      runtime);
  files.insert(files.end(),
               {"index.html", publish::kModelViewerScript, publish::kMeshoptDecoderScript});
  progress.Report(0.95);
  phase("report");

  nlohmann::ordered_json summary;
  summary["name"] = session.product;
  summary["lossless_glb"] = {{"file", "model.glb"}, {"bytes", result.lossless_bytes}};
  summary["web_glb"] = {{"file", "model.web.glb"},
                        {"bytes", result.web.bytes},
                        {"texture_bytes", result.web.texture_bytes},
                        {"texture_size", result.web.texture_size},
                        {"geometry_bytes", result.web.geometry_bytes},
                        {"geometry_raw_bytes", result.web.geometry_raw_bytes},
                        {"vertices", result.web.vertices},
                        {"triangles", result.web.triangles},
                        {"jpeg_quality", options.web.jpeg_quality},
                        {"unlit", options.web.unlit},
                        {"meshopt", options.web.compress}};
  if (!excluded.empty()) {
    nlohmann::ordered_json rows = nlohmann::ordered_json::array();
    for (std::size_t i = 0; i < excluded.size(); ++i)
      rows.push_back({{"view", excluded[i]},
                      {"psnr_db_lossless", result.held_out_lossless[i].psnr_db},
                      {"psnr_db_web", result.held_out_web[i].psnr_db},
                      {"ssim_lossless", result.held_out_lossless[i].ssim},
                      {"ssim_web", result.held_out_web[i].ssim}});
    summary["held_out"] = {{"views", rows},
                           {"mean_psnr_db_lossless", result.mean_psnr_lossless_db},
                           {"mean_psnr_db_web", result.mean_psnr_web_db}};
  }
  summary["catalog"] = {{"cutouts", result.cutouts},
                        {"cutouts_turned_upright", result.cutouts_turned},
                        {"backdrop", publish::CutoutBackdropName(options.backdrop)},
                        {"spin_frames", result.spin_frames},
                        {"spin_source", result.spin_frames == 0   ? "none"
                                        : result.spin_from_photos ? "photos"
                                                                  : "renders"}};
  if (result.spin_frames > 0 && !result.spin_from_photos)
    summary["catalog"]["spin_renders"] = {{"elevation_deg", result.spin_elevation_deg},
                                          {"first_azimuth_deg", publish::OrbitShot().azimuth_deg},
                                          {"step_deg", -360.0 / result.spin_frames},
                                          {"size", options.spin_size},
                                          {"framing", "cylinder"}};
  if (result.spin_from_photos) summary["catalog"]["spin_camera"] = result.spin_camera;
  nlohmann::ordered_json page_links = nlohmann::ordered_json::array();
  for (const auto& [label, href] : links) page_links.push_back({label, href});
  summary["page"] = {{"glb", "model.web.glb"}, {"poster", "poster.jpg"}, {"links", page_links}};
  summary["seconds"] = part_seconds;
  // What the next `carousel publish` or `process` of this session starts from (their flags
  // change only what they name).
  summary["options"] =
      nlohmann::ordered_json::parse(OptionsToJson(PublishSessionOptions::Fields(), options).dump());
  summary["files"] = files;
  files.push_back("publish.json");
  WriteFileAtomic(model_folder / "publish.json", summary.dump(2) + "\n");
  result.seconds = total.ElapsedSeconds();
  progress.Report(1.0);
  return result;
}

SiteResult AddToSite(const std::filesystem::path& session_folder, const std::filesystem::path& site,
                     const std::string& title) {
  std::filesystem::path folder = session_folder.lexically_normal();
  if (folder.filename().empty()) folder = folder.parent_path();
  if (folder.filename().empty() || folder.filename() == "." || folder.filename() == "..")
    folder = std::filesystem::absolute(folder).lexically_normal();
  SiteResult result;
  result.product = publish::PublishToSite(session_folder / "model",
                                          publish::SiteSlug(folder.filename().string()), site,
                                          publish::FindWebRuntime());
  result.products = publish::WriteSiteIndex(site, title);
  return result;
}

}  // namespace carousel::studio
