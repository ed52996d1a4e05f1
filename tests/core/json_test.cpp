#include "carousel/core/json.h"

#include <cstring>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "carousel/core/error.h"
#include "carousel/testing/testing.h"

namespace carousel {
namespace {

using nlohmann::json;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

// Bit for bit, NaN-free: the round trip must not lose a single ulp.
bool SameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

bool SameCamera(const CameraModel& a, const CameraModel& b) {
  bool same =
      a.width == b.width && a.height == b.height && SameBits(a.fx, b.fx) && SameBits(a.fy, b.fy) &&
      SameBits(a.cx, b.cx) && SameBits(a.cy, b.cy) && SameBits(a.distortion.k1, b.distortion.k1) &&
      SameBits(a.distortion.k2, b.distortion.k2) && SameBits(a.distortion.p1, b.distortion.p1) &&
      SameBits(a.distortion.p2, b.distortion.p2) && SameBits(a.distortion.k3, b.distortion.k3);
  for (int i = 0; i < 9; ++i) {
    same = same && SameBits(a.cam_from_world.rotation(i / 3, i % 3),
                            b.cam_from_world.rotation(i / 3, i % 3));
  }
  for (int i = 0; i < 3; ++i) {
    same = same && SameBits(a.cam_from_world.translation(i), b.cam_from_world.translation(i));
  }
  return same;
}

CameraModel SimpleCamera() {
  CameraModel camera;
  camera.width = 640;
  camera.height = 480;
  camera.fx = 500.5;
  camera.fy = 501.25;
  camera.cx = 319.5;
  camera.cy = 239.5;
  camera.distortion = {-0.125, 0.0625, 0.001, -0.002, 0.0};
  camera.cam_from_world.translation = Eigen::Vector3d(0.1, -0.2, 1.5);
  return camera;
}

// A view whose camera is `camera` (a JSON object's text), as session.json holds them.
std::string Manifest(const std::string& camera) {
  return R"({"views": [{"camera_model": )" + CameraModelToJson(SimpleCamera()).dump() +
         R"(}, {"camera_model": )" + camera + "}]}";
}

// Reads views[1].camera_model of a manifest's text as a file would be read.
CameraModel ReadSecondCamera(const testing::TempDir& dir, const std::string& camera) {
  testing::WriteBytes(dir / "session.json", Manifest(camera));
  const json manifest = ParseJsonFile(dir / "session.json");
  const JsonReader read(manifest, dir / "session.json");
  return CameraModelFromJson(read.Array("views").at(1).Object("camera_model"));
}

TEST(JsonTest, ParseErrorsNameTheFileAndTheField) {
  testing::TempDir dir;
  const auto file = dir / "session.json";
  EXPECT_THROW(ParseJsonFile(dir / "none.json"), IoError);
  testing::WriteBytes(file, "{ not json");
  EXPECT_THAT(
      [&] { ParseJsonFile(file); },
      ThrowsMessage<FormatError>(AllOf(HasSubstr(file.string()), HasSubstr("not valid JSON"))));
  // A number out of double's range: nlohmann throws out_of_range, not parse_error.
  std::string camera = CameraModelToJson(SimpleCamera()).dump();
  camera.replace(camera.find(R"("fx":500.5)"), std::strlen(R"("fx":500.5)"), R"("fx":1e999)");
  testing::WriteBytes(file, Manifest(camera));
  EXPECT_THAT(
      [&] { ParseJsonFile(file); },
      ThrowsMessage<FormatError>(AllOf(HasSubstr(file.string()),
                                       HasSubstr("views[1].camera_model.fx"), HasSubstr("1e999"))));
  // Syntax errors deep inside: the field too.
  EXPECT_THAT([&] { ParseJsonText(R"({"a": {"b": [1, 2, }})", "run.json"); },
              ThrowsMessage<FormatError>(AllOf(HasSubstr("run.json"), HasSubstr("at a.b[2]"))));
  EXPECT_THAT([&] { ParseJsonText("[1, -1e400]", "x.json"); },
              ThrowsMessage<FormatError>(HasSubstr("at [1]")));
  EXPECT_EQ(ParseJsonText(R"({"a": [1, 2.5]})", "x.json").at("a").at(1).get<double>(), 2.5);
}

TEST(JsonTest, FieldsAreTypedAndStrict) {
  const json j = json::parse(R"({
    "int": 7, "half": 3.5, "big": 3000000000, "huge": 18446744073709551615, "neg": -4,
    "text": "x", "flag": true, "zero": 0, "list": [1, 2, 3], "mixed": [1, "two"],
    "map": {"a": "1", "b": "2"}, "bad_map": {"a": 1}, "null": null,
    "paths": {"ok": "images/a.jpg", "abs": "/etc/passwd", "up": "images/../../x", "empty": ""},
    "nested": {"deeper": [{"v": "not a number"}]}
  })");
  const JsonReader read(j, "/data/rig.json");
  const auto fails = [](auto&& read_field, const std::string& needle) {
    EXPECT_THAT(read_field,
                ThrowsMessage<FormatError>(AllOf(HasSubstr("/data/rig.json: "), HasSubstr(needle))))
        << needle;
  };
  EXPECT_EQ(read.Int("int"), 7);
  EXPECT_EQ(read.Int("neg"), -4);
  EXPECT_EQ(read.Number("half"), 3.5);
  EXPECT_EQ(read.Number("int"), 7.0);  // an integer is a number
  EXPECT_EQ(read.Uint64("huge"), 18446744073709551615ull);
  EXPECT_EQ(read.String("text"), "x");
  EXPECT_TRUE(read.Bool("flag"));
  EXPECT_EQ(read.Numbers("list", 3), (std::vector<double>{1, 2, 3}));
  EXPECT_EQ(read.Ints("list"), (std::vector<int>{1, 2, 3}));
  EXPECT_EQ(read.StringMap("map").at("b"), "2");
  fails([&] { read.Int("missing"); }, "the top-level object has no field 'missing'");
  fails([&] { read.Int("half"); }, "half is not an integer");
  fails([&] { read.Int("big"); }, "big is out of range (3000000000)");
  fails([&] { read.Int("huge"); }, "huge is out of range");
  fails([&] { read.Uint64("neg"); }, "neg is negative");
  fails([&] { read.Number("text"); }, "text is not a number");
  fails([&] { read.Bool("zero"); }, "zero is not true or false");
  fails([&] { read.String("int"); }, "int is not a string");
  fails([&] { read.Numbers("list", 9); }, "list must be an array of 9 numbers");
  fails([&] { read.Numbers("mixed"); }, "mixed[1] is not a number");
  fails([&] { read.StringMap("bad_map"); }, "bad_map.a is not a string");
  fails([&] { read.Object("list"); }, "list is not an object");
  fails([&] { read.Member("int").Has("x"); }, "int is not an object");
  fails([&] { read.Array("map"); }, "map is not an array");
  fails([&] { read.Object("nested").Array("deeper").at(0).Number("v"); },
        "nested.deeper[0].v is not a number");
  // Optional: absent gives nullopt, present must still have the right type (null included).
  EXPECT_FALSE(read.OptionalInt("missing").has_value());
  EXPECT_EQ(read.OptionalInt("int"), 7);
  EXPECT_EQ(read.OptionalString("missing").value_or("fallback"), "fallback");
  fails([&] { read.OptionalString("int"); }, "int is not a string");
  fails([&] { read.OptionalNumber("null"); }, "null is not a number");
  EXPECT_FALSE(read.OptionalObject("missing").has_value());
  // An absent object reads as an empty one, named for messages.
  const JsonReader absent = read.ObjectOrEmpty("turntable");
  EXPECT_FALSE(absent.OptionalInt("steps").has_value());
  fails([&] { absent.String("port"); }, "turntable has no field 'port'");
  // Relative paths stay inside their folder.
  const JsonReader paths = read.Object("paths");
  EXPECT_EQ(paths.RelativePath("ok"), "images/a.jpg");
  fails([&] { paths.RelativePath("abs"); }, "paths.abs is an absolute path: /etc/passwd");
  fails([&] { paths.RelativePath("up", "session folder"); },
        "paths.up leaves the session folder: images/../../x");
  fails([&] { paths.RelativePath("empty"); }, "paths.empty is empty");
  EXPECT_FALSE(paths.OptionalRelativePath("none").has_value());
  // A reader bound below the top level prefixes every field.
  const JsonReader plan(j.at("nested"), "/data/rig.json", "calibration");
  fails([&] { plan.Int("placements"); }, "calibration has no field 'placements'");
}

TEST(JsonTest, CameraRoundTripsExactly) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 50; ++trial) {
    const CameraModel camera = testing::RandomCamera(rng);
    const std::string text = CameraModelToJson(camera).dump(2);
    const json parsed = ParseJsonText(text, "camera.json");
    const CameraModel back = CameraModelFromJson(JsonReader(parsed, "camera.json"));
    EXPECT_TRUE(SameCamera(back, camera)) << text;
    EXPECT_EQ(CameraModelToJson(back).dump(2), text);
  }
  // The pose under another name (the rig calibration file's cam_from_table).
  const json table = CameraModelToJson(SimpleCamera(), "cam_from_table");
  EXPECT_FALSE(table.contains("cam_from_world"));
  EXPECT_TRUE(SameCamera(CameraModelFromJson(JsonReader(table, "c.json"), "cam_from_table"),
                         SimpleCamera()));
  EXPECT_THAT([&] { CameraModelFromJson(JsonReader(table, "c.json")); },
              ThrowsMessage<FormatError>(HasSubstr("has no field 'cam_from_world'")));
}

TEST(JsonTest, CameraTextIsSessionJsonsFormat) {
  // The exact text session.json has always held; existing sessions and their fingerprints
  // (pipeline.h) depend on it.
  EXPECT_EQ(CameraModelToJson(SimpleCamera()).dump(),
            R"({"cam_from_world":{"rotation_row_major":[1.0,0.0,0.0,0.0,1.0,0.0,0.0,0.0,1.0],)"
            R"("translation":[0.1,-0.2,1.5]},"cx":319.5,"cy":239.5,)"
            R"("distortion":[-0.125,0.0625,0.001,-0.002,0.0],"fx":500.5,"fy":501.25,)"
            R"("height":480,"width":640})");
  const Rigid3d pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(1, 2, 3));
  const json j = Rigid3dToJson(pose);
  const Rigid3d back = Rigid3dFromJson(JsonReader(j, "p.json"));
  EXPECT_EQ(back.rotation, pose.rotation);
  EXPECT_EQ(back.translation, pose.translation);
}

TEST(JsonTest, MalformedCamerasNameTheFileAndTheField) {
  testing::TempDir dir;
  const std::string file = (dir / "session.json").string();
  const std::string good = CameraModelToJson(SimpleCamera()).dump();
  EXPECT_TRUE(SameCamera(ReadSecondCamera(dir, good), SimpleCamera()));
  const auto with = [&](const std::string& from, const std::string& to) {
    std::string text = good;
    const std::size_t at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    return text.replace(at, from.size(), to);
  };
  const auto fails = [&](const std::string& camera, const std::string& needle) {
    EXPECT_THAT([&] { ReadSecondCamera(dir, camera); },
                ThrowsMessage<FormatError>(AllOf(HasSubstr(file), HasSubstr(needle))))
        << needle;
  };
  fails(with(R"("fx":500.5,)", ""), "views[1].camera_model has no field 'fx'");
  fails(with(R"("fx":500.5)", R"("fx":"500")"), "views[1].camera_model.fx is not a number");
  fails(with(R"("width":640)", R"("width":640.5)"),
        "views[1].camera_model.width is not an integer");
  fails(with("[-0.125,0.0625,0.001,-0.002,0.0]", "[-0.125,0.0625]"),
        "views[1].camera_model.distortion must be an array of 5 numbers");
  fails(with(R"("fx":500.5)", R"("fx":1e999)"), "views[1].camera_model.fx");
  // CameraModel::Validate's refusals, named.
  fails(with(R"("fx":500.5)", R"("fx":-500.5)"), "views[1].camera_model: CameraModel.fx");
  fails(with(R"("width":640)", R"("width":0)"), "views[1].camera_model: CameraModel.width");
  // A rotation that is not orthonormal (scaled by 2), and one that mirrors (det -1): both
  // refused, as CameraModel::Validate refuses them.
  CameraModel scaled = SimpleCamera();
  scaled.cam_from_world.rotation *= 2.0;
  EXPECT_THROW(scaled.Validate(), InvalidArgument);
  fails(CameraModelToJson(scaled).dump(),
        "views[1].camera_model.cam_from_world is not a rigid transform");
  CameraModel mirrored = SimpleCamera();
  mirrored.cam_from_world.rotation(2, 2) = -1.0;
  EXPECT_THROW(mirrored.Validate(), InvalidArgument);
  fails(CameraModelToJson(mirrored).dump(),
        "views[1].camera_model.cam_from_world is not a rigid transform");
}

}  // namespace
}  // namespace carousel
