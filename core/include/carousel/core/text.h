// Helpers for the readers of line-based text formats (OBJ, MTL, PLY and OFF headers,
// Middlebury par files, COLMAP text models).
#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace carousel {

// The whitespace-separated words of `line` (views into it).
std::vector<std::string_view> SplitWhitespace(std::string_view line);

// As SplitWhitespace, as strings.
std::vector<std::string> SplitWords(std::string_view line);

// A text file's lines without their line ends (\n or \r\n); a last line without a line end
// is kept. \throw IoError (missing, unreadable) or FormatError (a NUL byte: not a text file).
std::vector<std::string> ReadTextLines(const std::filesystem::path& path);

}  // namespace carousel
