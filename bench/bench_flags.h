// Command-line flags for the benchmark programs in bench/ (CLI11 stays in app/). Each flag is
// registered with the variable it sets; the variable's value at registration is its default,
// which --help shows. Accepted forms:
//   --name VALUE, --name=VALUE   an option (a whole number, a real number, text or a path)
//   --name, --name=true|false    a flag (also 1|0, yes|no, on|off)
//   --name 1,2,3                 a list of whole numbers; the first use replaces the default,
//                                repeating the flag or writing more values after it appends
//   -h, --help                   prints the flags with their defaults
// An unknown flag, a missing or malformed value, or an option given twice is an error that
// names the flag; the bench's main then returns BenchFlags::kUsageError (64, EX_USAGE).
//
//   int width = 5184;
//   BenchFlags flags(argc, argv, "x_bench: what it measures");
//   flags.Option("--width", &width, "image width, px");
//   if (const std::optional<int> exit_code = flags.Parse(std::cout, std::cerr)) return *exit_code;
#pragma once

#include <algorithm>
#include <charconv>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <optional>
#include <ostream>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <utility>
#include <vector>

namespace carousel {

class BenchFlags {
 public:
  // What main returns for a command line it rejects (EX_USAGE in <sysexits.h>).
  static constexpr int kUsageError = 64;

  // `about` opens the help: the program's name and what it measures.
  BenchFlags(int argc, char** argv, std::string about)
      : args_(argv + std::min(argc, 1), argv + argc), about_(std::move(about)) {
    const std::string_view path = argc > 0 ? argv[0] : "bench";
    program_ = path.substr(path.rfind('/') + 1);
  }

  // An option taking one value: T is an integer type, double, std::string or
  // std::filesystem::path.
  template <class T>
  BenchFlags& Option(const char* name, T* value, const char* help = "") {
    static_assert(!std::is_same_v<T, bool>, "a bool is a Flag");
    return Add({name, help, TypeName<T>(), Format(*value), Kind::kOption,
                [value](std::string_view text, bool) { return ParseValue(text, value); }});
  }

  // A flag: given alone it sets *value to true.
  BenchFlags& Flag(const char* name, bool* value, const char* help = "") {
    return Add({name, help, "", *value ? "true" : "false", Kind::kFlag,
                [value](std::string_view text, bool) { return ParseBool(text, value); }});
  }

  // A comma-separated list of whole numbers.
  BenchFlags& List(const char* name, std::vector<int>* values, const char* help = "") {
    std::string text;
    for (const int v : *values) {
      if (!text.empty()) text.push_back(',');
      text.append(std::to_string(v));
    }
    return Add(
        {name, help, "INT,...", text, Kind::kList, [values](std::string_view items, bool first) {
           if (first) values->clear();
           return ParseList(items, values);
         }});
  }

  // Reads the command line into the registered variables. Returns std::nullopt when the bench
  // should run, else the code main returns: 0 after printing the help on `out`, kUsageError
  // after printing what is wrong on `err`.
  std::optional<int> Parse(std::ostream& out, std::ostream& err) {
    for (std::size_t i = 0; i < args_.size(); ++i) {
      const std::string_view arg = args_[i];
      if (arg == "-h" || arg == "--help") {
        PrintHelp(out);
        return 0;
      }
      const std::size_t equals = arg.find('=');
      const std::string_view name = arg.substr(0, equals);
      Entry* entry = Find(name);
      if (entry == nullptr) {
        const char* what = name.starts_with("--") ? "unknown flag" : "unexpected argument";
        return Fail(err, std::string(what) + " '" + std::string(name) + "'");
      }
      std::string_view text = "true";
      if (equals != std::string_view::npos) {
        text = arg.substr(equals + 1);
      } else if (entry->kind != Kind::kFlag) {
        if (i + 1 == args_.size()) return Fail(err, entry->name + " needs a value");
        text = args_[++i];
      }
      if (entry->kind == Kind::kOption && entry->count > 0)
        return Fail(err, entry->name + " given twice");
      const bool first = entry->count++ == 0;
      if (!entry->set(text, first)) return Fail(err, BadValue(*entry, text));
      // A list also takes the values after it, up to the next flag: `--sizes 8192 0`.
      while (entry->kind == Kind::kList && i + 1 < args_.size() && !args_[i + 1].starts_with('-')) {
        text = args_[++i];
        if (!entry->set(text, false)) return Fail(err, BadValue(*entry, text));
      }
    }
    return std::nullopt;
  }

 private:
  enum class Kind { kOption, kFlag, kList };

  struct Entry {
    std::string name;
    std::string help;
    std::string type;          // what --help shows after the name, e.g. "INT"
    std::string default_text;  // empty = no default shown
    Kind kind;
    // Stores the text (`first`: the flag's first use); false if the text is malformed.
    std::function<bool(std::string_view text, bool first)> set;
    int count = 0;  // times given on the command line
  };

  BenchFlags& Add(Entry entry) {
    entries_.push_back(std::move(entry));
    return *this;
  }

  Entry* Find(std::string_view name) {
    for (Entry& e : entries_)
      if (e.name == name) return &e;
    return nullptr;
  }

  std::optional<int> Fail(std::ostream& err, const std::string& what) const {
    err << program_ << ": " << what << " (see --help)\n";
    return kUsageError;
  }

  static std::string BadValue(const Entry& entry, std::string_view text) {
    const std::string expected = entry.kind == Kind::kFlag ? "true or false" : entry.type;
    return entry.name + ": bad value '" + std::string(text) + "' (expected " + expected + ")";
  }

  void PrintHelp(std::ostream& out) const {
    std::vector<std::pair<std::string, std::string>> lines;  // "--name TYPE", "help (default)"
    for (const Entry& e : entries_) {
      std::string text = e.help;
      if (!e.default_text.empty()) {
        text.append(text.empty() ? "(default " : " (default ");
        text.append(e.default_text).append(")");
      }
      lines.emplace_back(e.type.empty() ? e.name : e.name + " " + e.type, text);
    }
    lines.emplace_back("-h, --help", "print this help and exit");
    std::size_t width = 0;
    for (const auto& line : lines) width = std::max(width, line.first.size());
    out << about_ << "\nusage: " << program_ << " [flags]\n";
    for (const auto& [head, text] : lines)
      out << "  " << head << std::string(width - head.size() + 2, ' ') << text << "\n";
  }

  template <class T>
  static std::string TypeName() {
    if constexpr (std::is_integral_v<T>) return "INT";
    if constexpr (std::is_floating_point_v<T>) return "REAL";
    if constexpr (std::is_same_v<T, std::filesystem::path>) return "PATH";
    return "TEXT";
  }

  template <class T>
  static std::string Format(const T& value) {
    if constexpr (std::is_arithmetic_v<T>) {
      std::ostringstream text;
      text << value;
      return text.str();
    } else if constexpr (std::is_same_v<T, std::filesystem::path>) {
      return value.string();
    } else {
      static_assert(std::is_same_v<T, std::string>, "an option is a number, text or a path");
      return value;
    }
  }

  // The whole of `text` as a T (numbers in decimal); false if it is not one.
  template <class T>
  static bool ParseValue(std::string_view text, T* value) {
    if constexpr (std::is_arithmetic_v<T>) {
      T parsed{};
      const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), parsed);
      if (error != std::errc() || end != text.data() + text.size()) return false;
      *value = parsed;
    } else {
      *value = T(std::string(text));
    }
    return true;
  }

  static bool ParseBool(std::string_view text, bool* value) {
    if (text == "true" || text == "1" || text == "yes" || text == "on")
      *value = true;
    else if (text == "false" || text == "0" || text == "no" || text == "off")
      *value = false;
    else
      return false;
    return true;
  }

  // Appends the comma-separated whole numbers in `text` (empty items skipped, as in "3,11,");
  // false if an item is not a whole number or there is none.
  static bool ParseList(std::string_view text, std::vector<int>* values) {
    std::size_t added = 0;
    for (std::size_t start = 0; start <= text.size();) {
      const std::size_t end = std::min(text.find(',', start), text.size());
      if (end > start) {
        int v = 0;
        if (!ParseValue(text.substr(start, end - start), &v)) return false;
        values->push_back(v);
        ++added;
      }
      start = end + 1;
    }
    return added > 0;
  }

  std::vector<std::string_view> args_;  // argv[1..argc)
  std::string about_;
  std::string program_;  // argv[0]'s file name
  std::vector<Entry> entries_;
};

}  // namespace carousel
