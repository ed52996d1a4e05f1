// Files written so that a crash or a full disk never leaves a half-written file under its final
// name, and reads whose errors name the file (DESIGN.md: "no data already captured is ever lost
// or overwritten").
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

namespace carousel {

struct AtomicWriteOptions {
  // Replace an existing file of the same name. When false, an existing file is an IoError and
  // is left untouched.
  bool overwrite = true;
  // fsync the file and its folder before returning (durable across power loss).
  bool sync = true;
};

// Writes `bytes` to a temporary file beside `path`, flushes it, then renames it into place.
// \throw IoError naming `path` (missing folder, permission, disk full, ...); the temporary
//        file is removed and any previous file at `path` is untouched.
void WriteFileAtomic(const std::filesystem::path& path, std::span<const std::uint8_t> bytes,
                     const AtomicWriteOptions& options = {});
void WriteFileAtomic(const std::filesystem::path& path, const std::string& text,
                     const AtomicWriteOptions& options = {});

// Reads a whole file. \throw IoError if it does not exist, is a folder or cannot be read.
std::vector<std::uint8_t> ReadFileBytes(const std::filesystem::path& path);

// \throw IoError unless `path` is an existing, readable regular file.
void RequireReadableFile(const std::filesystem::path& path);

// A name for a temporary sibling of `path` (same folder, hidden, unique in this process).
std::filesystem::path TemporarySibling(const std::filesystem::path& path);

// Flushes the folder entry of `folder` to disk (after a rename into it). Best effort.
void SyncFolder(const std::filesystem::path& folder);

}  // namespace carousel
