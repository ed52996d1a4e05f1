#include "carousel/core/json.h"

#include <cmath>
#include <utility>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"

namespace carousel {
namespace {

using nlohmann::json;

// A SAX handler that only follows where the parser is ("views[3].camera_model.fx"), to name
// the field of a parse error. Run on the text again once the ordinary parse has failed.
class PathTracker {
 public:
  bool null() { return Value(); }
  bool boolean(bool /*value*/) { return Value(); }
  bool number_integer(json::number_integer_t /*value*/) { return Value(); }
  bool number_unsigned(json::number_unsigned_t /*value*/) { return Value(); }
  bool number_float(json::number_float_t /*value*/, const json::string_t& /*text*/) {
    return Value();
  }
  bool string(json::string_t& /*value*/) { return Value(); }
  bool binary(json::binary_t& /*value*/) { return Value(); }
  bool start_object(std::size_t /*size*/) { return Push(false); }
  bool key(json::string_t& name) {
    frames_.back().key = name;
    return true;
  }
  bool end_object() { return Pop(); }
  bool start_array(std::size_t /*size*/) { return Push(true); }
  bool end_array() { return Pop(); }
  bool parse_error(std::size_t /*position*/, const std::string& /*token*/,
                   const json::exception& /*error*/) {
    failed_ = true;
    return false;
  }

  bool failed() const { return failed_; }
  // The field being read when the parse stopped; empty at the top level.
  std::string Path() const {
    std::string path;
    for (const Frame& frame : frames_) {
      if (frame.array) {
        path.append("[").append(std::to_string(frame.index)).append("]");
      } else if (!frame.key.empty()) {
        if (!path.empty()) path.append(".");
        path.append(frame.key);
      } else {
        break;  // between two fields of this object
      }
    }
    return path;
  }

 private:
  struct Frame {
    bool array = false;
    std::size_t index = 0;  // array: the element being read
    std::string key;        // object: the field being read, empty between fields
  };

  // A value is complete: the enclosing array moves to its next element, the enclosing object
  // waits for its next key.
  bool Value() {
    if (!frames_.empty()) {
      Frame& top = frames_.back();
      if (top.array) {
        ++top.index;
      } else {
        top.key.clear();
      }
    }
    return true;
  }
  bool Push(bool array) {
    frames_.push_back({array, 0, {}});
    return true;
  }
  bool Pop() {
    frames_.pop_back();
    return Value();
  }

  std::vector<Frame> frames_;
  bool failed_ = false;
};

// nlohmann's message without its "[json.exception.parse_error.101] " prefix.
std::string Reason(const json::exception& e) {
  const std::string text = e.what();
  if (text.rfind("[json.exception.", 0) == 0) {
    const std::size_t end = text.find("] ");
    if (end != std::string::npos) return text.substr(end + 2);
  }
  return text;
}

template <typename T>
std::optional<T> Optional(const JsonReader& reader, std::string_view key,
                          T (JsonReader::*read)() const) {
  const std::optional<JsonReader> member = reader.OptionalMember(key);
  if (!member) return std::nullopt;
  return ((*member).*read)();
}

}  // namespace

json ParseJsonText(std::string_view text, const std::filesystem::path& source) {
  try {
    return json::parse(text.begin(), text.end());
  } catch (const json::exception& e) {
    // Syntax errors and numbers out of range (1e999, out_of_range.406) alike.
    PathTracker tracker;
    json::sax_parse(text.begin(), text.end(), &tracker);
    const std::string field = tracker.failed() ? tracker.Path() : std::string();
    throw FormatError(source, (field.empty() ? std::string("not valid JSON: ")
                                             : "not valid JSON at " + field + ": ") +
                                  Reason(e));
  }
}

json ParseJsonFile(const std::filesystem::path& path) {
  const std::vector<std::uint8_t> bytes = ReadFileBytes(path);
  return ParseJsonText(std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()),
                       path);
}

JsonReader::JsonReader(const json& value, std::filesystem::path file, std::string where)
    : value_(&value), file_(std::move(file)), where_(std::move(where)) {}

std::string JsonReader::Name() const {
  return where_.empty() ? std::string("the top-level object") : where_;
}

std::string JsonReader::FieldPath(std::string_view key) const {
  std::string path = where_;
  if (!path.empty()) path.append(".");
  path.append(key);
  return path;
}

void JsonReader::Fail(const std::string& what) const { throw FormatError(file_, what); }

int JsonReader::AsInt() const {
  if (!value_->is_number_integer()) Fail(Name() + " is not an integer");
  const bool fits = value_->is_number_unsigned()
                        ? value_->get<std::uint64_t>() <=
                              static_cast<std::uint64_t>(std::numeric_limits<int>::max())
                        : value_->get<std::int64_t>() >= std::numeric_limits<int>::min() &&
                              value_->get<std::int64_t>() <= std::numeric_limits<int>::max();
  if (!fits) Fail(Name() + " is out of range (" + value_->dump() + ")");
  return value_->get<int>();
}

std::uint64_t JsonReader::AsUint64() const {
  if (!value_->is_number_integer()) Fail(Name() + " is not an integer");
  if (!value_->is_number_unsigned() && value_->get<std::int64_t>() < 0) {
    Fail(Name() + " is negative (" + value_->dump() + ")");
  }
  return value_->get<std::uint64_t>();
}

double JsonReader::AsNumber() const {
  if (!value_->is_number()) Fail(Name() + " is not a number");
  const double number = value_->get<double>();
  if (!std::isfinite(number)) Fail(Name() + " is not finite");
  return number;
}

bool JsonReader::AsBool() const {
  if (!value_->is_boolean()) Fail(Name() + " is not true or false");
  return value_->get<bool>();
}

std::string JsonReader::AsString() const {
  if (!value_->is_string()) Fail(Name() + " is not a string");
  return value_->get<std::string>();
}

std::string JsonReader::AsRelativePath(std::string_view folder) const {
  std::string text = AsString();
  if (text.empty()) Fail(Name() + " is empty");
  const std::filesystem::path path(text);
  if (path.is_absolute()) Fail(Name() + " is an absolute path: " + text);
  for (const auto& part : path) {
    if (part == "..") {
      std::string what = Name();
      what.append(" leaves the ").append(folder).append(": ").append(text);
      Fail(what);
    }
  }
  return text;
}

std::vector<double> JsonReader::AsNumbers(std::size_t count) const {
  if (!value_->is_array() || (count != kAnyCount && value_->size() != count)) {
    Fail(Name() + (count == kAnyCount
                       ? std::string(" must be an array of numbers")
                       : " must be an array of " + std::to_string(count) + " numbers"));
  }
  std::vector<double> numbers;
  numbers.reserve(value_->size());
  for (const JsonReader& item : AsArray()) numbers.push_back(item.AsNumber());
  return numbers;
}

std::vector<int> JsonReader::AsInts() const {
  if (!value_->is_array()) Fail(Name() + " must be an array of integers");
  std::vector<int> numbers;
  numbers.reserve(value_->size());
  for (const JsonReader& item : AsArray()) numbers.push_back(item.AsInt());
  return numbers;
}

std::map<std::string, std::string> JsonReader::AsStringMap() const {
  std::map<std::string, std::string> map;
  for (const auto& [key, item] : RequireObject().items()) {
    map[key] = JsonReader(item, file_, FieldPath(key)).AsString();
  }
  return map;
}

std::vector<JsonReader> JsonReader::AsArray() const {
  if (!value_->is_array()) Fail(Name() + " is not an array");
  std::vector<JsonReader> items;
  items.reserve(value_->size());
  for (std::size_t i = 0; i < value_->size(); ++i) {
    items.emplace_back((*value_)[i], file_, where_ + "[" + std::to_string(i) + "]");
  }
  return items;
}

Eigen::Vector3d JsonReader::AsVector3() const {
  const std::vector<double> v = AsNumbers(3);
  return {v[0], v[1], v[2]};
}

const json& JsonReader::RequireObject() const {
  if (!value_->is_object()) Fail(Name() + " is not an object");
  return *value_;
}

bool JsonReader::Has(std::string_view key) const { return RequireObject().contains(key); }

JsonReader JsonReader::Member(std::string_view key) const {
  const json& object = RequireObject();
  const auto it = object.find(key);
  if (it == object.end()) Fail(Name() + " has no field '" + std::string(key) + "'");
  return {*it, file_, FieldPath(key)};
}

std::optional<JsonReader> JsonReader::OptionalMember(std::string_view key) const {
  if (!Has(key)) return std::nullopt;
  return Member(key);
}

JsonReader JsonReader::Object(std::string_view key) const {
  JsonReader member = Member(key);
  member.RequireObject();
  return member;
}

std::optional<JsonReader> JsonReader::OptionalObject(std::string_view key) const {
  if (!Has(key)) return std::nullopt;
  return Object(key);
}

JsonReader JsonReader::ObjectOrEmpty(std::string_view key) const {
  static const json kEmpty = json::object();
  if (!Has(key)) return {kEmpty, file_, FieldPath(key)};
  return Object(key);
}

std::optional<int> JsonReader::OptionalInt(std::string_view key) const {
  return Optional(*this, key, &JsonReader::AsInt);
}

std::optional<double> JsonReader::OptionalNumber(std::string_view key) const {
  return Optional(*this, key, &JsonReader::AsNumber);
}

std::optional<bool> JsonReader::OptionalBool(std::string_view key) const {
  return Optional(*this, key, &JsonReader::AsBool);
}

std::optional<std::string> JsonReader::OptionalString(std::string_view key) const {
  return Optional(*this, key, &JsonReader::AsString);
}

std::optional<std::string> JsonReader::OptionalRelativePath(std::string_view key,
                                                            std::string_view folder) const {
  if (!Has(key)) return std::nullopt;
  return RelativePath(key, folder);
}

std::optional<std::map<std::string, std::string>> JsonReader::OptionalStringMap(
    std::string_view key) const {
  return Optional(*this, key, &JsonReader::AsStringMap);
}

json Vector3dToJson(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

json Rigid3dToJson(const Rigid3d& pose) {
  json rotation = json::array();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) rotation.push_back(pose.rotation(r, c));
  }
  return {{"rotation_row_major", rotation}, {"translation", Vector3dToJson(pose.translation)}};
}

Rigid3d Rigid3dFromJson(const JsonReader& object) {
  const std::vector<double> r = object.Numbers("rotation_row_major", 9);
  Rigid3d pose;
  for (int i = 0; i < 9; ++i) pose.rotation(i / 3, i % 3) = r[i];
  pose.translation = object.Vector3("translation");
  if (!pose.IsValid()) {
    object.Fail(object.Name() +
                " is not a rigid transform (rotation not orthonormal with determinant +1)");
  }
  return pose;
}

json CameraModelToJson(const CameraModel& camera, std::string_view pose_key) {
  const Distortion& d = camera.distortion;
  json j = {{"width", camera.width},
            {"height", camera.height},
            {"fx", camera.fx},
            {"fy", camera.fy},
            {"cx", camera.cx},
            {"cy", camera.cy},
            {"distortion", {d.k1, d.k2, d.p1, d.p2, d.k3}}};
  if (!pose_key.empty()) j[std::string(pose_key)] = Rigid3dToJson(camera.cam_from_world);
  return j;
}

CameraModel CameraModelFromJson(const JsonReader& object, std::string_view pose_key) {
  CameraModel camera;
  camera.width = object.Int("width");
  camera.height = object.Int("height");
  camera.fx = object.Number("fx");
  camera.fy = object.Number("fy");
  camera.cx = object.Number("cx");
  camera.cy = object.Number("cy");
  const std::vector<double> d = object.Numbers("distortion", 5);
  camera.distortion = {d[0], d[1], d[2], d[3], d[4]};
  if (!pose_key.empty()) camera.cam_from_world = Rigid3dFromJson(object.Object(pose_key));
  try {
    camera.Validate();
  } catch (const InvalidArgument& e) {
    object.Fail(object.Name() + ": " + e.what());
  }
  return camera;
}

}  // namespace carousel
