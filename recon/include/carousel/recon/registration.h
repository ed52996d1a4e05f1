// Registration of a second pass: the product photographed again lying another way (on its
// side, upside down), found in the first pass's (the object's) frame from the silhouettes
// alone, with no help from the operator.
//
// Each pass carves its own visual hull in its own turntable frame. Both hulls contain the
// product, so at the right pose every surface point of the first pass's hull that belongs to
// the product projects inside every silhouette of the second pass, and the other way round;
// where a hull is too large (what its pass could not see: the underside, concavities) its
// points stray outside, and those are truncated so that they do not pull. The cost is the
// sum of squares of the truncated distances, in metres at the point, of each hull's surface
// points outside the other pass's silhouettes (distance transforms of the masks, bilinear).
//
// Search: a coarse level (masks of ~200 px, a few hundred points, up to 8 views per pass)
// scores `rotations` uniformly sampled rotations, each with the translation that lays the two
// hulls' centroids on each other; the best distinct ones are refined by Levenberg-Marquardt
// (analytic Jacobian through the distance maps' bilinear slope and the lens; 6 parameters: a
// rotation about the product's centre and a translation) at the coarse and a middle level, the
// best three distinct at the finest (masks of up to `max_side_px`, each full-size mask reduced
// once for every level). A runner-up pose at least `distinct_deg` away whose residual is within
// `ambiguity_ratio` of the best makes the registration ambiguous (a nearly symmetric product):
// it is reported, never silently accepted, unless the photos' colours tell the poses apart
// (a symmetric bottle's label): the pose where the two passes' photos agree clearly better
// in colour at the first pass's hull points is taken, and the result says so. An ambiguous
// result lists the poses the silhouettes fit alike (`alternatives`, at least 30 deg apart),
// with pictures to tell them apart (PosePreviews): the operator chooses one, and registration
// started from it (RegisterPass's `start`) refines it without searching.
// Units: metres; frames as View cameras say (reference: the object frame, pass: its table's).
#pragma once

#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "carousel/core/options.h"
#include "carousel/core/progress.h"
#include "carousel/core/rigid3.h"
#include "carousel/core/view.h"

namespace carousel::recon {

struct RegistrationOptions {
  // Rotations scored at the coarse level, 100..200000.
  int rotations = 4000;
  // Distinct coarse poses refined, 1..64.
  int candidates = 12;
  // Poses whose rotations differ by more than this are distinct, degrees (0, 90].
  double distinct_deg = 10.0;
  // A distinct runner-up whose residual is within this factor of the best's makes the pose
  // ambiguous, > 1.
  double ambiguity_ratio = 1.25;
  // The passes do not show the same product when, at the best pose, more than this fraction
  // of the hulls' surface points lie over 3 pixels (of the finest level) outside some
  // silhouette of the other pass. What a pass did not see lies outside too: a product's own
  // passes leave 3-16 %, another product 40-50 %. 0..1.
  double max_inconsistent = 0.25;
  // Surface points per hull at the finest level, 100..100000.
  int points = 4000;
  // The finest level's masks: longest side at most this, pixels, 256..20000.
  int max_side_px = 1600;
  // Poses the silhouettes fit alike are told apart by the photos' colours (a symmetric
  // product with a label): the pose where both passes' photos show the same colours at the
  // same surface points, when it agrees clearly better than the others.
  bool colour = true;
  // Worker threads; 0 = one per hardware thread.
  int threads = 0;
  static const OptionTable<RegistrationOptions>& Fields();
  void Validate() const;
};

// A pose the silhouettes fit nearly as well as the best (an ambiguous registration).
struct PoseAlternative {
  Rigid3d table_from_object;
  double residual_ratio = 1.0;       // its residual / the best's
  double colour_correlation = -1.0;  // the passes' colours agree so well there (-1: not known)
};

struct RegistrationResult {
  // The pass's turntable frame from the reference's (the object) frame.
  Rigid3d table_from_object;
  // RMS over every (point, view) pair of the truncated distance outside the silhouettes at
  // the finest level: metres, and pixels of the full-size photos.
  double residual_m = 0.0;
  double residual_px = 0.0;
  double size_m = 0.0;  // the reference hull's box diagonal
  // The fraction of the hulls' surface points over 3 pixels outside some silhouette of the
  // other pass at the best pose.
  double inconsistent_fraction = 0.0;
  // Whether the best pose leaves at most max_inconsistent of the points outside.
  bool matches = false;
  // A distinct pose (>= distinct_deg away) nearly as good: the pose is not determined.
  bool ambiguous = false;
  double runner_up_ratio = 0.0;  // the runner-up's residual / the best's (0: none)
  double runner_up_deg = 0.0;    // its rotation's distance from the best's
  std::optional<Rigid3d> runner_up;
  // When ambiguous: the poses the silhouettes fit alike, at least 30 deg apart, the likeliest
  // first (the best colour agreement, else the smallest residual), at most 12.
  std::vector<PoseAlternative> alternatives;
  // Started from the operator's pose (RegisterPass's `start`): never ambiguous.
  bool started = false;
  // Poses the silhouettes fit alike, told apart by colour (options.colour): the correlation
  // of the passes' colours at the chosen pose and at the best other tied pose (-1: too few
  // points seen by both passes), the points compared, and whether colour decided the pose.
  bool colour_decided = false;
  double colour_correlation = 0.0;
  double runner_up_colour_correlation = 0.0;
  int colour_points = 0;
  int rotations_scored = 0;
  int points_reference = 0, points_pass = 0;
  double seconds_hulls = 0.0, seconds_search = 0.0, seconds_refine = 0.0, seconds_colour = 0.0,
         seconds_total = 0.0;
};

// With `start` (the operator's choice among an ambiguous result's alternatives) nothing is
// searched: the pose is refined from there, by the silhouettes and, within 30 deg of its turn
// about the upright axis, by the photos' colours (options.colour).
// \pre every view has a mask (View::Mask()); at least 2 views in each pass.
// \throw InvalidArgument (too few views, no mask, bad options), FormatError (an empty
//        silhouette, naming the view; a pass whose own silhouettes carve nothing), Cancelled.
RegistrationResult RegisterPass(const std::vector<View>& reference, const std::vector<View>& pass,
                                const RegistrationOptions& options, Progress& progress,
                                const std::optional<Rigid3d>& start = std::nullopt);

// Pictures for choosing among poses, one per pose: two photos of the reference from opposite
// sides, each beside the pass's photos' colours laid onto the reference's visual hull at that
// pose and seen from the same camera (grey where no photo of the pass sees the surface
// frontally, darker off the hull). At the right pose the two sides of a row look alike. CV_8UC3,
// each photo at most `side` pixels long. \pre every view has an image and a mask; at least 2 views
// in each pass; side >= 64. \throw as RegisterPass.
std::vector<cv::Mat> PosePreviews(const std::vector<View>& reference, const std::vector<View>& pass,
                                  const std::vector<Rigid3d>& poses, int side, int threads,
                                  Progress& progress);

// The angle of the rotation that takes a to b, degrees.
double RotationDistanceDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b);

}  // namespace carousel::recon
