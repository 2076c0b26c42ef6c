#pragma once
// Files are written to a temporary name beside the target and renamed into place, so a run that
// is interrupted never leaves a half-written file under the real name.
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

namespace m3dp::io {

/// Calls write(stream) on a temporary file, then renames it to `target`. Throws m3dp::Error on failure.
void write_file_atomically(const std::filesystem::path& target, const std::function<void(std::ostream&)>& write,
                           bool binary = false);

/// Removes what writers killed mid-write left under `folder` (their temporary names), e.g. before a
/// run resumes there. Returns how many.
std::size_t remove_leftover_temporaries(const std::filesystem::path& folder);

/// Same for a whole string.
void write_text_atomically(const std::filesystem::path& target, const std::string& text);

}  // namespace m3dp::io
