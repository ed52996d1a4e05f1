// Carousel's one JSON layer: parsing that turns every problem into a FormatError naming the
// file, a strict reader of fields that names the file and the field at fault
// ("views[3].camera_model.fx is not a number"), and the codecs of the types several files
// store (Rigid3d, CameraModel). The session manifest (session.json), the rig file (rig.json),
// the rig calibration file and run.json all read through it.
//
// Reading:
//
//   const nlohmann::json manifest = ParseJsonFile(path);    // FormatError on any parse problem
//   const JsonReader read(manifest, path);
//   const int version = read.Int("version");                 // required, an integer in int
//   for (const JsonReader& view : read.Array("views")) {     // where: "views[0]", "views[1]"…
//     const CameraModel camera = CameraModelFromJson(view.Object("camera_model"));
//   }
//
// A JsonReader does not own the JSON value it reads: the value must outlive it (and every
// reader made from it). Numbers are finite doubles; integers must be written as integers (3,
// not 3.0) and fit the type asked for. An optional field that is present must have the right
// type (null is not "absent").
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "carousel/core/camera_model.h"
#include "carousel/core/rigid3.h"

namespace carousel {

// The JSON value of `text`; `source` names it in errors (a file path, or e.g. "run.json").
// \throw FormatError naming `source` for a syntax error or a number out of range (1e999),
// with the field being read when it happened ("not valid JSON at views[3].fx: ...").
nlohmann::json ParseJsonText(std::string_view text, const std::filesystem::path& source);

// The JSON value of the file at `path`. \throw IoError (missing, unreadable) or FormatError
// (as ParseJsonText) naming the file.
nlohmann::json ParseJsonFile(const std::filesystem::path& path);

// Typed, strict access to one JSON value of a file and to the fields below it. Every failure
// is a FormatError naming the file and the field path; `where` is the path of this value
// ("views[3].camera_model"; empty at the top level of the file).
class JsonReader {
 public:
  // For Numbers(): any number of elements.
  static constexpr std::size_t kAnyCount = std::numeric_limits<std::size_t>::max();

  JsonReader(const nlohmann::json& value, std::filesystem::path file, std::string where = {});
  // The value must outlive the reader: no temporaries.
  JsonReader(const nlohmann::json&& value, std::filesystem::path file,
             std::string where = {}) = delete;

  const nlohmann::json& value() const { return *value_; }
  const std::filesystem::path& file() const { return file_; }
  const std::string& where() const { return where_; }
  // This value in messages: its path, or "the top-level object" at the top level.
  std::string Name() const;
  // The path of this value's field `key`: "views[3].camera_model" + "fx" -> "...fx".
  std::string FieldPath(std::string_view key) const;

  // \throw FormatError(file(), what).
  [[noreturn]] void Fail(const std::string& what) const;

  // --- this value -------------------------------------------------------------------------
  int AsInt() const;               // an integer in int's range
  std::uint64_t AsUint64() const;  // a non-negative integer
  double AsNumber() const;         // any finite number
  bool AsBool() const;             // true or false
  std::string AsString() const;    // a string
  // A non-empty relative path that stays inside its folder (no absolute path, no ".."
  // part); `folder` names the folder in the message ("leaves the session folder").
  std::string AsRelativePath(std::string_view folder = "folder") const;
  // An array of numbers; of exactly `count` unless kAnyCount.
  std::vector<double> AsNumbers(std::size_t count = kAnyCount) const;
  std::vector<int> AsInts() const;                         // an array of integers in int's range
  std::map<std::string, std::string> AsStringMap() const;  // an object of strings
  std::vector<JsonReader> AsArray() const;  // an array; its elements where "<where>[i]"
  Eigen::Vector3d AsVector3() const;        // an array of 3 numbers

  // --- fields of this object: a required field that is missing fails "<Name()> has no field
  // '<key>'"; reading a field of a value that is not an object fails "<Name()> is not an
  // object". The Optional forms return nullopt for a field that is absent. --------------------
  bool Has(std::string_view key) const;
  JsonReader Member(std::string_view key) const;  // any type
  std::optional<JsonReader> OptionalMember(std::string_view key) const;

  JsonReader Object(std::string_view key) const;  // must be an object
  std::optional<JsonReader> OptionalObject(std::string_view key) const;
  // The object `key`, or an empty object named `key` when absent (its required fields then
  // fail "<key> has no field ...", its optional ones take their defaults).
  JsonReader ObjectOrEmpty(std::string_view key) const;
  std::vector<JsonReader> Array(std::string_view key) const { return Member(key).AsArray(); }

  int Int(std::string_view key) const { return Member(key).AsInt(); }
  std::uint64_t Uint64(std::string_view key) const { return Member(key).AsUint64(); }
  double Number(std::string_view key) const { return Member(key).AsNumber(); }
  bool Bool(std::string_view key) const { return Member(key).AsBool(); }
  std::string String(std::string_view key) const { return Member(key).AsString(); }
  std::string RelativePath(std::string_view key, std::string_view folder = "folder") const {
    return Member(key).AsRelativePath(folder);
  }
  std::vector<double> Numbers(std::string_view key, std::size_t count = kAnyCount) const {
    return Member(key).AsNumbers(count);
  }
  std::vector<int> Ints(std::string_view key) const { return Member(key).AsInts(); }
  std::map<std::string, std::string> StringMap(std::string_view key) const {
    return Member(key).AsStringMap();
  }
  Eigen::Vector3d Vector3(std::string_view key) const { return Member(key).AsVector3(); }

  std::optional<int> OptionalInt(std::string_view key) const;
  std::optional<double> OptionalNumber(std::string_view key) const;
  std::optional<bool> OptionalBool(std::string_view key) const;
  std::optional<std::string> OptionalString(std::string_view key) const;
  std::optional<std::string> OptionalRelativePath(std::string_view key,
                                                  std::string_view folder = "folder") const;
  std::optional<std::map<std::string, std::string>> OptionalStringMap(std::string_view key) const;

 private:
  const nlohmann::json& RequireObject() const;

  const nlohmann::json* value_;
  std::filesystem::path file_;
  std::string where_;
};

// --- codecs ----------------------------------------------------------------------------------

// [x, y, z], and back (\throw FormatError unless an array of 3 finite numbers).
nlohmann::json Vector3dToJson(const Eigen::Vector3d& v);

// {"rotation_row_major": [9 numbers], "translation": [x, y, z]} (metres), and back.
// \throw FormatError naming the field when malformed or not a rigid transform (rotation not
// orthonormal with determinant +1: Rigid3d::IsValid).
nlohmann::json Rigid3dToJson(const Rigid3d& pose);
Rigid3d Rigid3dFromJson(const JsonReader& object);

// A camera as session.json stores it: {"width", "height", "fx", "fy", "cx", "cy",
// "distortion": [k1, k2, p1, p2, k3], "cam_from_world": Rigid3dToJson}; `pose_key` names the
// pose field (the rig calibration file stores it as "cam_from_table"; empty: no pose, the
// identity, for intrinsics alone). Doubles are written in
// their shortest exact form, so reading back gives the same camera bit for bit.
nlohmann::json CameraModelToJson(const CameraModel& camera,
                                 std::string_view pose_key = "cam_from_world");
// \throw FormatError naming the field when malformed or when CameraModel::Validate refuses
// the camera ("views[3].camera_model: CameraModel.fx must be ...").
CameraModel CameraModelFromJson(const JsonReader& object,
                                std::string_view pose_key = "cam_from_world");

}  // namespace carousel
