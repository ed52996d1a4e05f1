// The texture map (texture paper, sections 4-5): each face's front image chosen among the
// photos, and the atlas's texels filled from it.
//
// Grouping: a face's candidates are the views that see it frontally (angle between the face
// normal and the direction to the camera under 90 deg) and unoccluded (its sample points pass
// a per-view z-buffer test); its front image is the candidate with the smallest angle. With
// correction on, a candidate whose silhouette mask puts any of the face's sample points on
// the background is refused too (the paper's missing-colour / white-spot fix): such a face
// moves to another view. Island cleanup then switches small groups whose front image differs
// from all their neighbours to a neighbour's image when that image is valid for them.
//
// Transfer works per texel: the texel's centre is mapped through its face's UV triangle to a
// surface point (taken from another view where the front view's depth buffer or mask shows it
// hidden or on the background), projected into the front photo with the full camera model (lens
// distortion included) and sampled with a Lanczos-3 kernel (sharper than bilinear interpolation,
// whose blur a viewer's own texture filtering adds to), so the texture is as sharp as the photo.
// Seam blending follows the paper's Eq. 8 near edges between faces of different front images;
// per-view colour gains (least squares over faces seen by several views) even out exposure
// differences; the gutter is dilated so that mip-mapping does not pull in black. Faces no
// view sees get the colour of their neighbours and are counted.
//
// Texel coordinates: atlas texel (x, y) has its centre at UV ((x + 0.5) / size,
// 1 - (y + 0.5) / size) (v up, row 0 at the top of the image); `size` is the atlas's side,
// decided once with the atlas (atlas_size.h).
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "carousel/core/mesh.h"
#include "carousel/core/options.h"
#include "carousel/core/progress.h"
#include "carousel/core/view.h"
#include "carousel/texture/atlas_size.h"

namespace carousel::texture {

struct GroupingOptions {
  // Views never used (held out for evaluation), by index.
  std::vector<int> exclude_views;
  // Refuse front images whose mask shows background under the face.
  bool correction = true;
  // Island cleanup: groups of at most this many faces may switch to a neighbour's view (0: off).
  int max_island_faces = 8;
  // Coherent front views: each face's choice costs 1 - (its cosine / the face's best cosine),
  // and every neighbouring face with another front view adds seam_cost; the sum is minimised
  // face by face (iterated conditional modes) from the most frontal choice, among views whose
  // cosine is at least min_cosine_ratio of the best. Where the mesh is off (a visual hull's
  // concavities), neighbouring faces' best views alternate and make a mosaic of triangle-sized
  // patches; this keeps large patches. 0: every face takes its most frontal view.
  double seam_cost = 0.25;
  double min_cosine_ratio = 0.7;
  // The capture pass of each view (empty: one pass). A face takes its front view from the
  // earliest pass that sees it nearly as frontally as any: a later pass (the product laid
  // down another way, lit another way) only where no view of an earlier one reaches
  // pass_cosine_ratio of the face's best cosine. 0: from whichever pass sees it best.
  std::vector<int> view_pass;
  double pass_cosine_ratio = 0.8;
  // Longest side of the per-view z-buffers, pixels (the photo is scaled down to it), 64..8192.
  int zbuffer_max_side = 1600;
  // The description of every field above (core/options.h): flags, widgets, range checks.
  static const OptionTable<GroupingOptions>& Fields();
  void Validate() const;
};

struct GroupingResult {
  std::vector<int> front_view;  // per face; Mesh::kNoView where no view sees the face
  // Per face and view (face * views + view): 1 where the view is a valid source for the face
  // (frontal, unoccluded, and on the mask when correcting).
  std::vector<unsigned char> usable;
  // Per face and view: frontal and unoccluded (whatever the mask says).
  std::vector<unsigned char> seen;
  int views = 0;
  int unseen_faces = 0;         // seen by no view
  int corrected_faces = 0;      // moved to another view by the mask check
  int uncorrectable_faces = 0;  // background under them in every view that sees them
  int island_faces_switched = 0;
  int coherence_faces_switched = 0;  // faces that took a neighbour's view (seam_cost)
  // Patches: connected groups of faces with the same front view (faces across an edge).
  int patches = 0;
  double mean_patch_faces = 0.0;
  double seconds = 0.0;
};

// \throw InvalidArgument (no views, a view without a mask while correcting, an excluded index
// out of range), IoError/FormatError naming a photo or mask, Cancelled.
GroupingResult GroupFaces(const Mesh& mesh, const std::vector<View>& views,
                          const GroupingOptions& options, Progress& progress);

// The atlas side is the atlas's (atlas_size.h), passed to TransferTexture.
struct TransferOptions {
  // Seam blending by the paper's Eq. 8.
  bool blend = true;
  // Per-view colour gains.
  bool gain = true;
  // Per-texel correction: a texel whose point falls on the front photo's background (mask)
  // is taken from another view that sees the face with the point on the object, or, when
  // none does, filled from the surrounding texels. Needs the views' masks. The same switch as
  // GroupingOptions::correction (--correction), which the texture session copies here; not
  // described in Fields() for that reason.
  bool correction = true;
  // Texels the charts are grown by into the gutter (0..64).
  int dilation_texels = 8;
  // Per-texel occlusion: the grouping sees a face whole in its front view by 7 sample points;
  // a texel between them that the view's depth buffer shows hidden (under a lace, behind a
  // fold) is taken from the most frontal other view that sees it, if one does. The longest
  // side of those depth buffers, pixels (64..8192); 0: no per-texel test.
  int zbuffer_max_side = 1600;
  // The description of every field above but `correction` (core/options.h).
  static const OptionTable<TransferOptions>& Fields();
  void Validate() const;
};

struct TextureMap {
  cv::Mat texture;   // CV_8UC3, BGR, size x size; row 0 is v = 1
  cv::Mat coverage;  // CV_8UC1, 255 where a face's texel is
  std::vector<int> texels_per_face;
  // Texels per front-photo pixel of each face (0 for faces no view sees).
  std::vector<double> density_ratio;
  std::vector<cv::Vec3d> gains;  // per view, BGR multipliers (1 when off)
  int filled_faces = 0;          // coloured from neighbours (no view sees them)
  int blended_texels = 0;
  int corrected_texels = 0;  // taken from another view than the face's (mask)
  int occluded_texels = 0;   // taken from another view: hidden in the face's (depth buffer)
  int inpainted_texels = 0;  // on the background in every view: filled from around
  double seconds = 0.0;
};

// `mesh` must have UVs and chart ids (BuildAtlas); `grouping` from GroupFaces on it;
// `atlas_size` the side the atlas was packed at (PackingResult::size, AtlasResult::size),
// kMinAtlasSize..kMaxAtlasSize.
// \throw InvalidArgument (no UVs, sizes), IoError/FormatError naming a photo, Cancelled.
TextureMap TransferTexture(const Mesh& mesh, const std::vector<View>& views,
                           const GroupingResult& grouping, int atlas_size,
                           const TransferOptions& options, Progress& progress);

}  // namespace carousel::texture
