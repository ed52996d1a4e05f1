#include "carousel/core/options.h"

#include <array>
#include <charconv>
#include <cmath>

#include "carousel/core/error.h"

namespace carousel {
namespace {

std::string UnitSuffix(const OptionInfo& info) { return info.unit.empty() ? "" : " " + info.unit; }

}  // namespace

std::string OptionNumberText(double value) {
  std::array<char, 32> text{};
  const auto end = std::to_chars(text.data(), text.data() + text.size(), value).ptr;
  return std::string(text.data(), end);
}

std::string OptionInfo::RangeText() const {
  const bool low = std::isfinite(min), high = std::isfinite(max);
  std::string text;
  if (low && high) {
    if (!min_exclusive && !max_exclusive) {
      text = OptionNumberText(min) + ".." + OptionNumberText(max);
    } else {
      text = std::string(min_exclusive ? "(" : "[") + OptionNumberText(min) + ", " +
             OptionNumberText(max) + (max_exclusive ? ")" : "]");
    }
  } else if (low) {
    text = std::string(min_exclusive ? "> " : ">= ") + OptionNumberText(min);
  } else if (high) {
    text = std::string(max_exclusive ? "< " : "<= ") + OptionNumberText(max);
  }
  if (!text.empty()) text += UnitSuffix(*this);
  if (special) {
    text += (text.empty() ? "" : ", or ") + OptionNumberText(*special);
    if (!special_meaning.empty()) text += " = " + special_meaning;
  }
  return text;
}

bool OptionInfo::Allows(double value) const {
  if (special && value == *special) return true;
  if (!std::isfinite(value)) return false;
  if (min_exclusive ? !(value > min) : !(value >= min)) return false;
  if (max_exclusive ? !(value < max) : !(value <= max)) return false;
  return true;
}

void CheckOptionValue(const OptionInfo& info, double value) {
  if (info.Allows(value)) return;
  throw InvalidArgument("--" + info.name + " must be " + info.RangeText() + ", got " +
                        OptionNumberText(value));
}

void CheckOptionChoice(const OptionInfo& info, const std::string& value) {
  for (const std::string& choice : info.choices)
    if (choice == value) return;
  std::string list;
  for (std::size_t i = 0; i < info.choices.size(); ++i) {
    if (i > 0) list += i + 1 == info.choices.size() ? " or " : ", ";
    list += info.choices[i];
  }
  throw InvalidArgument("--" + info.name + " must be " + list + ", got '" + value + "'");
}

void CheckOptionName(const std::vector<std::string>& taken, const std::string& name) {
  bool well_formed = !name.empty() && name.front() != '-' && name.back() != '-';
  for (const char ch : name)
    well_formed =
        well_formed && ((ch >= 'a' && ch <= 'z') || (ch >= '0' && ch <= '9') || ch == '-');
  if (!well_formed) throw std::logic_error("option name '" + name + "' is not a flag name");
  for (const std::string& t : taken)
    if (t == name) throw std::logic_error("option '" + name + "' is described twice");
}

}  // namespace carousel
