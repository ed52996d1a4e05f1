// One description per options field (STYLE.md §4, DESIGN.md "every options field is described
// once"): its name, help, unit, range and (through the struct's default member initialiser) its
// default, kept beside each Options struct. The command line makes its flags from it (app/), the
// window its widgets (gui/), and the struct's Validate() its range checks, so an error names
// what the user typed: "--faces must be >= 100, got 50", not a struct field.
//
// A table is built once per Options type (a function-local static) and can include the table
// of a nested Options struct, so ReconstructOptions' table is its silhouette, hull and mesh
// tables together:
//
//   const OptionTable<MeshOptimizationOptions>& MeshOptimizationOptions::Fields() {
//     static const OptionTable<MeshOptimizationOptions> table = [] {
//       OptionTable<MeshOptimizationOptions> t;
//       t.Add(&MeshOptimizationOptions::target_faces,
//             {.name = "faces", .help = "faces of the optimized mesh", .min = 100});
//       return t;
//     }();
//     return table;
//   }
//
// Names are flag names without the dashes (lowercase, '-' between words) and unique within a
// table (Include() checks). A bool whose default is true is offered as --no-<name>.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

namespace carousel {

// A number as option text: the shortest form that reads back as the same double ("4096",
// "0.5", "1e-06", "22.5"), for ranges, defaults and the option values files record.
std::string OptionNumberText(double value);

// What a field means to a person, and the values it may take.
struct OptionInfo {
  std::string name;  // flag name without dashes, e.g. "faces"
  std::string help;  // one line, lowercase start, no final full stop
  std::string unit;  // "px", "m", "deg", "texels", "ms", ... ("" for counts and words)
  // Inclusive range of a number (of each element of a list of numbers).
  double min = -std::numeric_limits<double>::infinity();
  double max = std::numeric_limits<double>::infinity();
  // Exclusive bounds instead (e.g. a fraction in (0, 1]).
  bool min_exclusive = false, max_exclusive = false;
  // A value allowed outside the range with a meaning of its own ("0 = automatic").
  std::optional<double> special;
  std::string special_meaning;  // "automatic", "none", ...
  // Text fields with a fixed set of values (enums are added with AddChoice, which fills it).
  std::vector<std::string> choices;
  // Shown in advanced panels only; the command line offers it all the same.
  bool advanced = false;
  // A bool whose default is true is switched off by --<negative_name> (default "no-<name>").
  std::string negative_name;

  // "64..16384 texels, or 0 = automatic": the range in words, for help texts.
  std::string RangeText() const;
  // Whether `value` is allowed by the range (or is the special value).
  bool Allows(double value) const;
};

// Where a described field lives in one Options object.
using OptionRef = std::variant<int*, double*, bool*, std::uint64_t*, std::string*,
                               std::filesystem::path*, std::vector<int>*, std::vector<double>*>;

// A field: its description, and how to reach it in an object. Enums and composite values are
// reached through text (`text_get`/`text_set`; enums with `info.choices`), everything else
// through `ref`.
template <typename Owner>
struct OptionField {
  OptionInfo info;
  std::function<OptionRef(Owner&)> ref;  // empty for a choice
  std::function<std::string(const Owner&)> text_get;
  std::function<void(Owner&, const std::string&)> text_set;  // \throw InvalidArgument
  bool is_choice() const { return static_cast<bool>(text_get); }
};

// Throws InvalidArgument("--<name> must be ..., got ...") for a value outside `info`'s range.
void CheckOptionValue(const OptionInfo& info, double value);
void CheckOptionChoice(const OptionInfo& info, const std::string& value);
// Throws std::logic_error for a malformed table (a name twice, empty, not a flag name).
void CheckOptionName(const std::vector<std::string>& taken, const std::string& name);

// A value as a person types it (a GUI's text field, a front end's --name VALUE without CLI11):
// numbers parsed whole ("12", "0.5", "1e-3"; "12abc" is refused), bools "true"/"false"/"1"/"0"/
// "on"/"off", lists comma-separated. \throw InvalidArgument("--<name> takes <kind>, got '<text>'").
// Range checks are the options' Validate()'s.
int ParseOptionInt(const OptionInfo& info, const std::string& text);
double ParseOptionDouble(const OptionInfo& info, const std::string& text);
std::uint64_t ParseOptionUint64(const OptionInfo& info, const std::string& text);
bool ParseOptionBool(const OptionInfo& info, const std::string& text);
std::vector<int> ParseOptionIntList(const OptionInfo& info, const std::string& text);
std::vector<double> ParseOptionDoubleList(const OptionInfo& info, const std::string& text);

template <typename Owner>
class OptionTable {
 public:
  using Field = OptionField<Owner>;

  // A plain field of Owner.
  template <typename T>
  OptionTable& Add(T Owner::*member, OptionInfo info) {
    return Push(
        {std::move(info), [member](Owner& o) -> OptionRef { return &(o.*member); }, {}, {}});
  }

  // A field reached some other way (a member of a member).
  OptionTable& Add(OptionInfo info, std::function<OptionRef(Owner&)> ref) {
    return Push({std::move(info), std::move(ref), {}, {}});
  }

  // An enum field offered as words: choices = {{"obb", Mode::kObb}, {"aabb", Mode::kAabb}}.
  template <typename E>
  OptionTable& AddChoice(E Owner::*member, OptionInfo info,
                         std::vector<std::pair<std::string, E>> choices) {
    info.choices.clear();
    for (const auto& [word, value] : choices) info.choices.push_back(word);
    const OptionInfo copy = info;
    Field field;
    field.info = std::move(info);
    field.text_get = [member, choices](const Owner& o) {
      for (const auto& [word, value] : choices)
        if (o.*member == value) return word;
      return std::string();
    };
    field.text_set = [member, choices, copy](Owner& o, const std::string& text) {
      CheckOptionChoice(copy, text);
      for (const auto& [word, value] : choices)
        if (word == text) o.*member = value;
    };
    return Push(std::move(field));
  }

  // A field offered as text with its own parser (e.g. an image size "5184x3456" filling two
  // members): `set` throws InvalidArgument naming the flag for text it does not take.
  OptionTable& AddText(OptionInfo info, std::function<std::string(const Owner&)> get,
                       std::function<void(Owner&, const std::string&)> set) {
    Field field;
    field.info = std::move(info);
    field.text_get = std::move(get);
    field.text_set = std::move(set);
    return Push(std::move(field));
  }

  // Every field of a nested Options struct (its own table), reached through `member`.
  template <typename Sub>
  OptionTable& Include(Sub Owner::*member, const OptionTable<Sub>& sub) {
    for (const auto& f : sub.fields()) {
      Field field;
      field.info = f.info;
      if (f.ref) field.ref = [member, r = f.ref](Owner& o) { return r(o.*member); };
      if (f.text_get) {
        field.text_get = [member, g = f.text_get](const Owner& o) { return g(o.*member); };
        field.text_set = [member, s = f.text_set](Owner& o, const std::string& t) {
          s(o.*member, t);
        };
      }
      Push(std::move(field));
    }
    return *this;
  }

  // Only the named fields of a nested table (the others stay internal to that stage).
  template <typename Sub>
  OptionTable& Include(Sub Owner::*member, const OptionTable<Sub>& sub,
                       const std::vector<std::string>& names) {
    return Include(member, sub.Only(names));
  }

  // A copy with only the named fields, in the given order. \throw std::logic_error for a
  // name the table does not have.
  OptionTable Only(const std::vector<std::string>& names) const {
    OptionTable out;
    for (const std::string& name : names) out.Push(Find(name));
    return out;
  }

  // A copy without the named fields.
  OptionTable Without(const std::vector<std::string>& names) const {
    OptionTable out;
    for (const Field& f : fields_) {
      bool skip = false;
      for (const std::string& n : names) skip = skip || n == f.info.name;
      if (!skip) out.Push(f);
    }
    return out;
  }

  const Field& Find(const std::string& name) const {
    for (const Field& f : fields_)
      if (f.info.name == name) return f;
    throw std::logic_error("no option named '" + name + "'");
  }

  const std::vector<Field>& fields() const { return fields_; }

  // The range and choice checks of every field. \throw InvalidArgument naming the flag.
  void Check(const Owner& object) const {
    Owner& o = const_cast<Owner&>(object);  // read only: the refs are not const-qualified
    for (const Field& f : fields_) {
      if (f.is_choice()) {
        if (!f.info.choices.empty()) CheckOptionChoice(f.info, f.text_get(object));
        continue;
      }
      std::visit(
          [&f](auto* p) {
            using T = std::remove_pointer_t<decltype(p)>;
            if constexpr (std::is_same_v<T, int> || std::is_same_v<T, double> ||
                          std::is_same_v<T, std::uint64_t>) {
              CheckOptionValue(f.info, static_cast<double>(*p));
            } else if constexpr (std::is_same_v<T, std::vector<int>> ||
                                 std::is_same_v<T, std::vector<double>>) {
              for (const auto v : *p) CheckOptionValue(f.info, static_cast<double>(v));
            } else if constexpr (std::is_same_v<T, std::string>) {
              if (!f.info.choices.empty()) CheckOptionChoice(f.info, *p);
            }
          },
          f.ref(o));
    }
  }

 private:
  OptionTable& Push(Field field) {
    std::vector<std::string> taken;
    taken.reserve(fields_.size());
    for (const Field& f : fields_) taken.push_back(f.info.name);
    CheckOptionName(taken, field.info.name);
    fields_.push_back(std::move(field));
    return *this;
  }

  std::vector<Field> fields_;
};

// A field's value as text, the way SetOptionText reads it back.
template <typename Owner>
std::string GetOptionText(const OptionField<Owner>& field, const Owner& object) {
  if (field.is_choice()) return field.text_get(object);
  Owner& o = const_cast<Owner&>(object);  // read only: the refs are not const-qualified
  return std::visit(
      [](auto* value) -> std::string {
        using T = std::remove_pointer_t<decltype(value)>;
        if constexpr (std::is_same_v<T, bool>) {
          return *value ? "true" : "false";
        } else if constexpr (std::is_same_v<T, std::string>) {
          return *value;
        } else if constexpr (std::is_same_v<T, std::filesystem::path>) {
          return value->string();
        } else if constexpr (std::is_same_v<T, std::vector<int>> ||
                             std::is_same_v<T, std::vector<double>>) {
          std::string text;
          for (std::size_t i = 0; i < value->size(); ++i) {
            if (i > 0) text += ',';
            text += OptionNumberText(static_cast<double>((*value)[i]));
          }
          return text;
        } else {
          return OptionNumberText(static_cast<double>(*value));
        }
      },
      field.ref(o));
}

// Sets a field from text as typed (the Parse* functions above; enums and composite values
// through their own text). \throw InvalidArgument naming the flag.
template <typename Owner>
void SetOptionText(const OptionField<Owner>& field, Owner& object, const std::string& text) {
  if (field.is_choice()) {
    field.text_set(object, text);
    return;
  }
  std::visit(
      [&](auto* value) {
        using T = std::remove_pointer_t<decltype(value)>;
        const OptionInfo& info = field.info;
        if constexpr (std::is_same_v<T, int>) {
          *value = ParseOptionInt(info, text);
        } else if constexpr (std::is_same_v<T, double>) {
          *value = ParseOptionDouble(info, text);
        } else if constexpr (std::is_same_v<T, bool>) {
          *value = ParseOptionBool(info, text);
        } else if constexpr (std::is_same_v<T, std::uint64_t>) {
          *value = ParseOptionUint64(info, text);
        } else if constexpr (std::is_same_v<T, std::vector<int>>) {
          *value = ParseOptionIntList(info, text);
        } else if constexpr (std::is_same_v<T, std::vector<double>>) {
          *value = ParseOptionDoubleList(info, text);
        } else {
          *value = text;
        }
      },
      field.ref(object));
}

}  // namespace carousel
