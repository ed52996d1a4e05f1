#include "carousel/sim/sim_session.h"

#include <cstdio>
#include <numbers>
#include <string>

#include <opencv2/imgcodecs.hpp>

#include "carousel/core/error.h"

namespace carousel::sim {
namespace {

cv::Mat ThroughJpeg(const cv::Mat& image, int quality) {
  if (quality <= 0) return image;
  std::vector<std::uint8_t> bytes;
  CAROUSEL_CHECK(cv::imencode(".jpg", image, bytes, {cv::IMWRITE_JPEG_QUALITY, quality}),
                 "JPEG encoding failed");
  return cv::imdecode(bytes, cv::IMREAD_COLOR);
}

}  // namespace

void SimViewsOptions::Validate() const {
  rig.Validate();
  render.Validate();
  CAROUSEL_THROW_IF(stops < 1, InvalidArgument, "SimViewsOptions.stops must be >= 1");
  CAROUSEL_THROW_IF(jpeg_quality < 0 || jpeg_quality > 100, InvalidArgument,
                    "SimViewsOptions.jpeg_quality must be in [0, 100]");
}

SimViews RenderViews(const Scene& scene, const SimViewsOptions& options) {
  options.Validate();
  scene.Validate();
  SimViews result;
  const std::vector<CameraModel> rig = MakeSimRig(options.rig, scene.Bounds());
  std::vector<cv::Mat> camera_backgrounds;
  if (options.backgrounds) {
    Scene empty;
    empty.source = "empty turntable";
    for (std::size_t c = 0; c < rig.size(); ++c) {
      RenderOptions render = options.render;
      render.seed = options.render.seed * 7919ULL + 1000000ULL + c;
      camera_backgrounds.push_back(
          ThroughJpeg(Render(empty, rig[c], 0.0, render).image, options.jpeg_quality));
    }
  }
  int index = 0;
  for (int stop = 0; stop < options.stops; ++stop) {
    const double angle = 2.0 * std::numbers::pi * stop / options.stops;
    for (std::size_t c = 0; c < rig.size(); ++c) {
      const CameraModel camera = CameraAtTableAngle(rig[c], angle);
      RenderOptions render = options.render;
      render.seed = options.render.seed * 1000003ULL + static_cast<std::uint64_t>(index++);
      RenderResult rendered = Render(scene, camera, angle, render);
      View view(camera, {}, {}, angle);
      char name[48];  // "cam" + 20 digits + "_stop" + 11 + NUL
      std::snprintf(name, sizeof name, "cam%zu_stop%02d", c, stop);
      view.set_name(name);
      view.SetImage(ThroughJpeg(rendered.image, options.jpeg_quality));
      if (options.mask_shots) {
        RenderOptions backlit = render;
        backlit.backlit = true;
        backlit.seed = render.seed ^ 0x6a09e667f3bcc909ULL;
        View shot(camera, {}, {}, angle);
        shot.set_name(std::string(name) + "_backlit");
        shot.SetImage(
            ThroughJpeg(Render(scene, camera, angle, backlit).image, options.jpeg_quality));
        result.mask_shots.push_back(std::move(shot));
      }
      result.views.push_back(std::move(view));
      result.truth_masks.push_back(rendered.mask);
      if (options.backgrounds) result.backgrounds.push_back(camera_backgrounds[c]);
    }
  }
  result.truth_mesh = scene.ToMesh();
  return result;
}

}  // namespace carousel::sim
