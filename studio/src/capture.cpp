#include "carousel/studio/capture.h"

#include <algorithm>
#include <chrono>
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
  const auto move_timeout =
      std::chrono::milliseconds(static_cast<long long>(plan.move_timeout_s * 1000));
  const auto camera_timeout =
      std::chrono::milliseconds(static_cast<long long>(plan.camera_timeout_s * 1000));
  std::filesystem::create_directories(folder / "images");
  // What is recorded and verified.
  std::map<std::string, SessionView> recorded;
  for (const SessionView& view : session.views) {
    const auto file = folder / view.image;
    if (!view.sha256.empty() && std::filesystem::is_regular_file(file) &&
        FileSha256(file) == view.sha256) {
      recorded[view.image] = view;
      ++result.photos_kept;
    } else {
      if (std::filesystem::exists(file)) MoveAside(file);
      ++result.photos_retaken;
    }
  }
  session.views.clear();
  for (const auto& [name, view] : recorded) session.views.push_back(view);
  const int cameras = static_cast<int>(rig.cameras.size());
  // A calibration session turns the table once per board placement.
  const int total_stops = plan.stops * placements;
  const int total = total_stops * cameras;
  int done = static_cast<int>(recorded.size());
  auto record = [&](SessionView view) {
    view.sha256 = FileSha256(folder / view.image);
    session.views.push_back(view);
    // The manifest names the photo only now that it is on disk.
    WriteSessionManifest(folder, session);
    progress.Report(static_cast<std::size_t>(++done), static_cast<std::size_t>(total));
  };
  auto angle_of = [&](int stop) {
    return 2.0 * std::numbers::pi * (stop % plan.stops) / plan.stops;
  };
  bool homed = false;
  int moving_to = -1;  // the stop the table was last sent to
  int placed = -1;     // the board placement in place
  for (int stop = 0; stop < total_stops; ++stop) {
    progress.CheckCancelled();
    const double angle = angle_of(stop);
    std::vector<SessionView> to_take;
    for (int c = 0; c < cameras; ++c) {
      const std::string image = "images/" + ViewStem(c, stop) + ".jpg";
      if (recorded.count(image) != 0) continue;
      SessionView view;
      view.image = image;
      view.camera = c;
      view.stop = stop;
      view.table_angle_deg = 360.0 * (stop % plan.stops) / plan.stops;
      view.camera_model = sim::CameraAtTableAngle(rig.cam_from_table[c], angle);
      const auto file = folder / image;
      if (std::filesystem::exists(file)) {
        // On disk but not recorded: a kill between the download and the manifest.
        if (IsCompletePhoto(file, view.camera_model)) {
          ++result.photos_adopted;
          record(view);
          continue;
        }
        MoveAside(file);
        ++result.photos_retaken;
      }
      to_take.push_back(view);
    }
    if (to_take.empty()) continue;
    if (rig.place_board && stop / plan.stops != placed) {
      placed = stop / plan.stops;
      CAROUSEL_LOG_INFO("board placement " << placed + 1 << " of " << placements);
      rig.place_board(placed);
    }
    if (!homed) {
      rig.turntable->Home(move_timeout);
      homed = true;
      moving_to = -1;
    }
    if (moving_to != stop) rig.turntable->StartMoveTo(angle);
    rig.turntable->WaitUntilStopped(move_timeout);
    if (plan.settle_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(plan.settle_ms));
    // Every camera of this stop fires at once: triggered through libgphoto2, or released
    // together by the controller's shutter outputs.
    std::vector<std::future<rig::CapturedPhoto>> shots;
    shots.reserve(to_take.size());
    const bool external = static_cast<bool>(rig.release);
    if (external) {
      std::vector<int> released;
      released.reserve(to_take.size());
      for (const SessionView& view : to_take) {
        rig.cameras[view.camera]->PrepareExternalRelease(camera_timeout);
        released.push_back(view.camera);
      }
      rig.release(released);
    }
    for (const SessionView& view : to_take) {
      rig::Camera* camera = rig.cameras[view.camera].get();
      shots.push_back(std::async(std::launch::async, [camera, camera_timeout, external] {
        return external ? camera->WaitForPhoto(camera_timeout) : camera->Capture(camera_timeout);
      }));
    }
    std::exception_ptr error;
    const std::vector<std::optional<rig::CapturedPhoto>> photos = JoinAll(shots, &error);
    // Trigger skew: each camera's trigger time after the first one's at this stop.
    std::optional<std::chrono::steady_clock::time_point> first_trigger;
    for (const auto& photo : photos) {
      if (photo && photo->triggered_at != std::chrono::steady_clock::time_point{} &&
          (!first_trigger || photo->triggered_at < *first_trigger))
        first_trigger = photo->triggered_at;
    }
    double skew_ms = 0.0;
    for (std::size_t i = 0; i < to_take.size(); ++i) {
      if (!photos[i] || !first_trigger ||
          photos[i]->triggered_at == std::chrono::steady_clock::time_point{})
        continue;
      to_take[i].trigger_offset_ms =
          std::chrono::duration<double, std::milli>(photos[i]->triggered_at - *first_trigger)
              .count();
      skew_ms = std::max(skew_ms, to_take[i].trigger_offset_ms);
    }
    result.max_trigger_skew_ms = std::max(result.max_trigger_skew_ms, skew_ms);
    if (to_take.size() > 1)
      CAROUSEL_LOG_INFO("stop " << stop << ": " << to_take.size() << " cameras triggered within "
                                << skew_ms << " ms");
    // The table turns to the next stop while the photos download.
    if (!error && stop + 1 < total_stops) {
      rig.turntable->StartMoveTo(angle_of(stop + 1));
      moving_to = stop + 1;
    }
    std::vector<std::future<int>> downloads;
    for (std::size_t i = 0; i < to_take.size(); ++i) {
      if (!photos[i]) continue;
      rig::Camera* camera = rig.cameras[to_take[i].camera].get();
      const rig::CapturedPhoto photo = *photos[i];
      const std::filesystem::path file = folder / to_take[i].image;
      const bool remove = plan.delete_from_camera;
      downloads.push_back(
          std::async(std::launch::async, [camera, photo, file, remove, camera_timeout] {
            camera->Download(photo, file, remove, camera_timeout);
            return 0;
          }));
    }
    std::size_t d = 0;
    for (std::size_t i = 0; i < to_take.size(); ++i) {
      if (!photos[i]) continue;
      try {
        downloads[d++].get();
        ++result.photos_taken;
        record(to_take[i]);
      } catch (...) {
        if (!error) error = std::current_exception();
      }
    }
    if (error) std::rethrow_exception(error);
  }
  std::sort(session.views.begin(), session.views.end(),
            [](const SessionView& a, const SessionView& b) {
              return std::tie(a.stop, a.camera) < std::tie(b.stop, b.camera);
            });
  const bool capture_changed =
      result.photos_taken + result.photos_adopted + result.photos_retaken > 0;
  if (capture_changed || session.stages["capture"] != "done") {
    session.stages["capture"] = "done";
    session.stage_seconds["capture"] = watch.ElapsedSeconds();
    if (capture_changed) {
      // New photos make the later stages stale.
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
