// SHA-256 checksums (OpenSSL) of photos in the manifest and of stage inputs, lowercase hex.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

namespace carousel::studio {

// SHA-256 of a file. \throw IoError naming the file.
std::string FileSha256(const std::filesystem::path& path);
// SHA-256 of bytes in memory.
std::string Sha256(std::string_view bytes);

}  // namespace carousel::studio
