#include "viewer_files.hpp"

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <utility>

namespace m3dp::app {

namespace {

namespace fs = std::filesystem;

/// The project's folder: $M3DP_ROOT, else where it was built from.
fs::path project_root() {
  if (const char* root = std::getenv("M3DP_ROOT"); root && *root) return root;
  return M3DP_PROJECT_ROOT;
}

const char* content_type(const fs::path& file) {
  const std::string extension = file.extension().string();
  if (extension == ".html") return "text/html; charset=utf-8";
  if (extension == ".js" || extension == ".mjs") return "text/javascript; charset=utf-8";
  if (extension == ".css") return "text/css; charset=utf-8";
  if (extension == ".proto") return "text/plain; charset=utf-8";
  if (extension == ".json" || extension == ".map") return "application/json";
  if (extension == ".png") return "image/png";
  if (extension == ".svg") return "image/svg+xml";
  return nullptr;
}

}  // namespace

std::optional<record::HttpFile> viewer_file(std::string_view path) {
  const fs::path root = project_root();
  // URL prefix → folder under the project.
  const std::pair<std::string_view, fs::path> mounts[] = {
      {"/viewer/", root / "viewer"},
      {"/vendor/three/", root / "node_modules" / "three"},
      {"/vendor/uplot/", root / "node_modules" / "uplot" / "dist"},
      {"/vendor/protobufjs/", root / "node_modules" / "protobufjs" / "dist"},
      {"/schemas/", root / "src" / "m3dp" / "record" / "proto"},
  };
  fs::path file;
  if (path == "/" || path == "/index.html") {
    file = root / "viewer" / "index.html";
  } else {
    for (const auto& [prefix, folder] : mounts) {
      if (path.substr(0, prefix.size()) != prefix) continue;
      const fs::path relative(std::string(path.substr(prefix.size())));
      // No way out of the folder: no "..", no absolute parts.
      for (const auto& part : relative)
        if (part == ".." || part.string().empty() || part.is_absolute()) return std::nullopt;
      file = folder / relative;
      break;
    }
  }
  const char* type = file.empty() ? nullptr : content_type(file);
  if (!type || !fs::is_regular_file(file)) return std::nullopt;
  std::ifstream stream(file, std::ios::binary);
  std::ostringstream body;
  body << stream.rdbuf();
  return record::HttpFile{type, body.str()};
}

}  // namespace m3dp::app
