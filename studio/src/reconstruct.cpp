#include "carousel/studio/reconstruct.h"

#include <algorithm>
#include <iomanip>
#include <limits>
#include <map>
#include <numeric>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/image_io.h"
#include "carousel/core/logging.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/parallel.h"
#include "carousel/core/timer.h"
#include "carousel/recon/reprojection.h"
#include "carousel/studio/checksum.h"
#include "carousel/studio/session.h"

namespace carousel::studio {
namespace {

// Background plates per view for the difference method, one file per camera.
std::vector<cv::Mat> LoadBackgrounds(const std::filesystem::path& folder, const Session& session) {
  std::map<int, cv::Mat> per_camera;
  std::vector<cv::Mat> backgrounds;
  for (const SessionView& view : session.views) {
    auto it = per_camera.find(view.camera);
    if (it == per_camera.end()) {
      const std::string stem = "backgrounds/cam" + std::to_string(view.camera);
      std::filesystem::path path = folder / (stem + ".jpg");
      if (!std::filesystem::exists(path)) path = folder / (stem + ".png");
      if (!std::filesystem::exists(path))
        throw IoError(folder / (stem + ".jpg"),
                      "no background plate for camera " + std::to_string(view.camera) +
                          " (the difference method needs a photo of the empty turntable)");
      cv::Mat image = ReadImage(path);
      if (image.cols != view.camera_model.width || image.rows != view.camera_model.height)
        throw FormatError(path, "background plate is " + std::to_string(image.cols) + "x" +
                                    std::to_string(image.rows) + ", the camera's photos are " +
                                    std::to_string(view.camera_model.width) + "x" +
                                    std::to_string(view.camera_model.height));
      it = per_camera.emplace(view.camera, image).first;
    }
    backgrounds.push_back(it->second);
  }
  return backgrounds;
}

// A hull that broke into more pieces than this while some view disagrees with the others
// (keeps less than kMinPieceConsistency of their hull), or that lost a quarter of its faces to
// small pieces, is broken: mesh optimization would grind on it. (A whole hull of a large
// product at full resolution sheds thousands of sub-voxel crumbs in its concavities, a few
// percent of its faces, with every view consistent: not broken.)
constexpr std::size_t kMaxHullPieces = 100;
constexpr double kMinPieceConsistency = 0.9;
constexpr double kMaxDroppedFaceFraction = 0.25;
// The mesh gets at most this many times --faces to keep its outline near the silhouettes.
constexpr int kMaxFaceFactor = 8;
// ... and twice the faces only while they bring the outline at least this much nearer.
constexpr double kMinFaceGain = 0.9;
// The optimized mesh reproduces every silhouette at least this well, or a view is at fault.
constexpr double kMinAgreementIoU = 0.8;
// Longest side of a diagnostic overlay, pixels.
constexpr int kDiagnosticSize = 1600;

constexpr const char* kDiagnosticsFolder = "recon/diagnostics";
// The pictures an ambiguous pass's poses are chosen by: each photo at most this long, pixels.
constexpr int kPosePictureSide = 480;

// Per named view, recon/diagnostics/<photo>.jpg: the photo with its silhouette's outline (red)
// and, when there is one, the hull's (green), at most kDiagnosticSize pixels along its longest
// side. Earlier overlays are removed first (they would describe another run). Returns the
// folder, relative to the session.
std::string WriteDiagnostics(const std::filesystem::path& folder, const std::vector<View>& views,
                             const std::vector<cv::Mat>& masks,
                             const std::vector<std::size_t>& which, const Mesh* hull) {
  const std::filesystem::path out = folder / kDiagnosticsFolder;
  std::filesystem::remove_all(out);
  std::filesystem::create_directories(out);
  for (const std::size_t v : which) {
    const View& view = views[v];
    cv::Mat photo = view.Image();
    const double scale =
        std::min(1.0, static_cast<double>(kDiagnosticSize) / std::max(photo.cols, photo.rows));
    auto outline = [&](const cv::Mat& mask) {
      cv::Mat small = mask;
      if (scale < 1.0) cv::resize(mask, small, cv::Size(), scale, scale, cv::INTER_AREA);
      std::vector<std::vector<cv::Point>> contours;
      cv::findContours(small >= 128, contours, cv::RETR_LIST, cv::CHAIN_APPROX_SIMPLE);
      return contours;
    };
    cv::Mat overlay;
    if (scale < 1.0)
      cv::resize(photo, overlay, cv::Size(), scale, scale, cv::INTER_AREA);
    else
      overlay = photo.clone();
    view.ReleasePixels();
    if (hull != nullptr && hull->n_faces() > 0)
      cv::drawContours(overlay, outline(recon::RasterizeSilhouette(*hull, view.camera())), -1,
                       cv::Scalar(0, 200, 0), 2, cv::LINE_AA);
    cv::drawContours(overlay, outline(masks[v]), -1, cv::Scalar(0, 0, 255), 2, cv::LINE_AA);
    WriteImage(out / (std::filesystem::path(view.name()).stem().string() + ".jpg"), overlay);
  }
  return kDiagnosticsFolder;
}

// The views by how little of the others' hull they keep, those below `below` (at least
// `at_least` of them): the ones that carve the hull apart.
std::vector<std::size_t> CarvingViews(const std::vector<double>& consistency, double below,
                                      std::size_t at_least) {
  std::vector<std::size_t> order(consistency.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return consistency[a] < consistency[b]; });
  std::size_t n = 0;
  while (n < order.size() && (n < at_least || consistency[order[n]] < below)) ++n;
  order.resize(n);
  return order;
}

std::string ViewList(const std::vector<View>& views, const std::vector<std::size_t>& which,
                     const std::vector<double>& consistency) {
  std::ostringstream list;
  for (std::size_t i = 0; i < which.size(); ++i) {
    list << (i ? ", " : "") << views[which[i]].name();
    if (which[i] < consistency.size())
      list << " (keeps " << cvRound(100.0 * consistency[which[i]]) << "% of the others' hull)";
  }
  return list.str();
}

// The first silhouettes of every view: given masks as they are, the others segmented (from
// the photos, the background plates or the mask shots); then the multi-view consistency step
// over all of them.
recon::SilhouettesResult FindSilhouettes(const std::filesystem::path& folder,
                                         const Session& session, const std::vector<View>& views,
                                         const std::vector<cv::Mat>& backgrounds,
                                         const std::vector<View>& mask_shots,
                                         const ReconstructOptions& options, Progress& progress) {
  std::vector<std::size_t> segmented;
  for (std::size_t i = 0; i < session.views.size(); ++i)
    if (session.views[i].given_mask.empty()) segmented.push_back(i);
  if (segmented.size() == views.size())
    return recon::ComputeSilhouettes(views, backgrounds, options.silhouettes, progress,
                                     options.hull, mask_shots);
  recon::SilhouettesResult result;
  result.masks.resize(views.size());
  result.stats.resize(views.size());
  if (!segmented.empty()) {
    std::vector<View> sub_views, sub_shots;
    std::vector<cv::Mat> sub_backgrounds;
    for (const std::size_t i : segmented) {
      sub_views.push_back(views[i]);
      if (!mask_shots.empty()) sub_shots.push_back(mask_shots[i]);
      if (!backgrounds.empty()) sub_backgrounds.push_back(backgrounds[i]);
    }
    recon::SilhouetteOptions first = options.silhouettes;
    first.multi_view = false;  // below, over every view
    recon::SilhouettesResult sub = recon::ComputeSilhouettes(sub_views, sub_backgrounds, first,
                                                             progress, options.hull, sub_shots);
    for (std::size_t k = 0; k < segmented.size(); ++k) {
      result.masks[segmented[k]] = sub.masks[k];
      result.stats[segmented[k]] = sub.stats[k];
    }
  }
  for (std::size_t i = 0; i < views.size(); ++i) {
    const SessionView& entry = session.views[i];
    if (entry.given_mask.empty()) continue;
    const View given(entry.camera_model, folder / entry.image, folder / entry.given_mask);
    result.masks[i] = given.Mask().clone();
    result.stats[i].given = true;
    result.stats[i].object_fraction =
        cv::countNonZero(result.masks[i] >= 128) / static_cast<double>(result.masks[i].total());
    if (result.stats[i].object_fraction == 0.0)
      throw FormatError(folder / entry.given_mask, "the given mask is empty (no object)");
  }
  if (options.silhouettes.multi_view && views.size() >= 4)
    recon::MakeConsistent(views, backgrounds, options.silhouettes, options.hull, &result, progress,
                          mask_shots);
  return result;
}

// FindSilhouettes for each pass on its own (each in its own turntable frame: the plate is
// removed and the views checked against each other there). A later pass whose silhouettes
// cannot be found (out of frame, ...) is named in `failed` with the reason, its masks left
// empty: the first pass's model is made all the same.
recon::SilhouettesResult FindSilhouettesPerPass(
    const std::filesystem::path& folder, const Session& session, const std::vector<View>& views,
    const std::vector<cv::Mat>& backgrounds, const std::vector<View>& mask_shots,
    const ReconstructOptions& options, Progress& progress, std::map<int, std::string>* failed) {
  if (!HasSeveralPasses(session))
    return FindSilhouettes(folder, session, views, backgrounds, mask_shots, options, progress);
  recon::SilhouettesResult result;
  result.masks.resize(views.size());
  result.stats.resize(views.size());
  const int passes = session.views.back().pass + 1;
  for (int pass = 0; pass < passes; ++pass) {
    std::vector<std::size_t> which;
    for (std::size_t i = 0; i < session.views.size(); ++i)
      if (session.views[i].pass == pass) which.push_back(i);
    if (which.empty()) continue;
    Session sub = session;
    sub.views.clear();
    std::vector<View> sub_views, sub_shots;
    std::vector<cv::Mat> sub_backgrounds;
    for (const std::size_t i : which) {
      sub.views.push_back(session.views[i]);
      sub_views.push_back(views[i]);
      if (!mask_shots.empty()) sub_shots.push_back(mask_shots[i]);
      if (!backgrounds.empty()) sub_backgrounds.push_back(backgrounds[i]);
    }
    recon::SilhouettesResult found;
    try {
      found =
          FindSilhouettes(folder, sub, sub_views, sub_backgrounds, sub_shots, options, progress);
    } catch (const Cancelled&) {
      throw;
    } catch (const Error& e) {
      if (pass == 0) throw;
      (*failed)[pass] = e.what();
      continue;
    }
    for (std::size_t k = 0; k < which.size(); ++k) {
      result.masks[which[k]] = found.masks[k];
      result.stats[which[k]] = found.stats[k];
    }
  }
  return result;
}

std::string Millimetres(double metres) {
  std::ostringstream text;
  text << std::fixed << std::setprecision(2) << metres * 1e3 << " mm";
  return text.str();
}

// The pictures an ambiguous pass's poses are chosen by: recon/pass<N>_pose<K>.jpg (N, K
// 1-based; the pass's older pictures go). Returns their names for people.
std::string WritePosePictures(const std::filesystem::path& folder, int pass,
                              const std::vector<View>& reference, const std::vector<View>& moved,
                              const std::vector<Rigid3d>& poses, const ReconstructOptions& options,
                              Progress& progress) {
  const std::string stem = "pass" + std::to_string(pass + 1) + "_pose";
  std::filesystem::create_directories(folder / "recon");
  for (const auto& entry : std::filesystem::directory_iterator(folder / "recon"))
    if (entry.path().filename().string().starts_with(stem)) std::filesystem::remove(entry.path());
  const std::vector<cv::Mat> pictures = recon::PosePreviews(
      reference, moved, poses, kPosePictureSide, options.hull.threads, progress);
  for (std::size_t k = 0; k < pictures.size(); ++k)
    WriteImage(folder / "recon" / (stem + std::to_string(k + 1) + ".jpg"), pictures[k],
               {.jpeg_quality = 90});
  return "recon/" + stem + "1.jpg to " + stem + std::to_string(pictures.size()) + ".jpg";
}

// "PASS:POSE[,PASS:POSE...]" as (pass, pose) pairs, both 1-based. \throw InvalidArgument.
std::vector<std::pair<int, int>> ParsePoseChoices(const std::string& text) {
  std::vector<std::pair<int, int>> choices;
  std::istringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    int pass = 0, pose = 0;
    char colon = 0;
    std::istringstream one(item);
    if (!(one >> pass >> colon >> pose) || colon != ':' || !(one >> std::ws).eof() || pass < 2 ||
        pose < 1)
      throw InvalidArgument("--choose-pose: '" + item +
                            "' is not PASS:POSE (a later pass, 2 or more, and a pose, 1 or more; "
                            "e.g. 2:3)");
    choices.emplace_back(pass, pose);
  }
  return choices;
}

// Registers every later pass to pass 0 (views: every photo in its own table frame, masks
// set), records the outcome in the session, and maps the registered passes' cameras into the
// object frame. Returns the outcomes; a pass that is not registered (out of frame, another
// product, an ambiguous pose) is named with the reason and left out of the model.
std::vector<PassOutcome> RegisterPasses(const std::filesystem::path& folder,
                                        const Session& session_in, Session& session,
                                        std::vector<View>& views,
                                        const std::map<int, std::string>& silhouettes_failed,
                                        const ReconstructOptions& options, Progress& progress) {
  std::vector<PassOutcome> outcomes;
  const int passes = session_in.views.back().pass + 1;
  std::vector<View> reference;
  for (std::size_t i = 0; i < views.size(); ++i)
    if (session.views[i].pass == 0) reference.push_back(views[i]);
  int unregistered = 0;  // the first pass not registered (0: none yet)
  for (int pass = 1; pass < passes; ++pass) {
    PassOutcome outcome;
    outcome.pass = pass;
    SessionPass& record = session.passes.at(static_cast<std::size_t>(pass));
    outcome.orientation = record.orientation;
    const std::string name = "pass " + std::to_string(pass + 1) + " (" + record.orientation + ")";
    std::vector<std::size_t> which;
    for (std::size_t i = 0; i < views.size(); ++i)
      if (session.views[i].pass == pass) which.push_back(i);
    outcome.views = static_cast<int>(which.size());
    // A pass whose product runs out of the frame failed in its silhouettes already (their
    // border check names the photo).
    std::vector<View> moved;
    if (!silhouettes_failed.contains(pass))
      for (const std::size_t i : which) moved.push_back(views[i]);
    record.table_from_object.reset();
    // The operator's choice among the poses an earlier run found alike.
    std::optional<Rigid3d> start;
    if (record.chosen_pose > 0 &&
        record.chosen_pose <= static_cast<int>(record.pose_choices.size()))
      start = record.pose_choices[static_cast<std::size_t>(record.chosen_pose - 1)];
    if (!start) record.pose_choices.clear();
    if (unregistered > 0) {
      // The passes reach the model in order (SessionViews).
      outcome.status = "failed";
      outcome.note = name + ": not used, because pass " + std::to_string(unregistered + 1) +
                     " before it was not registered";
    } else if (const auto it = silhouettes_failed.find(pass); it != silhouettes_failed.end()) {
      outcome.status = "failed";
      outcome.note = name + ": its silhouettes cannot be found: " + it->second;
    } else if (which.size() < 2) {
      outcome.status = "failed";
      outcome.note = name + " has " + std::to_string(which.size()) + " view(s); it needs 2 or more";
    } else {
      try {
        recon::RegistrationOptions registration = options.registration;
        registration.threads = options.hull.threads;
        const recon::RegistrationResult found =
            recon::RegisterPass(reference, moved, registration, progress, start);
        outcome.registration = found;
        std::ostringstream note;
        note << name << ": residual " << std::fixed << std::setprecision(2) << found.residual_px
             << " px (" << Millimetres(found.residual_m) << "), " << std::setprecision(0)
             << 100.0 * found.inconsistent_fraction
             << "% of the hulls' points outside the other pass's silhouettes";
        if (start)
          note << ", from the pose the operator chose (" << record.chosen_pose << " of "
               << record.pose_choices.size() << ")";
        if (found.runner_up)
          note << ", the next pose " << std::setprecision(1) << found.runner_up_deg
               << " deg away fits " << std::setprecision(2) << found.runner_up_ratio
               << " times worse";
        if (found.colour_decided)
          note << "; the silhouettes fit such poses alike, and the photos' colours chose this "
                  "one (they agree with a correlation of "
               << std::setprecision(2) << found.colour_correlation << " there, at most "
               << found.runner_up_colour_correlation << " at the others)";
        else if (found.started && found.colour_points > 0)
          note << "; near it the photos' colours agree best (correlation " << std::setprecision(2)
               << found.colour_correlation << ")";
        else if (found.colour_points > 0)
          note << "; nor do the photos' colours tell the poses apart (correlation "
               << std::setprecision(2) << found.colour_correlation << " against "
               << found.runner_up_colour_correlation << ")";
        if (!found.matches) {
          outcome.status = "failed";
          outcome.note = note.str() +
                         ": its silhouettes do not fit pass 1's at any pose, so it does not show "
                         "the same product, or its silhouettes miss part of it (a part the "
                         "colour of the backdrop: take backlit mask shots)";
        } else if (found.ambiguous) {
          outcome.status = "ambiguous";
          for (const recon::PoseAlternative& alternative : found.alternatives)
            record.pose_choices.push_back(alternative.table_from_object);
          const std::string pictures = WritePosePictures(folder, pass, reference, moved,
                                                         record.pose_choices, options, progress);
          std::ostringstream choose;
          choose << ": the pose is ambiguous, the product's silhouettes look alike turned (a "
                    "symmetric product). Choose the pose: "
                 << pictures << " show pass 1's photos beside pass " << pass + 1
                 << "'s colours laid on its shape at each of " << record.pose_choices.size()
                 << " poses; where the two sides of each row look alike, the pose is right: "
                    "choose it (carousel process "
                 << folder.string() << " --choose-pose " << pass + 1
                 << ":K, or the picture's button in the window). Or lay the product down so "
                    "that it does not look alike, or leave the pass out";
          outcome.note = note.str() + choose.str();
        } else {
          outcome.status = "registered";
          outcome.note = note.str();
          record.table_from_object = found.table_from_object;
        }
      } catch (const Cancelled&) {
        throw;
      } catch (const Error& e) {
        outcome.status = "failed";
        outcome.note = name + " cannot be registered: " + e.what();
      }
    }
    record.registration = outcome.status;
    record.registration_note = outcome.note;
    if (outcome.status == "registered") {
      CAROUSEL_LOG_INFO(outcome.note);
      for (const std::size_t i : which) {
        CameraModel camera = views[i].camera();
        camera.cam_from_world = camera.cam_from_world * *record.table_from_object;
        views[i].mutable_camera() = camera;
      }
    } else {
      if (unregistered == 0) unregistered = pass;
      CAROUSEL_LOG_WARN(outcome.note << "; the model is made without it");
    }
    outcomes.push_back(outcome);
  }
  return outcomes;
}

}  // namespace

std::vector<std::string> AdoptEditedMasks(const std::filesystem::path& folder, Session& session) {
  std::vector<std::string> edited;
  for (SessionView& view : session.views) {
    if (view.mask.empty() || view.mask_sha256.empty()) continue;
    const std::filesystem::path file = folder / view.mask;
    if (!std::filesystem::is_regular_file(file) || FileSha256(file) == view.mask_sha256) continue;
    const std::string given = "masks/given/" + std::filesystem::path(view.mask).filename().string();
    std::filesystem::create_directories(folder / "masks/given");
    WriteFileAtomic(folder / given, ReadFileBytes(file));
    view.given_mask = given;
    view.given_mask_sha256 = FileSha256(folder / given);
    view.mask_sha256.clear();
    edited.push_back(view.mask);
    CAROUSEL_LOG_WARN(view.mask << " was edited since the reconstruction: kept as " << given
                                << " and taken as given (checked against the other views)");
  }
  if (!edited.empty()) WriteSessionManifest(folder, session);
  return edited;
}

const OptionTable<ReconstructOptions>& ReconstructOptions::Fields() {
  static const OptionTable<ReconstructOptions> table =
      OptionTable<ReconstructOptions>()
          .Include(&ReconstructOptions::silhouettes, recon::SilhouetteOptions::Fields())
          .Include(&ReconstructOptions::hull, recon::VisualHullOptions::Fields())
          .Include(&ReconstructOptions::mesh, recon::MeshOptimizationOptions::Fields())
          .Include(&ReconstructOptions::registration, recon::RegistrationOptions::Fields())
          .Add(&ReconstructOptions::max_outline_deviation_px,
               {.name = "max-outline-deviation",
                .help = "a mesh whose outline strays further from the silhouettes on average is "
                        "made again with twice the faces (up to 8x --faces)",
                .unit = "px",
                .min = 0,
                .special = 0,
                .special_meaning = "never"})
          .Add(&ReconstructOptions::choose_pose,
               {.name = "choose-pose",
                .help = "for a pass whose pose was ambiguous, the pose its pictures show right: "
                        "PASS:POSE[,PASS:POSE...], e.g. 2:3 for recon/pass2_pose3.jpg (kept in "
                        "the session)",
                .advanced = true});
  return table;
}

void ReconstructOptions::Validate() const {
  silhouettes.Validate();
  hull.Validate();
  mesh.Validate();
  registration.Validate();
  Fields().Check(*this);
  ParsePoseChoices(choose_pose);
}

bool ApplyPoseChoices(Session& session, const std::string& choices) {
  bool changed = false;
  for (const auto& [pass, pose] : ParsePoseChoices(choices)) {
    const std::string given =
        "--choose-pose " + std::to_string(pass) + ":" + std::to_string(pose) + ": ";
    if (pass > static_cast<int>(session.passes.size()))
      throw InvalidArgument(given + "the session has " + std::to_string(session.passes.size()) +
                            " pass(es)");
    SessionPass& record = session.passes[static_cast<std::size_t>(pass - 1)];
    const std::string name = "pass " + std::to_string(pass) + " (" + record.orientation + ")";
    if (record.pose_choices.empty())
      throw InvalidArgument(
          given + name + " has no poses to choose from: only a pass whose pose " +
          "was found ambiguous has (it is " +
          (record.registration.empty() ? "not registered yet" : record.registration) + ")");
    const int count = static_cast<int>(record.pose_choices.size());
    if (pose > count)
      throw InvalidArgument(given + name + " has " + std::to_string(count) +
                            " poses to choose from (recon/pass" + std::to_string(pass) +
                            "_pose1.jpg to _pose" + std::to_string(count) + ".jpg)");
    changed = changed || record.chosen_pose != pose;
    record.chosen_pose = pose;
  }
  return changed;
}

ReconstructResult ReconstructSession(const std::filesystem::path& session_folder,
                                     const ReconstructOptions& options, Progress& progress) {
  options.Validate();  // a bad option is named before any file is read
  Session session = ReadSession(session_folder);
  return ReconstructSession(session_folder, session, options, progress);
}

ReconstructResult ReconstructSession(const std::filesystem::path& session_folder, Session& session,
                                     const ReconstructOptions& requested, Progress& progress) {
  requested.Validate();
  if (session.views.size() < 2)
    throw FormatError(session_folder / kManifestName,
                      "a reconstruction needs at least 2 views, the session has " +
                          std::to_string(session.views.size()));
  ApplyPoseChoices(session, requested.choose_pose);
  ReconstructOptions options = requested;
  if (session.frame != "turntable") {
    // Not on our turntable: no plate to remove, no floor to stand on.
    options.silhouettes.plate_radius_m = 0.0;
    options.hull.use_floor = false;
  }
  AdoptEditedMasks(session_folder, session);
  std::vector<View> views = SessionTableViews(session_folder, session);
  const std::vector<View> mask_shots = SessionMaskShotViews(session_folder, session);
  ReconstructResult result;
  result.views = static_cast<int>(views.size());
  result.method = recon::SilhouetteMethodName(
      recon::ResolveSilhouetteMethod(options.silhouettes.method, views.size(), mask_shots.size()));

  // Silhouettes -> masks/.
  Stopwatch watch;
  std::vector<cv::Mat> backgrounds;
  if (options.silhouettes.method == recon::SilhouetteMethod::kDifference)
    backgrounds = LoadBackgrounds(session_folder, session);
  std::map<int, std::string> silhouettes_failed;
  const recon::SilhouettesResult silhouettes =
      FindSilhouettesPerPass(session_folder, session, views, backgrounds, mask_shots, options,
                             progress, &silhouettes_failed);
  result.given_masks =
      static_cast<int>(std::count_if(silhouettes.stats.begin(), silhouettes.stats.end(),
                                     [](const recon::SilhouetteStats& s) { return s.given; }));
  for (const recon::SilhouetteStats& s : silhouettes.stats) result.redecided += s.redecided ? 1 : 0;
  std::filesystem::create_directories(session_folder / "masks");
  result.min_mask_fraction = 1.0;
  // The masks are encoded in parallel (18 MP PNGs take a few tenths of a second each); binary
  // masks compress well at the fastest level.
  ParallelFor(views.size(), 1, options.hull.threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      if (silhouettes.masks[i].empty()) continue;  // a later pass that failed
      const std::string mask =
          "masks/" + std::filesystem::path(session.views[i].image).stem().string() + ".png";
      WriteImage(session_folder / mask, silhouettes.masks[i], {.png_compression = 1});
    }
  });
  for (std::size_t i = 0; i < views.size(); ++i) {
    if (silhouettes.masks[i].empty()) {
      session.views[i].mask.clear();
      session.views[i].mask_sha256.clear();
      continue;
    }
    const std::string mask =
        "masks/" + std::filesystem::path(session.views[i].image).stem().string() + ".png";
    session.views[i].mask = mask;
    // A later edit of the mask shows against this (AdoptEditedMasks).
    session.views[i].mask_sha256 = FileSha256(session_folder / mask);
    views[i].set_mask_path(session_folder / mask);
    views[i].SetMask(silhouettes.masks[i]);
    result.min_mask_fraction =
        std::min(result.min_mask_fraction, silhouettes.stats[i].object_fraction);
  }
  result.seconds_silhouettes = watch.ElapsedSeconds();

  // Later passes -> registered into the object frame, or left out (named, with the reason).
  // The model is made from pass 0 and the registered passes that follow it (SessionViews).
  std::vector<cv::Mat> masks = silhouettes.masks;
  if (HasSeveralPasses(session)) {
    watch.Restart();
    const Session before = session;
    result.passes = RegisterPasses(session_folder, before, session, views, silhouettes_failed,
                                   options, progress);
    std::size_t used = 0;
    while (used < views.size() &&
           (session.views[used].pass == 0 ||
            session.passes[static_cast<std::size_t>(session.views[used].pass)].registration ==
                "registered"))
      ++used;
    views.resize(used);
    masks.resize(used);
    result.seconds_registration = watch.ElapsedSeconds();
    session.stage_seconds["reconstruct/registration"] = result.seconds_registration;
  }
  result.model_views = static_cast<int>(views.size());

  // Visual hull -> recon/hull.ply. A broken hull stops here, with the views that carve it
  // apart named and their overlays in recon/diagnostics/ (the masks stay for inspection).
  watch.Restart();
  std::filesystem::remove_all(session_folder / kDiagnosticsFolder);
  recon::VisualHullResult hull;
  try {
    hull = recon::ComputeVisualHull(views, options.hull, progress);
  } catch (const recon::InconsistentViews& e) {
    const std::string where = WriteDiagnostics(session_folder, views, masks, e.views(), nullptr);
    throw FormatError(e.path(), e.reason() + "; each view's mask outline on its photo: " + where);
  }
  const std::size_t kept_faces = hull.mesh.n_faces();
  const double dropped_fraction =
      static_cast<double>(hull.faces_dropped) /
      static_cast<double>(std::max<std::size_t>(1, kept_faces + hull.faces_dropped));
  const bool views_disagree = !hull.view_consistency.empty() &&
                              *std::min_element(hull.view_consistency.begin(),
                                                hull.view_consistency.end()) < kMinPieceConsistency;
  if ((hull.components_dropped > kMaxHullPieces && views_disagree) ||
      dropped_fraction > kMaxDroppedFaceFraction) {
    const std::vector<std::size_t> culprits = CarvingViews(hull.view_consistency, 0.9, 3);
    const std::string where = WriteDiagnostics(session_folder, views, masks, culprits, &hull.mesh);
    std::ostringstream reason;
    reason << "the visual hull breaks apart: " << hull.components_dropped
           << " pieces beside the largest (" << hull.faces_dropped << " of "
           << kept_faces + hull.faces_dropped
           << " faces), so the silhouettes or the calibration are wrong; the views that carve "
              "it most: "
           << ViewList(views, culprits, hull.view_consistency)
           << "; each view's mask (red) and the hull (green) on its photo: " << where;
    throw FormatError(session_folder / "masks", reason.str());
  }
  std::filesystem::create_directories(session_folder / "recon");
  WriteMesh(hull.mesh, session_folder / "recon/hull.ply");
  result.hull_faces = hull.mesh.n_faces();
  result.voxel_size_m = hull.voxel_size_m;
  result.seconds_hull = watch.ElapsedSeconds();

  // Optimized mesh -> recon/mesh.ply.
  // How well the mesh reproduces the silhouettes: calibration or mask trouble shows here. A
  // mesh whose outline strays further than max_outline_deviation_px on average is made again
  // with twice the faces (up to kMaxFaceFactor times --faces): photos sharp enough to show
  // more than the face budget holds get it.
  watch.Restart();
  recon::MeshOptimizationOptions mesh_options = options.mesh;
  mesh_options.target_volume_m3 = hull.volume_m3;
  recon::MeshOptimizationResult mesh;
  std::vector<recon::SilhouetteAgreement> agreement;
  double seconds_agreement = 0.0;
  double previous = std::numeric_limits<double>::infinity();
  for (;;) {
    recon::MeshOptimizationResult candidate =
        recon::OptimizeMesh(hull.OptimizationInput(), mesh_options, progress);
    Stopwatch measure;
    std::vector<recon::SilhouetteAgreement> measured =
        recon::MeasureSilhouetteAgreement(candidate.mesh, views, options.hull.threads);
    seconds_agreement += measure.ElapsedSeconds();
    double deviation = 0.0;
    for (const recon::SilhouetteAgreement& a : measured)
      deviation += a.mean_deviation_px / static_cast<double>(measured.size());
    // More faces that bring the outline no nearer (the silhouettes or the calibration are
    // what stray) are not kept.
    if (deviation > kMinFaceGain * previous) break;
    mesh = std::move(candidate);
    agreement = std::move(measured);
    previous = deviation;
    if (options.max_outline_deviation_px <= 0.0 || deviation <= options.max_outline_deviation_px ||
        mesh_options.target_faces * 2 > kMaxFaceFactor * options.mesh.target_faces)
      break;
    mesh_options.target_faces *= 2;
    CAROUSEL_LOG_INFO("mesh: outline " << deviation << " px from the silhouettes on average, over "
                                       << options.max_outline_deviation_px << " px: again with "
                                       << mesh_options.target_faces << " faces");
  }
  result.agreement = std::move(agreement);
  WriteMesh(mesh.mesh, session_folder / "recon/mesh.ply");
  result.mesh_faces = mesh.mesh.n_faces();
  result.seconds_mesh = watch.ElapsedSeconds() - seconds_agreement;
  result.seconds_agreement = seconds_agreement;
  {
    std::vector<std::size_t> disagreeing;
    for (std::size_t v = 0; v < result.agreement.size(); ++v)
      if (result.agreement[v].iou < kMinAgreementIoU) disagreeing.push_back(v);
    if (!disagreeing.empty()) {
      // The views that disagree, and those that carve the others' hull (a bad view carves the
      // object from the others, which then disagree).
      std::vector<std::size_t> named = CarvingViews(hull.view_consistency, 0.9, 1);
      for (const std::size_t v : disagreeing)
        if (std::find(named.begin(), named.end(), v) == named.end()) named.push_back(v);
      const std::string where = WriteDiagnostics(session_folder, views, masks, named, &mesh.mesh);
      std::ostringstream reason;
      reason << "the mesh does not reproduce " << disagreeing.size() << " view(s)' silhouettes"
             << " (IoU below " << kMinAgreementIoU << "):";
      for (std::size_t i = 0; i < disagreeing.size(); ++i)
        reason << (i ? ", " : " ") << views[disagreeing[i]].name() << " ("
               << cvRound(100.0 * result.agreement[disagreeing[i]].iou) << "%)";
      reason << "; the view that carves the others' hull most: "
             << ViewList(views, {named.front()}, hull.view_consistency)
             << "; wrong masks or calibration; each view's mask (red) and the mesh (green) on "
                "its photo: "
             << where;
      throw FormatError(session_folder / "masks", reason.str());
    }
  }

  session.stages["reconstruct"] = "done";
  session.stage_seconds["reconstruct/silhouettes"] = result.seconds_silhouettes;
  session.stage_seconds["reconstruct/hull"] = result.seconds_hull;
  session.stage_seconds["reconstruct/mesh"] = result.seconds_mesh;
  session.stage_seconds["reconstruct/agreement"] = result.seconds_agreement;
  WriteSessionManifest(session_folder, session);
  return result;
}

}  // namespace carousel::studio
