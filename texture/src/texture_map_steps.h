// Internal: the steps of the texture map (texture_map.h), one file each, and what they share:
//   grouping.cpp       GroupFaces: per-view visibility and masks, front views, island cleanup;
//                      DepthBuffer
//   texture_map.cpp    TransferTexture: the transfer steps below, in order; the face data
//   transfer.cpp       ViewSampler; every chart's texels from the photos (per-texel correction)
//   gains.cpp          per-view colour gains
//   seam_blending.cpp  the paper's Eq. 8 across seam edges
//   filling.cpp        what no photo gives: holes, faces no view sees, the gutter
//   atlas_size.cpp     ChooseTextureSize (the texel density per face)
#pragma once

#include <array>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "carousel/core/camera_model.h"
#include "carousel/core/mesh.h"
#include "carousel/core/progress.h"
#include "carousel/core/view.h"
#include "carousel/texture/texture_map.h"

namespace carousel::texture::internal {

// A face's corners, normal and UVs, read once.
struct FaceData {
  std::array<Eigen::Vector3d, 3> p;
  std::array<Eigen::Vector2d, 3> uv;
  std::array<int, 3> across{-1, -1, -1};  // the face across edge (k, k + 1)
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  int chart = -1;
};

// \throw InvalidArgument for a face that is not a triangle.
std::vector<FaceData> ReadFaces(const Mesh& mesh);

// Sample points of a face (barycentric): centre, near each corner, near each edge's middle.
inline constexpr std::array<std::array<double, 3>, 7> kSamples = {{{1.0 / 3, 1.0 / 3, 1.0 / 3},
                                                                   {0.8, 0.1, 0.1},
                                                                   {0.1, 0.8, 0.1},
                                                                   {0.1, 0.1, 0.8},
                                                                   {0.45, 0.45, 0.1},
                                                                   {0.1, 0.45, 0.45},
                                                                   {0.45, 0.1, 0.45}}};

inline Eigen::Vector3d At(const FaceData& f, const std::array<double, 3>& b) {
  return b[0] * f.p[0] + b[1] * f.p[1] + b[2] * f.p[2];
}

// The face's area in the camera's image, pixels (0 when a corner is behind the camera).
double ProjectedArea(const FaceData& f, const CameraModel& camera);
// The face's area in the atlas, as a fraction of the atlas's.
double UvArea(const FaceData& f);

// Per-view depth buffer of the mesh (camera-frame z, metres) at a reduced resolution: the
// camera scaled so that its longer side is at most `max_side` pixels. Built in grouping.cpp;
// the grouping tests faces' sample points with it, the transfer each texel.
class DepthBuffer {
 public:
  DepthBuffer(const std::vector<FaceData>& faces, const CameraModel& camera, int max_side);

  // Whether the surface point (on a face seen at `cosine`) is the nearest thing the camera sees
  // along its ray. The tolerance is what the face's own depth changes over the 3 x 3 pixels
  // searched (its footprint over the cosine) plus 1 mm: a layer a few millimetres under another
  // (a thin wall's lining, a label's edge) stays hidden. Near an occluder's edge the nearest of
  // the 3 x 3 pixels is the occluder's: points just behind the edge count as hidden.
  bool Visible(const Eigen::Vector3d& point_world, double cosine) const;
  // The same for a point already projected: at `photo_px` in the full-size photo (pixel
  // centres at integers), camera-frame depth `z`.
  bool VisibleAt(const Eigen::Vector2d& photo_px, double z, double cosine) const;

 private:
  bool VisibleInBuffer(const Eigen::Vector2d& px, double z, double cosine) const;
  CameraModel camera_;
  Eigen::Vector2d scale_;                             // buffer pixels per photo pixel, x and y
  Eigen::Vector2d origin_ = Eigen::Vector2d::Zero();  // of depth_ in the scaled image
  cv::Mat depth_;  // CV_32F: the part of the scaled image the mesh covers
};

// \throw InvalidArgument (no views, an invalid camera).
void CheckViews(const std::vector<View>& views);

// ---- transfer.cpp ----------------------------------------------------------------------------

// The photos and eroded masks the transfer reads, loaded once: the photos of the views that
// are some face's front view, and with correction the masks (and photos) of the views that
// see some face; with gains, the photos of the views usable for some face too; with
// options.zbuffer_max_side, a depth buffer of the mesh per loaded photo. Colours are
// multiplied by the per-view gains (1 until SetGains).
// Only the part of each photo and mask the mesh projects into is kept (a 5184x3456 photo is
// 54 MB; the product covers a fraction of it), and the views' own cached pixels are released
// (they reload from their files when asked for again).
class ViewSampler {
 public:
  // \throw IoError/FormatError naming a photo or mask.
  ViewSampler(const std::vector<FaceData>& faces, const std::vector<View>& views,
              const GroupingResult& grouping, const TransferOptions& options);
  // A world point seen from view v: projected once (lens included), then tested and sampled.
  struct Located {
    Eigen::Vector2d px;  // in the full photo, pixel centres at integers
    double z = 0.0;      // camera-frame depth, metres
  };
  // Empty when `p` is behind view v's camera.
  std::optional<Located> Locate(int v, const Eigen::Vector3d& p) const;
  // Whether the point falls on view v's object (its eroded mask; true without a mask).
  bool OnObject(int v, const Located& at) const;
  bool OnObject(int v, const Eigen::Vector3d& p) const;
  // View v's photo at the point (Lanczos-3; bilinear at the border), times the view's gain;
  // false when v has no photo loaded, or the point is behind the camera or outside the photo.
  bool Sample(int v, const Located& at, cv::Vec3d* colour) const;
  bool Sample(int v, const Eigen::Vector3d& p, cv::Vec3d* colour) const;
  // Whether view v's depth buffer shows the point (on a face seen at `cosine`) unhidden; true
  // without one (options.zbuffer_max_side 0, or v's photo not loaded).
  bool Visible(int v, const Located& at, double cosine) const {
    return !depth_[v] || depth_[v]->VisibleAt(at.px, at.z, cosine);
  }
  // Whether v's photo is loaded (Sample can read it).
  bool HasPhoto(int v) const { return !photos_[v].empty(); }
  void SetGains(std::vector<cv::Vec3d> gains) { gains_ = std::move(gains); }
  const std::vector<cv::Vec3d>& gains() const { return gains_; }

 private:
  const std::vector<View>& views_;
  std::vector<cv::Mat> photos_;                    // the part in `origins_`'s box of each photo
  std::vector<cv::Mat> masks_;                     // likewise
  std::vector<std::optional<DepthBuffer>> depth_;  // of the views whose photo is loaded
  std::vector<Eigen::Vector2d> origins_;
  std::vector<cv::Vec3d> gains_;
};

// What the texel transfer leaves for the filling steps.
struct TransferredTexels {
  // Per face: the sum and count of its texels' colours (the faces no view sees take their
  // neighbours' mean).
  std::vector<cv::Vec3d> face_sum;
  std::vector<int> face_count;
  // Per chart: texels on the background in every view that sees their face.
  std::vector<std::vector<cv::Point>> holes;
};

// Fills the texels of every face that has a front view from the photos (charts in parallel:
// charts never share texels), blending across seams with options.blend and taking texels on
// the front photo's background from other views with options.correction. Writes `map`'s
// texture, coverage, texels_per_face, density_ratio, blended_texels, corrected_texels and
// occluded_texels.
// \pre map's images are size x size and zero, its per-face vectors sized and zero.
TransferredTexels TransferCharts(const std::vector<FaceData>& faces, const std::vector<View>& views,
                                 const GroupingResult& grouping, const ViewSampler& sampler,
                                 const TransferOptions& options, int size, Progress& progress,
                                 TextureMap* map);

// ---- gains.cpp -------------------------------------------------------------------------------

// Per-view BGR gains that bring every view to the common level (colours are multiplied by
// them): alternating least squares on the log colours of faces usable in several views.
// \pre the sampler's gains are 1.
std::vector<cv::Vec3d> EstimateGains(const std::vector<FaceData>& faces,
                                     const GroupingResult& grouping, const ViewSampler& sampler);

// ---- seam_blending.cpp -----------------------------------------------------------------------

// Per edge (k, k + 1) of face f, whose front view is `view`: the front view of the face across
// when it is another view usable for f (a seam edge), else -1.
std::array<int, 3> SeamViews(const std::vector<FaceData>& faces, int f, int view,
                             const GroupingResult& grouping);

// The paper's Eq. 8 at the texel of barycentrics `b` (surface point `p`): `colour`, from the
// face's front view, blended with the view across the nearest seam edge, d = D_c / D_f being
// the barycentric of the corner opposite that edge. With `correction`, only where `p` is on
// that view's object. Returns whether it blended.
bool BlendAcrossSeam(const ViewSampler& sampler, const std::array<int, 3>& seam,
                     const std::array<double, 3>& b, const Eigen::Vector3d& p, bool correction,
                     cv::Vec3d* colour);

// ---- filling.cpp -----------------------------------------------------------------------------

// The holes (background in every view) filled in rings of the surrounding texels' mean,
// inwards; islands without a good texel around take the texture's mean. Returns their count.
int InpaintHoles(const std::vector<std::vector<cv::Point>>& holes, TextureMap* map);

// The faces no view sees (front view -1) painted with the mean colour of their textured
// neighbours, spreading outwards; writes their texels_per_face. Returns their count.
int FillUnseenFaces(const std::vector<FaceData>& faces, const std::vector<int>& front_view,
                    const TransferredTexels& texels, TextureMap* map);

// The gutter grown by `texels` rings, each texel the mean of its covered neighbours; what is
// left takes the texture's mean colour (the coarsest mip levels blend towards it).
void DilateGutter(int texels, TextureMap* map);

}  // namespace carousel::texture::internal
