#include "carousel/studio/capture.h"

#include <algorithm>
#include <chrono>
#include <exception>
#include <future>
#include <map>
#include <numbers>
#include <optional>
#include <thread>
#include <tuple>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/core/logging.h"
#include "carousel/core/timer.h"
#include "carousel/sim/sim_rig.h"
#include "carousel/studio/checksum.h"

namespace carousel::studio {
namespace {

// Moves a damaged photo aside into <session>/damaged/ (never deletes captured data).
void MoveAside(const std::filesystem::path& file) {
  const auto folder = file.parent_path().parent_path() / "damaged";
  std::filesystem::create_directories(folder);
  for (int n = 1;; ++n) {
    const auto aside = folder / (file.filename().string() + "." + std::to_string(n));
    if (!std::filesystem::exists(aside)) {
      std::filesystem::rename(file, aside);
      CAROUSEL_LOG_WARN("moved the damaged photo " << file.string() << " aside to " << aside);
      return;
    }
  }
}

// Whether `file` is a complete photo of `camera`'s size.
bool IsCompletePhoto(const std::filesystem::path& file, const CameraModel& camera) {
  try {
    const cv::Mat image = ReadImage(file);
    return image.cols == camera.width && image.rows == camera.height;
  } catch (const Error&) {
    return false;
  }
}

// Waits for every future; returns the results, and rethrows the first error only after all
// have finished (no camera is left mid-operation).
template <typename T>
std::vector<std::optional<T>> JoinAll(std::vector<std::future<T>>& futures,
                                      std::exception_ptr* error) {
  std::vector<std::optional<T>> results(futures.size());
  for (std::size_t i = 0; i < futures.size(); ++i) {
    try {
      results[i] = futures[i].get();
    } catch (...) {
      if (!*error) *error = std::current_exception();
    }
  }
  return results;
}

}  // namespace

std::string MaskShotPath(int camera, int stop, int pass) {
  return "images/" + ViewStem(camera, stop, pass) + kMaskShotSuffix + ".jpg";
}

// Removes the temporary files atomic writes leave behind when a process is killed.
void RemoveStaleTemporaries(const std::filesystem::path& folder) {
  std::error_code ec;
  for (const char* sub : {"", "images", "masks", "recon", "model"}) {
    const auto dir = folder / sub;
    if (!std::filesystem::is_directory(dir, ec)) continue;
    for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
      const std::string name = entry.path().filename().string();
      if (name.size() > 1 && name[0] == '.' && name.find(".tmp-") != std::string::npos) {
        CAROUSEL_LOG_INFO("removing the stale temporary file " << entry.path().string());
        std::filesystem::remove(entry.path(), ec);
      }
    }
  }
}

CaptureResult CaptureSession(const std::filesystem::path& folder, Session& session,
                             RigBackends& rig, int placements, Progress& progress) {
  CaptureResult result;
  Stopwatch watch;
  progress.BeginStage("capture");
  const CapturePlan& plan = rig.plan;
  const bool mask_shots = plan.mask_shots == "backlit";
  const auto move_timeout =
      std::chrono::milliseconds(static_cast<long long>(plan.move_timeout_s * 1000));
  const auto camera_timeout =
      std::chrono::milliseconds(static_cast<long long>(plan.camera_timeout_s * 1000));
  std::filesystem::create_directories(folder / "images");
  // What is recorded and verified (a view's photo, and its mask shot when the plan takes them).
  std::map<std::string, SessionView> recorded;
  auto verified = [&](const std::string& file, const std::string& sha256) {
    return !sha256.empty() && std::filesystem::is_regular_file(folder / file) &&
           FileSha256(folder / file) == sha256;
  };
  for (SessionView view : session.views) {
    if (!verified(view.image, view.sha256)) {
      if (std::filesystem::exists(folder / view.image)) MoveAside(folder / view.image);
      ++result.photos_retaken;
      // Its mask shot is checked again when the photo is retaken.
      continue;
    }
    ++result.photos_kept;
    if (!view.mask_shot.empty()) {
      if (verified(view.mask_shot, view.mask_shot_sha256)) {
        ++result.photos_kept;
      } else {
        if (std::filesystem::exists(folder / view.mask_shot)) MoveAside(folder / view.mask_shot);
        ++result.photos_retaken;
        view.mask_shot.clear();
        view.mask_shot_sha256.clear();
      }
    }
    recorded[view.image] = view;
  }
  session.views.clear();
  for (const auto& [name, view] : recorded) session.views.push_back(view);
  const int cameras = static_cast<int>(rig.cameras.size());
  // A calibration session turns the table once per board placement; a product session once per
  // orientation (pass), its views tagged with their pass.
  const int passes = rig.place_board ? 1 : std::max(1, plan.orientations);
  const int total_stops = plan.stops * placements * passes;
  if (passes > 1 && static_cast<int>(session.passes.size()) != passes) {
    session.passes.clear();
    for (int pass = 0; pass < passes; ++pass) {
      SessionPass entry;
      entry.orientation = pass < static_cast<int>(rig.orientation_names.size())
                              ? rig.orientation_names[pass]
                              : "pass " + std::to_string(pass + 1);
      session.passes.push_back(entry);
    }
  }
  const int shots_per_view = mask_shots ? 2 : 1;
  const int total = total_stops * cameras * shots_per_view;
  int done = 0;
  for (const SessionView& view : session.views)
    done += 1 + (mask_shots && !view.mask_shot.empty() ? 1 : 0);
  // The view of `image` in the manifest (recorded by now).
  auto view_of = [&](const std::string& image) -> SessionView* {
    for (SessionView& view : session.views)
      if (view.image == image) return &view;
    return nullptr;
  };
  // A photo (or mask shot) is on disk: its checksum goes into the manifest, which names it
  // only now.
  auto record = [&](const SessionView& view, bool mask_shot) {
    if (mask_shot) {
      SessionView* entry = view_of(view.image);
      CAROUSEL_CHECK(entry != nullptr, "the mask shot's view " << view.image << " is recorded");
      entry->mask_shot = MaskShotPath(view.camera, view.stop, view.pass);
      entry->mask_shot_sha256 = FileSha256(folder / entry->mask_shot);
    } else {
      SessionView entry = view;
      entry.sha256 = FileSha256(folder / entry.image);
      entry.mask_shot.clear();
      entry.mask_shot_sha256.clear();
      session.views.push_back(entry);
      // Each pass's views follow the earlier passes' (a photo of an earlier pass retaken
      // after a resume goes back among its own).
      std::stable_sort(session.views.begin(), session.views.end(),
                       [](const SessionView& x, const SessionView& y) { return x.pass < y.pass; });
    }
    WriteSessionManifest(folder, session);
    progress.Report(static_cast<std::size_t>(++done), static_cast<std::size_t>(total));
  };
  auto angle_of = [&](int stop) {
    return 2.0 * std::numbers::pi * (stop % plan.stops) / plan.stops;
  };
  // One shot of a camera at a stop: its photo, or its backlit mask shot.
  struct Shot {
    SessionView view;
    bool mask_shot = false;
    std::string file;  // relative
    std::optional<rig::CapturedPhoto> photo;
  };
  bool homed = false;
  int moving_to = -1;  // the stop the table was last sent to
  int placed = -1;     // the board placement in place
  int laid = -1;       // the product's pass in place (-1: as the session found it)
  // A resume that retakes photos of an earlier pass after a later one was begun asks for the
  // product to be turned back first.
  const bool later_pass_begun = std::any_of(
      recorded.begin(), recorded.end(), [](const auto& entry) { return entry.second.pass > 0; });
  for (int stop = 0; stop < total_stops; ++stop) {
    progress.CheckCancelled();
    const double angle = angle_of(stop);
    const int pass = passes > 1 ? stop / plan.stops : 0;
    const int stop_in_pass = passes > 1 ? stop % plan.stops : stop;
    std::vector<Shot> to_take;
    for (int c = 0; c < cameras; ++c) {
      SessionView view;
      view.image = "images/" + ViewStem(c, stop_in_pass, pass) + ".jpg";
      view.camera = c;
      view.stop = stop_in_pass;
      view.pass = pass;
      view.table_angle_deg = 360.0 * (stop % plan.stops) / plan.stops;
      view.camera_model = sim::CameraAtTableAngle(rig.cam_from_table[c], angle);
      const auto it = recorded.find(view.image);
      const bool have_photo = it != recorded.end();
      if (have_photo) view = it->second;
      const bool have_mask_shot = !mask_shots || (have_photo && !it->second.mask_shot.empty());
      for (const bool mask_shot : {false, true}) {
        if (mask_shot ? have_mask_shot : have_photo) continue;
        const std::string file = mask_shot ? MaskShotPath(c, stop_in_pass, pass) : view.image;
        if (std::filesystem::exists(folder / file)) {
          // On disk but not recorded: a kill between the download and the manifest. A mask
          // shot is adopted once its photo is recorded (below, in order).
          if (IsCompletePhoto(folder / file, view.camera_model) &&
              (!mask_shot || have_photo || view_of(view.image) != nullptr)) {
            ++result.photos_adopted;
            record(view, mask_shot);
            continue;
          }
          // Damaged, or a complete mask shot whose photo is to be retaken (taken again with
          // it): moved aside, never deleted.
          MoveAside(folder / file);
          ++result.photos_retaken;
        }
        to_take.push_back({view, mask_shot, file, std::nullopt});
      }
    }
    if (to_take.empty()) continue;
    if (rig.place_board && stop / plan.stops != placed) {
      placed = stop / plan.stops;
      CAROUSEL_LOG_INFO("board placement " << placed + 1 << " of " << placements);
      rig.place_board(placed);
    }
    // A later pass: the product is laid down another way before its first photo (after a
    // resume, again before the first photo it still lacks: the operator confirms it lies so;
    // back as in the first pass when a photo of that is to be retaken).
    if (rig.turn_product && pass != laid && (pass > 0 || laid >= 0 || later_pass_begun)) {
      laid = pass;
      CAROUSEL_LOG_INFO("pass " << pass + 1 << " of " << passes << ": the product "
                                << session.passes[static_cast<std::size_t>(pass)].orientation);
      // The table stands still while the operator handles the product.
      if (moving_to >= 0) rig.turntable->WaitUntilStopped(move_timeout);
      rig.turn_product(pass);
    }
    if (pass == 0 && laid < 0) laid = 0;
    if (!homed) {
      rig.turntable->Home(move_timeout);
      homed = true;
      moving_to = -1;
    }
    if (moving_to != stop) rig.turntable->StartMoveTo(angle);
    rig.turntable->WaitUntilStopped(move_timeout);
    if (plan.settle_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(plan.settle_ms));
    std::exception_ptr error;
    // Every camera of a phase fires at once: triggered through libgphoto2, or released
    // together by the controller's shutter outputs. The photos first, then (the backlight on)
    // the mask shots.
    auto fire = [&](bool mask_phase) {
      std::vector<Shot*> shots;
      for (Shot& shot : to_take)
        if (shot.mask_shot == mask_phase) shots.push_back(&shot);
      if (shots.empty() || error) return;
      std::vector<std::future<rig::CapturedPhoto>> futures;
      futures.reserve(shots.size());
      const bool external = static_cast<bool>(rig.release);
      try {
        if (external) {
          std::vector<int> released;
          released.reserve(shots.size());
          for (const Shot* shot : shots) {
            rig.cameras[shot->view.camera]->PrepareExternalRelease(camera_timeout);
            released.push_back(shot->view.camera);
          }
          rig.release(released);
        }
      } catch (...) {
        error = std::current_exception();
        return;
      }
      for (const Shot* shot : shots) {
        rig::Camera* camera = rig.cameras[shot->view.camera].get();
        futures.push_back(std::async(std::launch::async, [camera, camera_timeout, external] {
          return external ? camera->WaitForPhoto(camera_timeout) : camera->Capture(camera_timeout);
        }));
      }
      const std::vector<std::optional<rig::CapturedPhoto>> photos = JoinAll(futures, &error);
      // Trigger skew: each camera's trigger time after the first one's in this phase.
      std::optional<std::chrono::steady_clock::time_point> first_trigger;
      for (const auto& photo : photos) {
        if (photo && photo->triggered_at != std::chrono::steady_clock::time_point{} &&
            (!first_trigger || photo->triggered_at < *first_trigger))
          first_trigger = photo->triggered_at;
      }
      double skew_ms = 0.0;
      for (std::size_t i = 0; i < shots.size(); ++i) {
        shots[i]->photo = photos[i];
        if (!photos[i] || !first_trigger ||
            photos[i]->triggered_at == std::chrono::steady_clock::time_point{})
          continue;
        const double offset_ms =
            std::chrono::duration<double, std::milli>(photos[i]->triggered_at - *first_trigger)
                .count();
        if (!mask_phase) shots[i]->view.trigger_offset_ms = offset_ms;
        skew_ms = std::max(skew_ms, offset_ms);
      }
      result.max_trigger_skew_ms = std::max(result.max_trigger_skew_ms, skew_ms);
      if (shots.size() > 1)
        CAROUSEL_LOG_INFO("stop " << stop << (mask_phase ? " (mask shots)" : "") << ": "
                                  << shots.size() << " cameras triggered within " << skew_ms
                                  << " ms");
    };
    fire(false);
    if (mask_shots && !error) {
      const bool any = std::any_of(to_take.begin(), to_take.end(),
                                   [](const Shot& shot) { return shot.mask_shot; });
      if (any) {
        try {
          rig.turntable->SetBacklight(true);
          if (plan.backlight_settle_ms > 0)
            std::this_thread::sleep_for(std::chrono::milliseconds(plan.backlight_settle_ms));
          fire(true);
        } catch (...) {
          if (!error) error = std::current_exception();
        }
        // Off again whatever happened: the next stop's photos are lit from the front.
        try {
          rig.turntable->SetBacklight(false);
        } catch (...) {
          if (!error) error = std::current_exception();
        }
      }
    }
    // The table turns to the next stop while the photos download.
    if (!error && stop + 1 < total_stops) {
      rig.turntable->StartMoveTo(angle_of(stop + 1));
      moving_to = stop + 1;
    }
    std::vector<std::future<int>> downloads(to_take.size());
    for (std::size_t i = 0; i < to_take.size(); ++i) {
      if (!to_take[i].photo) continue;
      rig::Camera* camera = rig.cameras[to_take[i].view.camera].get();
      const rig::CapturedPhoto photo = *to_take[i].photo;
      const std::filesystem::path file = folder / to_take[i].file;
      const bool remove = plan.delete_from_camera;
      downloads[i] = std::async(std::launch::async, [camera, photo, file, remove, camera_timeout] {
        camera->Download(photo, file, remove, camera_timeout);
        return 0;
      });
    }
    // Recorded in order: a view's photo before its mask shot.
    for (const bool mask_phase : {false, true}) {
      for (std::size_t i = 0; i < to_take.size(); ++i) {
        if (to_take[i].mask_shot != mask_phase || !to_take[i].photo) continue;
        try {
          downloads[i].get();
          ++result.photos_taken;
          if (!mask_phase || view_of(to_take[i].view.image) != nullptr)
            record(to_take[i].view, mask_phase);
        } catch (...) {
          if (!error) error = std::current_exception();
        }
      }
    }
    if (error) std::rethrow_exception(error);
  }
  std::sort(session.views.begin(), session.views.end(),
            [](const SessionView& a, const SessionView& b) {
              return std::tie(a.pass, a.stop, a.camera) < std::tie(b.pass, b.stop, b.camera);
            });
  const bool capture_changed =
      result.photos_taken + result.photos_adopted + result.photos_retaken > 0;
  if (capture_changed || session.stages["capture"] != "done") {
    session.stages["capture"] = "done";
    session.stage_seconds["capture"] = watch.ElapsedSeconds();
    if (capture_changed) {
      // New photos make the later stages stale, and the passes' registrations with them.
      for (SessionPass& pass : session.passes) {
        pass.registration.clear();
        pass.registration_note.clear();
        pass.table_from_object.reset();
      }
      session.stages.erase("reconstruct");
      session.stages.erase("texture");
      session.stages.erase("calibrate");
    }
    WriteSessionManifest(folder, session);
  }
  progress.EndStage();
  result.seconds = watch.ElapsedSeconds();

  return result;
}

}  // namespace carousel::studio
