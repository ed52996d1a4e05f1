// A second pass of the product laid down another way (capture plan orientations): the
// simulated capture, its registration by the reconstruct stage against the simulator's truth,
// the model from both passes, and the passes that cannot be registered (another product, out
// of frame), named and left out while the first pass's model is made.
#include <algorithm>
#include <numbers>

#include <gtest/gtest.h>

#include "carousel/core/error.h"
#include "carousel/recon/registration.h"
#include "carousel/studio/pipeline.h"
#include "carousel/studio/reconstruct.h"
#include "carousel/studio/session.h"
#include "carousel/studio/sim_capture.h"
#include "carousel/studio/texture_session.h"
#include "carousel/testing/testing.h"

namespace carousel::studio {
namespace {

using testing::TempDir;

// 8 stops per pass at 480x320 on the grey backdrop (the shoe's white sole, facing the cameras
// in the second pass, is keyed against it).
SimCaptureOptions TwoPasses(const std::string& scene) {
  SimCaptureOptions options;
  options.scene = scene;
  options.data_dir = testing::SharedDataDir();
  options.stops = 8;
  options.rig.width = 480;
  options.rig.height = 320;
  options.orientations = 2;
  SetOptionText(SimCaptureOptions::Fields().Find("backdrop"), options, std::string("grey"));
  return options;
}

TEST(PassesTest, TheShoeOnItsSideIsRegisteredAndSeenAllRound) {
  TempDir dir;
  Progress progress;
  SimCaptureOptions options = TwoPasses("shoe");
  options.eval_below = 2;
  SimulateCapture(options, dir / "shoe", progress);
  Session session = ReadSession(dir / "shoe");
  ASSERT_EQ(session.views.size(), 16u);
  ASSERT_EQ(session.passes.size(), 2u);
  EXPECT_EQ(session.passes[1].orientation, "side");
  EXPECT_EQ(session.views[8].pass, 1);
  EXPECT_EQ(session.views[8].image, "images/pass1_cam0_stop00.jpg");
  ASSERT_EQ(session.ground_truth.table_from_object.size(), 2u);
  ASSERT_EQ(session.ground_truth.eval_views.size(), 2u);
  // Not registered yet: only the first pass reaches the model.
  EXPECT_EQ(SessionViews(dir / "shoe", session).size(), 8u);
  EXPECT_EQ(SessionTableViews(dir / "shoe", session).size(), 16u);

  const ReconstructResult result = ReconstructSession(dir / "shoe", session, {}, progress);
  ASSERT_EQ(result.passes.size(), 1u);
  EXPECT_EQ(result.passes[0].status, "registered") << result.passes[0].note;
  EXPECT_EQ(result.model_views, 16);
  ASSERT_TRUE(result.passes[0].registration);
  const recon::RegistrationResult& found = *result.passes[0].registration;
  const Rigid3d& truth = session.ground_truth.table_from_object[1];
  const double rotation_deg =
      recon::RotationDistanceDeg(found.table_from_object.rotation, truth.rotation);
  const Eigen::Vector3d centre(0.0, 0.0, 0.05);
  const double moved_mm = 1e3 * (found.table_from_object * centre - truth * centre).norm();
  std::printf("two passes at 480x320: rotation error %.3f deg, centre %.3f mm, residual %.2f px\n",
              rotation_deg, moved_mm, found.residual_px);
  // A pixel at the shoe is about 1.3 mm at this size.
  EXPECT_LT(rotation_deg, 1.0);
  EXPECT_LT(moved_mm, 2.0);
  EXPECT_LT(found.residual_px, 1.5);
  EXPECT_FALSE(found.ambiguous);

  // Recorded: read back, the second pass's cameras come into the object frame through it.
  const Session reread = ReadSession(dir / "shoe");
  EXPECT_EQ(reread.passes[1].registration, "registered");
  ASSERT_TRUE(reread.passes[1].table_from_object);
  const std::vector<View> views = SessionViews(dir / "shoe", reread);
  ASSERT_EQ(views.size(), 16u);
  const Rigid3d expected = reread.views[9].camera_model.cam_from_world * found.table_from_object;
  EXPECT_LT((views[9].camera().cam_from_world.translation - expected.translation).norm(), 1e-9);

  // Every face of the model is seen by some photo (one ring of cameras never sees the sole).
  const TextureSessionResult textured = TextureSession(dir / "shoe", {}, progress);
  EXPECT_EQ(textured.views, 16);
  EXPECT_LE(textured.grouping.unseen_faces, static_cast<int>(textured.faces / 200))
      << textured.grouping.unseen_faces << " of " << textured.faces << " faces unseen";
  // The second pass (lit otherwise: the product lies another way under the studio's lights)
  // gives the faces the first one sees badly or not at all, not those it sees well.
  const auto from_second_pass = [](const texture::GroupingResult& grouping) {
    return std::count_if(grouping.front_view.begin(), grouping.front_view.end(),
                         [](int v) { return v >= 8; });
  };
  TextureSessionOptions any_pass;
  any_pass.grouping.pass_cosine_ratio = 0.0;
  const TextureSessionResult most_frontal = TextureSession(dir / "shoe", any_pass, progress);
  std::printf("faces textured from the second pass: %td of %zu (the most frontal photo: %td)\n",
              from_second_pass(textured.grouping), textured.faces,
              from_second_pass(most_frontal.grouping));
  // (Measured: 720 faces of 4,500 against 1,465.)
  EXPECT_LT(3 * from_second_pass(textured.grouping), 2 * from_second_pass(most_frontal.grouping));
  EXPECT_GT(from_second_pass(textured.grouping), 0);
  EXPECT_EQ(textured.grouping.unseen_faces, most_frontal.grouping.unseen_faces);
}

// The second pass's photos replaced by another product's: named, left out, and the model made
// from the first pass alone.
TEST(PassesTest, AnotherProductInTheSecondPassIsNamedAndLeftOut) {
  TempDir dir;
  Progress progress;
  SimulateCapture(TwoPasses("shoe"), dir / "shoe", progress);
  SimCaptureOptions other = TwoPasses("duck");
  other.second_pose = "upside-down";
  SimulateCapture(other, dir / "duck", progress);
  Session session = ReadSession(dir / "shoe");
  const Session duck = ReadSession(dir / "duck");
  for (std::size_t i = 8; i < 16; ++i) {
    std::filesystem::copy_file(dir / "duck" / duck.views[i].image,
                               dir / "shoe" / session.views[i].image,
                               std::filesystem::copy_options::overwrite_existing);
    session.views[i].camera_model = duck.views[i].camera_model;
  }
  WriteSessionManifest(dir / "shoe", session);

  const ReconstructResult result = ReconstructSession(dir / "shoe", session, {}, progress);
  ASSERT_EQ(result.passes.size(), 1u);
  std::printf("%s\n", result.passes[0].note.c_str());
  EXPECT_EQ(result.passes[0].status, "failed");
  EXPECT_NE(result.passes[0].note.find("pass 2"), std::string::npos) << result.passes[0].note;
  EXPECT_NE(result.passes[0].note.find("not show the same product"), std::string::npos)
      << result.passes[0].note;
  EXPECT_EQ(result.model_views, 8);
  EXPECT_TRUE(std::filesystem::exists(dir / "shoe" / "recon" / "mesh.ply"));
  const Session reread = ReadSession(dir / "shoe");
  EXPECT_EQ(reread.passes[1].registration, "failed");
  EXPECT_FALSE(reread.passes[1].table_from_object);
  EXPECT_EQ(SessionViews(dir / "shoe", reread).size(), 8u);
  EXPECT_EQ(reread.stages.at("reconstruct"), "done");
}

TEST(PassesTest, ASecondPassOutOfFrameIsNamedAndLeftOut) {
  TempDir dir;
  Progress progress;
  SimCaptureOptions options = TwoPasses("shoe");
  options.second_offset_m = 0.25;  // laid down at the plate's edge
  SimulateCapture(options, dir / "shoe", progress);
  Session session = ReadSession(dir / "shoe");
  const ReconstructResult result = ReconstructSession(dir / "shoe", session, {}, progress);
  ASSERT_EQ(result.passes.size(), 1u);
  EXPECT_EQ(result.passes[0].status, "failed");
  // The silhouettes' own check names the photo; the note names the pass.
  const std::string& note = result.passes[0].note;
  EXPECT_EQ(note.rfind("pass 2 (side): ", 0), 0u) << note;
  EXPECT_TRUE(note.find("touches the image border") != std::string::npos ||
              note.find("runs out of the frame") != std::string::npos)
      << note;
  EXPECT_NE(note.find("pass1_cam0_stop"), std::string::npos) << note;
  EXPECT_EQ(result.model_views, 8);
  // The left-out pass's photos have no masks; the texture of the first pass's model still
  // corrects missing colours (it needs masks only of the views it is made from).
  const TextureSessionResult textured = TextureSession(dir / "shoe", {}, progress);
  EXPECT_EQ(textured.views, 8);
  EXPECT_TRUE(textured.warnings.empty()) << textured.warnings.front();
}

// A bottle laid on its side fits alike turned about its axis. Without the colours' help the
// pass is ambiguous: left out, with the poses to choose among and their pictures; the
// operator's choice registers it, stays in the session and makes the stage current again.
TEST(PassesTest, AnAmbiguousPassIsRegisteredFromThePoseTheOperatorChooses) {
  TempDir dir;
  Progress progress;
  SimulateCapture(TwoPasses("bottle"), dir / "bottle", progress);
  Session session = ReadSession(dir / "bottle");
  ReconstructOptions options;
  options.registration.colour = false;
  const ReconstructResult ambiguous =
      ReconstructSession(dir / "bottle", session, options, progress);
  ASSERT_EQ(ambiguous.passes.size(), 1u);
  std::printf("%s\n", ambiguous.passes[0].note.c_str());
  ASSERT_EQ(ambiguous.passes[0].status, "ambiguous") << ambiguous.passes[0].note;
  EXPECT_EQ(ambiguous.model_views, 8);
  const Session listed = ReadSession(dir / "bottle");
  const std::vector<Rigid3d>& choices = listed.passes[1].pose_choices;
  ASSERT_GE(choices.size(), 2u);
  EXPECT_EQ(listed.passes[1].chosen_pose, 0);
  EXPECT_NE(ambiguous.passes[0].note.find("--choose-pose 2:K"), std::string::npos);
  for (std::size_t k = 1; k <= choices.size(); ++k)
    EXPECT_TRUE(std::filesystem::is_regular_file(dir / "bottle" / "recon" /
                                                 ("pass2_pose" + std::to_string(k) + ".jpg")))
        << k;
  EXPECT_FALSE(std::filesystem::exists(
      dir / "bottle" / "recon" / ("pass2_pose" + std::to_string(choices.size() + 1) + ".jpg")));

  // What cannot be chosen is named.
  auto refused = [&](const std::string& choice) {
    Session copy = listed;
    try {
      ReconstructOptions bad;
      bad.choose_pose = choice;
      bad.Validate();
      ApplyPoseChoices(copy, choice);
    } catch (const InvalidArgument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(refused("2:" + std::to_string(choices.size() + 1))
                .find("has " + std::to_string(choices.size()) + " poses"),
            std::string::npos);
  EXPECT_NE(refused("3:1").find("the session has 2 pass(es)"), std::string::npos);
  EXPECT_NE(refused("1:1").find("is not PASS:POSE"), std::string::npos);
  EXPECT_NE(refused("2-1").find("is not PASS:POSE"), std::string::npos);

  // The operator picks the pose whose picture looks right (here: the one nearest the truth).
  const Rigid3d& truth = listed.ground_truth.table_from_object[1];
  std::size_t right = 0;
  for (std::size_t k = 1; k < choices.size(); ++k)
    if (recon::RotationDistanceDeg(choices[k].rotation, truth.rotation) <
        recon::RotationDistanceDeg(choices[right].rotation, truth.rotation))
      right = k;
  ReconstructOptions chosen;
  chosen.choose_pose = "2:" + std::to_string(right + 1);
  Session again = ReadSession(dir / "bottle");
  const ReconstructResult result = ReconstructSession(dir / "bottle", again, chosen, progress);
  ASSERT_EQ(result.passes.size(), 1u);
  std::printf("%s\n", result.passes[0].note.c_str());
  ASSERT_EQ(result.passes[0].status, "registered") << result.passes[0].note;
  EXPECT_NE(result.passes[0].note.find("the operator chose (" + std::to_string(right + 1) + " of " +
                                       std::to_string(choices.size()) + ")"),
            std::string::npos);
  EXPECT_EQ(result.model_views, 16);
  const double error = recon::RotationDistanceDeg(
      result.passes[0].registration->table_from_object.rotation, truth.rotation);
  std::printf("offered %.1f deg off, registered %.2f deg off\n",
              recon::RotationDistanceDeg(choices[right].rotation, truth.rotation), error);
  EXPECT_LT(error, 3.0);  // measured 0.9 from a pose 17.7 deg off
  const Session kept = ReadSession(dir / "bottle");
  EXPECT_EQ(kept.passes[1].registration, "registered");
  EXPECT_EQ(kept.passes[1].chosen_pose, static_cast<int>(right) + 1);
  EXPECT_EQ(kept.passes[1].pose_choices.size(), choices.size());
  // The choice is the session's: without the option the stage's inputs are the same; another
  // choice changes them.
  EXPECT_EQ(ReconstructFingerprint(dir / "bottle", kept, chosen),
            ReconstructFingerprint(dir / "bottle", kept, {}));
  Session other = kept;
  ApplyPoseChoices(other, "2:" + std::to_string(right == 0 ? 2 : 1));
  EXPECT_NE(ReconstructFingerprint(dir / "bottle", other, {}),
            ReconstructFingerprint(dir / "bottle", kept, {}));
}

TEST(PassesTest, TheManifestRefusesPassesOutOfOrderOrUnlisted) {
  TempDir dir;
  Session session;
  session.product = "p";
  session.passes = {{.orientation = "upright"}, {.orientation = "side"}};
  for (const int pass : {0, 1, 0}) {
    SessionView view;
    view.image = "images/x" + std::to_string(session.views.size()) + ".jpg";
    view.pass = pass;
    view.camera_model.width = view.camera_model.height = 10;
    view.camera_model.fx = view.camera_model.fy = 10;
    session.views.push_back(view);
  }
  WriteSessionManifest(dir.path(), session);
  EXPECT_THROW(ReadSession(dir.path()), FormatError);
  session.views.pop_back();
  session.views.back().pass = 2;  // only 2 passes listed
  WriteSessionManifest(dir.path(), session);
  EXPECT_THROW(ReadSession(dir.path()), FormatError);
  session.views.back().pass = 1;
  session.passes[1].registration = "registered";  // without its pose
  WriteSessionManifest(dir.path(), session);
  EXPECT_THROW(ReadSession(dir.path()), FormatError);
  session.passes[1].registration.clear();
  WriteSessionManifest(dir.path(), session);
  EXPECT_EQ(ReadSession(dir.path()).views.back().pass, 1);
}

}  // namespace
}  // namespace carousel::studio
