#include "carousel/sim/renderer.h"

#include <cmath>
#include <iostream>
#include <memory>
#include <numbers>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/mesh_primitives.h"
#include "carousel/sim/scene.h"
#include "carousel/sim/sim_rig.h"
#include "carousel/sim/test_scenes.h"
#include "carousel/testing/testing.h"

namespace carousel::sim {
namespace {

CameraModel StudioCamera(int width, int height, double elevation_deg,
                         const Eigen::AlignedBox3d& bounds, Distortion distortion) {
  SimRigOptions rig;
  rig.width = width;
  rig.height = height;
  rig.elevations_deg = {elevation_deg};
  rig.distortion = distortion;
  return MakeSimRig(rig, bounds).front();
}

double IoU(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat both, either;
  cv::bitwise_and(a, b, both);
  cv::bitwise_or(a, b, either);
  return static_cast<double>(cv::countNonZero(both)) / cv::countNonZero(either);
}

TEST(RendererTest, SphereSilhouetteMatchesTheAnalyticOne) {
  const double radius = 0.1;
  const Eigen::Vector3d centre(0.01, -0.02, 0.1);
  const Scene sphere = MakeSphereScene(radius, centre, 6);
  for (const Distortion& distortion : {Distortion{}, Distortion{-0.12, 0.05, 0.001, -0.001, 0}}) {
    const CameraModel camera = StudioCamera(1296, 864, 25, sphere.Bounds(), distortion);
    RenderOptions options;
    options.plate_radius_m = 0;
    const RenderResult result = Render(sphere, camera, 0.3, options);
    // Analytic: a pixel is inside when the ray through its centre passes within the radius.
    cv::Mat expected(camera.height, camera.width, CV_8UC1, cv::Scalar(0));
    for (int y = 0; y < camera.height; ++y) {
      for (int x = 0; x < camera.width; ++x) {
        const std::optional<Ray> ray = camera.RayThrough({x, y});
        ASSERT_TRUE(ray);
        const Eigen::Vector3d to_centre = centre - ray->origin;
        const double along = to_centre.dot(ray->direction);
        if ((to_centre - along * ray->direction).norm() < radius) expected.at<uint8_t>(y, x) = 255;
      }
    }
    EXPECT_GT(cv::countNonZero(expected), 50000);
    const double iou = IoU(result.mask, expected);
    std::cout << "sphere silhouette IoU " << iou << " (k1 = " << distortion.k1 << ")\n";
    EXPECT_GT(iou, 0.995) << "k1 = " << distortion.k1;
    // Depth: the nearest point of the sphere is at |C - centre| - r along the optical axis
    // direction or more; every object pixel is within the sphere's depth range.
    double min_depth = 1e9, max_depth = 0;
    for (int y = 0; y < camera.height; ++y) {
      for (int x = 0; x < camera.width; ++x) {
        const float d = result.depth.at<float>(y, x);
        if (d > 0) {
          min_depth = std::min<double>(min_depth, d);
          max_depth = std::max<double>(max_depth, d);
        }
      }
    }
    const double centre_depth = (camera.cam_from_world * centre).z();
    EXPECT_GT(min_depth, centre_depth - radius - 1e-3);
    EXPECT_LT(max_depth, centre_depth + 1e-3);
  }
}

TEST(RendererTest, CheckerCornersLandWhereTheCameraModelProjectsThem) {
  constexpr int kSquares = 8;
  const double size = 0.24;
  const Scene plane = MakeCheckerPlaneScene(size, kSquares, 0.0, 64);
  const CameraModel camera =
      StudioCamera(1296, 864, 55, plane.Bounds(), Distortion{-0.15, 0.08, 0.001, -0.0015, 0.0});
  RenderOptions options;
  options.plate_radius_m = 0;
  options.lit = false;
  options.samples_per_axis = 4;
  const RenderResult result = Render(plane, camera, 0.0, options);
  cv::Mat gray;
  cv::cvtColor(result.image, gray, cv::COLOR_BGR2GRAY);
  std::vector<cv::Point2f> corners;
  ASSERT_TRUE(cv::findChessboardCorners(gray, {kSquares - 1, kSquares - 1}, corners));
  cv::cornerSubPix(gray, corners, {7, 7}, {-1, -1},
                   {cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4});
  std::vector<Eigen::Vector2d> projected;
  for (int j = 1; j < kSquares; ++j) {
    for (int i = 1; i < kSquares; ++i) {
      const Eigen::Vector3d corner(-size / 2 + i * size / kSquares, -size / 2 + j * size / kSquares,
                                   0.0);
      projected.push_back(*camera.Project(corner));
    }
  }
  double worst = 0.0;
  Eigen::Vector2d bias = Eigen::Vector2d::Zero();
  for (const cv::Point2f& found : corners) {
    double nearest = 1e9;
    Eigen::Vector2d offset;
    for (const Eigen::Vector2d& p : projected) {
      const double d = std::hypot(found.x - p.x(), found.y - p.y());
      if (d < nearest) {
        nearest = d;
        offset = Eigen::Vector2d(found.x - p.x(), found.y - p.y());
      }
    }
    worst = std::max(worst, nearest);
    bias += offset / static_cast<double>(corners.size());
  }
  std::cout << "checker corners: worst " << worst << " px, mean offset " << bias.transpose()
            << "\n";
  EXPECT_EQ(corners.size(), projected.size());
  EXPECT_LT(worst, 0.25) << "largest corner error in pixels";
}

TEST(RendererTest, SameSeedSameBytesAndNoiseOnlyWhereEnabled) {
  const Scene sphere = MakeSphereScene(0.08, {0, 0, 0.08}, 4);
  const CameraModel camera = StudioCamera(320, 240, 20, sphere.Bounds(), {});
  RenderOptions options;
  options.noise_sigma = 2.0;
  options.seed = 7;
  const RenderResult a = Render(sphere, camera, 0.5, options);
  options.threads = 1;
  const RenderResult b = Render(sphere, camera, 0.5, options);
  EXPECT_EQ(cv::norm(a.image, b.image, cv::NORM_INF), 0.0) << "thread count changed the image";
  options.seed = 8;
  const RenderResult c = Render(sphere, camera, 0.5, options);
  EXPECT_GT(cv::norm(a.image, c.image, cv::NORM_L1), 0.0);
  EXPECT_EQ(cv::norm(a.mask, c.mask, cv::NORM_INF), 0.0) << "the seed only changes noise";
  // Without noise the seed changes nothing.
  options.noise_sigma = 0;
  const RenderResult d = Render(sphere, camera, 0.5, options);
  options.seed = 9;
  const RenderResult e = Render(sphere, camera, 0.5, options);
  EXPECT_EQ(cv::norm(d.image, e.image, cv::NORM_INF), 0.0);
  // The noise has the requested strength: compare with the noiseless image.
  cv::Mat noisy, clean;
  a.image.convertTo(noisy, CV_32F);
  d.image.convertTo(clean, CV_32F);
  cv::Scalar mean, stddev;
  cv::meanStdDev(noisy - clean, mean, stddev);
  for (int channel = 0; channel < 3; ++channel) {
    EXPECT_NEAR(stddev[channel], 2.0, 0.3);
    EXPECT_NEAR(mean[channel], 0.0, 0.5);  // rounding of the clean image biases by < 0.5
  }
}

TEST(RendererTest, LightsStayInTheStudioWhileTheTableTurns) {
  // A sphere on the axis looks the same from every table angle only if the lights stay put.
  const Scene sphere = MakeSphereScene(0.08, {0, 0, 0.08}, 5, {0.7f, 0.7f, 0.7f});
  const CameraModel at_zero = StudioCamera(320, 240, 10, sphere.Bounds(), {});
  RenderOptions options;
  options.plate_radius_m = 0;
  const RenderResult a = Render(sphere, at_zero, 0.0, options);
  const double angle = 2.0;
  const CameraModel turned = CameraAtTableAngle(at_zero, angle);
  const RenderResult b = Render(sphere, turned, angle, options);
  // Lights wrongly fixed to the object instead (angle 0 for the lights).
  const RenderResult wrong = Render(sphere, turned, 0.0, options);
  cv::Mat diff_right, diff_wrong;
  cv::absdiff(a.image, b.image, diff_right);
  cv::absdiff(a.image, wrong.image, diff_wrong);
  const double right = cv::mean(diff_right, a.mask)[1];
  const double off = cv::mean(diff_wrong, a.mask)[1];
  EXPECT_LT(right, 1.0);
  EXPECT_GT(off, 10.0 * right + 2.0);
}

// A glossy material adds white highlights of the studio lights and changes nothing else: the
// same silhouette, never darker, brighter only in a small spot where the key light reflects.
TEST(RendererTest, GlossyMaterialsAddSmallWhiteHighlights) {
  Scene matte = MakeSphereScene(0.08, {0, 0, 0.08}, 5, {0.4f, 0.3f, 0.2f});
  Scene glossy = matte;
  glossy.OverrideMaterials(MaterialOverride::kGlossy);
  const CameraModel camera = StudioCamera(320, 240, 20, matte.Bounds(), {});
  RenderOptions options;
  options.plate_radius_m = 0;
  const RenderResult a = Render(matte, camera, 0.0, options);
  const RenderResult b = Render(glossy, camera, 0.0, options);
  EXPECT_EQ(cv::countNonZero(a.mask != b.mask), 0);
  cv::Mat darker, brighter;
  cv::subtract(a.image, b.image, darker);
  cv::subtract(b.image, a.image, brighter);
  double most_darker = 0.0, most_brighter = 0.0;
  cv::minMaxLoc(darker.reshape(1), nullptr, &most_darker);
  cv::minMaxLoc(brighter.reshape(1), nullptr, &most_brighter);
  EXPECT_EQ(most_darker, 0.0);
  EXPECT_GT(most_brighter, 60.0);
  std::vector<cv::Mat> channels;
  cv::split(brighter, channels);
  const cv::Mat spot = channels[0] > 20;  // blue: white added to a brown sphere
  const double fraction = cv::countNonZero(spot) / static_cast<double>(cv::countNonZero(a.mask));
  EXPECT_GT(fraction, 0.001);
  EXPECT_LT(fraction, 0.15);
  // White: the blue channel gains as much as the red one in the spot.
  EXPECT_NEAR(cv::mean(channels[0], spot)[0], cv::mean(channels[2], spot)[0], 25.0);
  EXPECT_THROW(ParseMaterialOverride("chrome"), InvalidArgument);
  EXPECT_EQ(ParseMaterialOverride(MaterialOverrideName(MaterialOverride::kBlack)),
            MaterialOverride::kBlack);
}

// The contact shadow darkens the plate at the object's base and fades with distance; the
// object and the mask are untouched.
// A grey sphere on the plate rendered plain and with a shadow; the shadow leaves the mask and
// the object itself (away from its anti-aliased outline, whose pixels hold plate samples)
// untouched. `diff`: the two renders' absolute difference.
struct ShadowPair {
  CameraModel camera;
  RenderResult plain, shadowed;
  cv::Mat diff;
};
ShadowPair RenderShadow(double plate_radius_m, double RenderOptions::*shadow, double amount) {
  const Scene sphere = MakeSphereScene(0.05, {0, 0, 0.05}, 5, {0.7f, 0.7f, 0.7f});
  ShadowPair pair;
  pair.camera = StudioCamera(320, 240, 30, sphere.Bounds(), {});
  RenderOptions options;
  options.plate_radius_m = plate_radius_m;
  pair.plain = Render(sphere, pair.camera, 0.0, options);
  options.*shadow = amount;
  pair.shadowed = Render(sphere, pair.camera, 0.0, options);
  EXPECT_EQ(cv::countNonZero(pair.plain.mask != pair.shadowed.mask), 0);
  cv::absdiff(pair.plain.image, pair.shadowed.image, pair.diff);
  cv::Mat inside;
  cv::erode(pair.plain.mask, inside, cv::Mat(), cv::Point(-1, -1), 2);
  EXPECT_EQ(cv::mean(pair.diff, inside)[1], 0.0);
  return pair;
}

TEST(RendererTest, ContactShadowDarkensThePlateAtTheBaseOnly) {
  const auto [camera, plain, shadowed, diff] =
      RenderShadow(0.15, &RenderOptions::contact_shadow, 0.6);
  // Plate pixels just below the sphere's image (its base) against the plate's far rim.
  const cv::Rect box = cv::boundingRect(plain.mask);
  const int below = std::min(box.br().y + 2, camera.height - 1);
  const int centre = box.x + box.width / 2;
  const cv::Vec3b near_plain = plain.image.at<cv::Vec3b>(below, centre);
  const cv::Vec3b near_shadow = shadowed.image.at<cv::Vec3b>(below, centre);
  EXPECT_LT(near_shadow[1] + 20, near_plain[1]);
  const cv::Vec3b far_plain = plain.image.at<cv::Vec3b>(camera.height - 3, 3);
  const cv::Vec3b far_shadow = shadowed.image.at<cv::Vec3b>(camera.height - 3, 3);
  EXPECT_NEAR(far_shadow[1], far_plain[1], 1.0);
}

double LinearGreen(const cv::Mat& image, int x, int y) {
  const double c = image.at<cv::Vec3b>(y, x)[1] / 255.0;
  return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}

// Vignetting and the backdrop light's falloff darken the frame's corners by the fractions set
// (in linear light), and leave its centre alone.
TEST(RendererTest, VignettingAndFalloffDarkenTheCornersByTheirFractions) {
  Scene empty;
  empty.source = "empty";
  SimRigOptions rig;
  rig.width = 300;
  rig.height = 200;
  rig.distortion = {};
  const CameraModel camera = MakeSimRig(rig, Eigen::AlignedBox3d(Eigen::Vector3d(-0.1, -0.1, 0),
                                                                 Eigen::Vector3d(0.1, 0.1, 0.2)))
                                 .front();
  RenderOptions options;
  options.plate_radius_m = 0.0;
  options.backdrop_top = options.backdrop_bottom = {0.8, 0.8, 0.8};
  const cv::Mat flat = Render(empty, camera, 0.0, options).image;
  for (const bool vignetting : {true, false}) {
    RenderOptions dark = options;
    (vignetting ? dark.vignetting : dark.backdrop_falloff) = 0.3;
    const cv::Mat image = Render(empty, camera, 0.0, dark).image;
    const int cx = static_cast<int>(camera.cx), cy = static_cast<int>(camera.cy);
    EXPECT_NEAR(LinearGreen(image, cx, cy) / LinearGreen(flat, cx, cy), 1.0, 0.02);
    for (const auto& [x, y] : {std::pair{0, 0}, std::pair{299, 199}, std::pair{0, 199}}) {
      const double ratio = LinearGreen(image, x, y) / LinearGreen(flat, x, y);
      EXPECT_NEAR(ratio, 0.7, 0.04)
          << (vignetting ? "vignetting" : "falloff") << " " << x << "," << y;
    }
    // Halfway out, less.
    const double half = LinearGreen(image, cx / 2, cy / 2) / LinearGreen(flat, cx / 2, cy / 2);
    EXPECT_GT(half, 0.8);
    EXPECT_LT(half, 0.99);
  }
}

// The key light (above, front left) casts the object's shadow onto the plate behind it to the
// right, soft at its edge; the object and the mask are untouched, the lit side of the plate too.
TEST(RendererTest, CastShadowFallsOnThePlateAwayFromTheKeyLightAndIsSoft) {
  const auto [camera, plain, shadowed, diff] = RenderShadow(0.2, &RenderOptions::cast_shadow, 0.8);
  cv::Mat green;
  cv::extractChannel(diff, green, 1);
  const cv::Mat dark = (green > 12) & (plain.mask == 0);
  const cv::Mat partial = (green > 2) & (green <= 12) & (plain.mask == 0);
  ASSERT_GT(cv::countNonZero(dark), 300);
  EXPECT_GT(cv::countNonZero(partial), 100);  // a penumbra
  const cv::Moments shadow = cv::moments(dark, true);
  const cv::Moments object = cv::moments(plain.mask, true);
  // Behind (higher in the photo) and to the right of the object.
  EXPECT_GT(shadow.m10 / shadow.m00, object.m10 / object.m00);
  EXPECT_LT(shadow.m01 / shadow.m00, object.m01 / object.m00 + 0.5 * std::sqrt(object.m00));
  // The lit side (left of the object) is untouched.
  const cv::Rect box = cv::boundingRect(plain.mask);
  EXPECT_EQ(cv::countNonZero(dark(cv::Rect(0, 0, std::max(1, box.x - 5), camera.height))), 0);
}

// The backlit shot: the panel and the plate glow, the product is dark against them; its mask
// and depth are the photo's.
TEST(RendererTest, BacklitShotShowsTheProductDarkAgainstTheLitPanel) {
  Scene sphere = MakeSphereScene(0.05, {0, 0, 0.05}, 5, {0.9f, 0.9f, 0.9f});  // white
  const CameraModel camera = StudioCamera(320, 240, 20, sphere.Bounds(), {});
  RenderOptions options;
  options.backdrop_top = options.backdrop_bottom = {0.96, 0.96, 0.96};  // white on white
  const RenderResult photo = Render(sphere, camera, 0.0, options);
  options.backlit = true;
  const RenderResult backlit = Render(sphere, camera, 0.0, options);
  EXPECT_EQ(cv::countNonZero(photo.mask != backlit.mask), 0);
  cv::Mat inside, outside;
  cv::erode(photo.mask, inside, cv::Mat(), cv::Point(-1, -1), 3);
  cv::dilate(photo.mask, outside, cv::Mat(), cv::Point(-1, -1), 3);
  outside = ~outside;
  const double panel = cv::mean(backlit.image, outside)[1];
  const double product = cv::mean(backlit.image, inside)[1];
  EXPECT_NEAR(panel, 231.0, 8.0);  // linear 0.8, plate included
  EXPECT_LT(product, 0.4 * panel);
  // In the photo the white product is nearly the backdrop's brightness: no such contrast.
  EXPECT_GT(cv::mean(photo.image, inside)[1], 0.6 * cv::mean(photo.image, outside)[1]);
  // The simulated camera shoots it while the table's backlight is on.
  auto table = std::make_shared<SimTurntable>(SimTurntableOptions{.time_scale = 0.0});
  SimCameraOptions camera_options;
  camera_options.render = options;
  camera_options.render.backlit = false;
  SimCamera sim_camera(std::make_shared<const Scene>(sphere), camera, table, camera_options);
  const auto mean_inside = [&](const std::vector<std::uint8_t>& jpeg) {
    return cv::mean(cv::imdecode(jpeg, cv::IMREAD_COLOR), inside)[1];
  };
  const double lit = mean_inside(sim_camera.Shoot());
  table->SetBacklight(true);
  EXPECT_TRUE(table->Status().backlight);
  const double backlit_shot = mean_inside(sim_camera.Shoot());
  table->SetBacklight(false);
  EXPECT_LT(backlit_shot, 0.5 * lit);
}

// A see-through material shows the backdrop behind it, tinted, and its outline a little darker
// (less passes through at grazing angles; refraction, which would darken it more, is not
// modelled).
TEST(RendererTest, SeeThroughMaterialShowsTheBackdropTintedBehindIt) {
  Scene sphere = MakeSphereScene(0.05, {0, 0, 0.05}, 5);
  sphere.OverrideMaterials(MaterialOverride::kSeeThrough);
  EXPECT_EQ(ParseMaterialOverride("see-through"), MaterialOverride::kSeeThrough);
  const CameraModel camera = StudioCamera(320, 240, 20, sphere.Bounds(), {});
  RenderOptions options;
  options.plate_radius_m = 0.0;
  options.lights.clear();  // no highlight in the way
  options.backdrop_top = options.backdrop_bottom = {0.8, 0.2, 0.2};
  const RenderResult result = Render(sphere, camera, 0.0, options);
  const cv::Rect box = cv::boundingRect(result.mask);
  const cv::Vec3b centre =
      result.image.at<cv::Vec3b>(box.y + box.height / 2, box.x + box.width / 2);
  const cv::Vec3b backdrop = result.image.at<cv::Vec3b>(5, 5);
  // Red like the backdrop behind it, a little dimmer.
  EXPECT_GT(centre[2], 2 * centre[1]);
  EXPECT_GT(centre[2], 0.75 * backdrop[2]);
  EXPECT_LT(centre[2], backdrop[2]);
  // The outline passes less: darker than the middle.
  // (Just inside it, clear of the pixels it shares with the backdrop.)
  cv::Mat in1, in3;
  cv::erode(result.mask, in1, cv::Mat(), cv::Point(-1, -1), 1);
  cv::erode(result.mask, in3, cv::Mat(), cv::Point(-1, -1), 3);
  const cv::Mat ring = in1 & ~in3;
  EXPECT_LT(cv::mean(result.image, ring)[2], centre[2] - 2.0);
}

// A finely tessellated disc under strong distortion: triangles split where the lens bends
// their edges, neighbours differently; no backdrop may show through between them.
TEST(RendererTest, SubdividedNeighboursLeaveNoCracks) {
  const Mesh disc = MakeDisc(0.12, 24, 3);  // large triangles: the lens bends them
  Scene scene;
  scene.source = "disc";
  for (Mesh::VertexHandle v : disc.vertices()) {
    const OpenMesh::Vec3d& p = disc.point(v);
    scene.positions.emplace_back(p[0], p[1], 0.0);
    scene.normals.emplace_back(0.0f, 0.0f, 1.0f);
    scene.uvs.emplace_back(0.0f, 0.0f);
  }
  for (Mesh::FaceHandle f : disc.faces()) {
    auto fv = disc.cfv_iter(f);
    const int a = fv->idx(), b = (++fv)->idx(), c = (++fv)->idx();
    scene.triangles.emplace_back(a, b, c);
    scene.triangle_material.push_back(0);
  }
  scene.materials.push_back(Material{"red", {0.8f, 0.05f, 0.05f}, -1, true});
  SimRigOptions rig;
  rig.width = 800;
  rig.height = 600;
  rig.elevations_deg = {60};
  rig.distance_m = 0.4;  // close: the disc reaches the image corners, where the lens bends most
  rig.distortion = {-0.35, 0.15, 0.002, -0.002, 0.0};
  const CameraModel camera = CameraAtTableAngle(MakeSimRig(rig, scene.Bounds()).front(), 0.4);
  RenderOptions options;
  options.plate_radius_m = 0;
  options.lit = false;
  options.samples_per_axis = 1;  // one sample per pixel: a crack would show as a pixel
  options.max_edge_error_px = 0.02;
  const RenderResult result = Render(scene, camera, 0.4, options);
  cv::Mat filled;
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_ELLIPSE, {7, 7});
  cv::morphologyEx(result.mask, filled, cv::MORPH_CLOSE, kernel);
  cv::Mat interior;
  cv::erode(filled, interior, kernel);
  cv::Mat holes;
  cv::bitwise_and(interior, ~result.mask, holes);
  EXPECT_GT(result.triangles_rasterized, scene.TriangleCount()) << "nothing was subdivided";
  EXPECT_GT(cv::countNonZero(interior), 50000);
  EXPECT_EQ(cv::countNonZero(holes), 0) << "pixels inside the disc show the backdrop";
}

TEST(RendererTest, RejectsBadOptions) {
  const Scene sphere = MakeSphereScene(0.08, {0, 0, 0.08}, 2);
  const CameraModel camera = StudioCamera(64, 48, 20, sphere.Bounds(), {});
  RenderOptions options;
  options.samples_per_axis = 0;
  CAROUSEL_EXPECT_THROW_WITH(Render(sphere, camera, 0, options), InvalidArgument,
                             "samples_per_axis");
  options = {};
  options.noise_sigma = -1;
  EXPECT_THROW(Render(sphere, camera, 0, options), InvalidArgument);
  CameraModel broken = camera;
  broken.fx = 0;
  EXPECT_THROW(Render(sphere, broken, 0, {}), InvalidArgument);
}

}  // namespace
}  // namespace carousel::sim
