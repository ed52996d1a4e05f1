#include "carousel/core/options.h"

#include <array>
#include <charconv>
#include <cmath>
#include <string>
#include <system_error>
#include <vector>

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

namespace {

[[noreturn]] void Refuse(const OptionInfo& info, const char* kind, const std::string& text) {
  throw InvalidArgument("--" + info.name + " takes " + kind + ", got '" + text + "'");
}

std::string Trimmed(const std::string& text) {
  const auto first = text.find_first_not_of(" \t");
  if (first == std::string::npos) return {};
  return text.substr(first, text.find_last_not_of(" \t") - first + 1);
}

template <typename T>
T ParseWhole(const OptionInfo& info, const std::string& raw, const char* kind) {
  const std::string text = Trimmed(raw);
  T value{};
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, value);
  if (text.empty() || ec != std::errc() || ptr != end) Refuse(info, kind, raw);
  return value;
}

std::vector<std::string> SplitList(const std::string& text) {
  std::vector<std::string> items;
  if (Trimmed(text).empty()) return items;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = text.find(',', start);
    items.push_back(text.substr(start, comma == std::string::npos ? comma : comma - start));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return items;
}

}  // namespace

int ParseOptionInt(const OptionInfo& info, const std::string& text) {
  return ParseWhole<int>(info, text, "a whole number");
}

double ParseOptionDouble(const OptionInfo& info, const std::string& text) {
  const double value = ParseWhole<double>(info, text, "a number");
  if (!std::isfinite(value)) Refuse(info, "a finite number", text);
  return value;
}

std::uint64_t ParseOptionUint64(const OptionInfo& info, const std::string& text) {
  return ParseWhole<std::uint64_t>(info, text, "a whole number >= 0");
}

bool ParseOptionBool(const OptionInfo& info, const std::string& raw) {
  const std::string text = Trimmed(raw);
  if (text == "true" || text == "1" || text == "on" || text == "yes") return true;
  if (text == "false" || text == "0" || text == "off" || text == "no") return false;
  Refuse(info, "true or false", raw);
}

std::vector<int> ParseOptionIntList(const OptionInfo& info, const std::string& text) {
  std::vector<int> values;
  for (const std::string& item : SplitList(text))
    values.push_back(ParseWhole<int>(info, item, "whole numbers separated by commas"));
  return values;
}

std::vector<double> ParseOptionDoubleList(const OptionInfo& info, const std::string& text) {
  std::vector<double> values;
  for (const std::string& item : SplitList(text)) {
    const double value = ParseWhole<double>(info, item, "numbers separated by commas");
    if (!std::isfinite(value)) Refuse(info, "finite numbers separated by commas", text);
    values.push_back(value);
  }
  return values;
}

}  // namespace carousel
