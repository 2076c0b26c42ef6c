#pragma once
// Small helpers for the text file readers (meshes, G-code): lines with their numbers, for
// messages that name file:line.
#include <string_view>

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

}  // namespace m3dp
