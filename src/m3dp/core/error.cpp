#include "m3dp/core/error.hpp"

#include <fmt/format.h>

namespace m3dp {

std::string SourceLocation::str() const {
  if (line > 0) return fmt::format("{}:{}", file, line);
  return file;
}

std::string Diagnostic::str() const { return fmt::format("{}: error: {}", location.str(), message); }

namespace {
std::string join_diagnostics(const std::vector<Diagnostic>& diagnostics) {
  std::string text;
  for (const auto& diagnostic : diagnostics) {
    if (!text.empty()) text += '\n';
    text += diagnostic.str();
  }
  return text;
}
}  // namespace

InputError::InputError(std::vector<Diagnostic> diagnostics)
    : Error(join_diagnostics(diagnostics)), diagnostics_(std::move(diagnostics)) {}

InputError::InputError(SourceLocation location, const std::string& message)
    : InputError(std::vector<Diagnostic>{Diagnostic{std::move(location), message}}) {}

}  // namespace m3dp
