#pragma once
// Small helpers for the text file readers (scenes, meshes, G-code, waypoints): whole files, lines
// with their numbers (for messages that name file:line), and words.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <string_view>
#include <vector>

#include "m3dp/core/error.hpp"

namespace m3dp {

/// Calls `visit(line_text, line_number)` for each line (1-based), without the line break.
template <typename Visitor>
void for_each_line(std::string_view text, Visitor&& visit) {
  int line_number = 0;
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    ++line_number;
    visit(text.substr(start, end - start), line_number);
    start = end + 1;
  }
}

/// The words of `text`, split at any of `separators` (by default white space).
inline std::vector<std::string_view> split_words(std::string_view text, std::string_view separators = " \t\r\n\v\f") {
  std::vector<std::string_view> words;
  std::size_t position = text.find_first_not_of(separators);
  while (position != std::string_view::npos) {
    const std::size_t end = std::min(text.find_first_of(separators, position), text.size());
    words.push_back(text.substr(position, end - position));
    position = text.find_first_not_of(separators, end);
  }
  return words;
}

/// The whole file as text. Throws InputError naming the file ("cannot open the <what>").
inline std::string read_text_file(const std::filesystem::path& file, std::string_view what) {
  std::error_code error;
  if (!std::filesystem::is_regular_file(file, error))
    throw InputError(SourceLocation{file.string(), 0}, "cannot read the " + std::string(what) + ": no such file");
  std::ifstream stream(file, std::ios::binary);
  if (!stream) throw InputError(SourceLocation{file.string(), 0}, "cannot open the " + std::string(what) + " for reading");
  return std::string((std::istreambuf_iterator<char>(stream)), std::istreambuf_iterator<char>());
}

/// Maps byte offsets in a text (an XML document's offset_debug) to 1-based line numbers; 0 for none.
class LineIndex {
 public:
  explicit LineIndex(std::string_view text) {
    for (std::size_t offset = 0; offset < text.size(); ++offset) {
      if (text[offset] == '\n') newline_offsets_.push_back(std::ptrdiff_t(offset));
    }
  }
  [[nodiscard]] int line_at(std::ptrdiff_t offset) const {
    if (offset < 0) return 0;
    const auto newlines_before = std::lower_bound(newline_offsets_.begin(), newline_offsets_.end(), offset);
    return int(newlines_before - newline_offsets_.begin()) + 1;
  }

 private:
  std::vector<std::ptrdiff_t> newline_offsets_;
};

}  // namespace m3dp
