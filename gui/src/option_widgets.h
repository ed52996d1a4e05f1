// ImGui widgets made from an options description (core/options.h): the window's capture-plan
// fields are the same table `carousel run` makes its flags from. Private to gui/.
#pragma once

#include <map>
#include <string>
#include <variant>

#include <imgui.h>
#include <imgui_stdlib.h>

#include "carousel/core/error.h"
#include "carousel/core/options.h"

namespace carousel::gui {

// Text being edited per field, and the last error per field (a value refused).
struct OptionEditState {
  std::map<std::string, std::string> editing;
  std::map<std::string, std::string> errors;
};

// One row per field: a checkbox for a bool, a combo for a choice, a text field for the rest
// (committed when editing ends; a refused value keeps the old one and shows why). `advanced`
// fields only when `show_advanced`. Returns true when a value changed. Disabled while `locked`.
template <typename Owner>
bool OptionWidgets(const char* id, const OptionTable<Owner>& table, Owner& object,
                   OptionEditState& state, bool show_advanced, bool locked) {
  bool changed = false;
  ImGui::PushID(id);
  if (locked) ImGui::BeginDisabled();
  for (const OptionField<Owner>& field : table.fields()) {
    const OptionInfo& info = field.info;
    if (info.advanced && !show_advanced) continue;
    ImGui::PushID(info.name.c_str());
    const bool is_bool = !field.is_choice() && std::holds_alternative<bool*>(field.ref(object));
    if (is_bool) {
      bool* value = std::get<bool*>(field.ref(object));
      changed |= ImGui::Checkbox(info.name.c_str(), value);
    } else if (!info.choices.empty()) {
      // An enum (is_choice) or a word field with its set of values.
      const std::string current = GetOptionText(field, object);
      if (ImGui::BeginCombo(info.name.c_str(), current.c_str())) {
        for (const std::string& choice : info.choices) {
          if (ImGui::Selectable(choice.c_str(), choice == current) && choice != current) {
            SetOptionText(field, object, choice);
            changed = true;
          }
        }
        ImGui::EndCombo();
      }
    } else {
      auto it = state.editing.try_emplace(info.name, GetOptionText(field, object)).first;
      ImGui::InputText(info.name.c_str(), &it->second);
      if (ImGui::IsItemDeactivatedAfterEdit()) {
        try {
          Owner trial = object;
          SetOptionText(field, trial, it->second);
          table.Check(trial);
          object = trial;
          state.errors.erase(info.name);
          changed = true;
        } catch (const Error& e) {
          state.errors[info.name] = e.what();
        }
        it->second = GetOptionText(field, object);
      } else if (!ImGui::IsItemActive()) {
        it->second = GetOptionText(field, object);
      }
    }
    if (ImGui::IsItemHovered()) {
      std::string tip = info.help;
      const std::string range = info.RangeText();
      if (!range.empty()) tip += " (" + range + ")";
      ImGui::SetTooltip("%s", tip.c_str());
    }
    if (const auto err = state.errors.find(info.name); err != state.errors.end())
      ImGui::TextColored(ImVec4(1.0f, 0.45f, 0.4f, 1.0f), "%s", err->second.c_str());
    ImGui::PopID();
  }
  if (locked) ImGui::EndDisabled();
  ImGui::PopID();
  return changed;
}

}  // namespace carousel::gui
