#include "carousel/core/text.h"

#include <cctype>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"

namespace carousel {

std::vector<std::string_view> SplitWhitespace(std::string_view line) {
  std::vector<std::string_view> tokens;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    const std::size_t start = i;
    while (i < line.size() && !std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    if (i > start) tokens.push_back(line.substr(start, i - start));
  }
  return tokens;
}

std::vector<std::string> SplitWords(std::string_view line) {
  const std::vector<std::string_view> views = SplitWhitespace(line);
  return {views.begin(), views.end()};
}

std::vector<std::string> ReadTextLines(const std::filesystem::path& path) {
  const std::vector<std::uint8_t> bytes = ReadFileBytes(path);
  std::vector<std::string> lines;
  std::string current;
  for (std::uint8_t byte : bytes) {
    if (byte == 0) throw FormatError(path, "binary data in a text file");
    if (byte == '\n') {
      lines.push_back(current);
      current.clear();
    } else if (byte != '\r') {
      current.push_back(static_cast<char>(byte));
    }
  }
  if (!current.empty()) lines.push_back(current);
  return lines;
}

}  // namespace carousel
