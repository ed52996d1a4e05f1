// Options objects as JSON through their OptionTable (options.h): one object per table, keyed by
// the flag names, so that a file records the same words a user types (run.json keeps the
// options a resumed session must use again).
#pragma once

#include <filesystem>
#include <string>
#include <type_traits>
#include <variant>

#include <nlohmann/json.hpp>

#include "carousel/core/error.h"
#include "carousel/core/options.h"

namespace carousel {

// {"<flag name>": value, ...} for every field of `table`: numbers, bools, words and lists as
// themselves, paths as strings, enums and composite values as their text.
template <typename Owner>
nlohmann::json OptionsToJson(const OptionTable<Owner>& table, const Owner& object) {
  nlohmann::json out = nlohmann::json::object();
  Owner& o = const_cast<Owner&>(object);  // read only: the refs are not const-qualified
  for (const OptionField<Owner>& field : table.fields()) {
    const std::string& name = field.info.name;
    if (field.is_choice()) {
      out[name] = field.text_get(object);
      continue;
    }
    std::visit(
        [&](auto* value) {
          using T = std::remove_pointer_t<decltype(value)>;
          if constexpr (std::is_same_v<T, std::filesystem::path>) {
            out[name] = value->string();
          } else {
            out[name] = *value;
          }
        },
        field.ref(o));
  }
  return out;
}

// Sets the fields of `object` named in `j` (an object written by OptionsToJson); a field that
// `j` does not name keeps its value, so a file from an older version reads with today's
// defaults. Values are not range-checked here (the options' Validate() does that).
// \throw FormatError naming `file` and the field for a value of the wrong type or word.
template <typename Owner>
void OptionsFromJson(const OptionTable<Owner>& table, const nlohmann::json& j, Owner* object,
                     const std::filesystem::path& file) {
  if (!j.is_object()) throw FormatError(file, "options must be a JSON object, got " + j.dump());
  for (const OptionField<Owner>& field : table.fields()) {
    const std::string& name = field.info.name;
    const auto it = j.find(name);
    if (it == j.end()) continue;
    try {
      if (field.is_choice()) {
        field.text_set(*object, it->template get<std::string>());
        continue;
      }
      std::visit(
          [&](auto* value) {
            using T = std::remove_pointer_t<decltype(value)>;
            if constexpr (std::is_same_v<T, std::filesystem::path>) {
              *value = it->template get<std::string>();
            } else {
              *value = it->template get<T>();
            }
          },
          field.ref(*object));
    } catch (const nlohmann::json::exception& e) {
      throw FormatError(file, "option '" + name + "': " + e.what());
    } catch (const InvalidArgument& e) {
      throw FormatError(file, "option '" + name + "': " + e.what());
    }
  }
}

}  // namespace carousel
