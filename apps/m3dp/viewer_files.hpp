#pragma once
// The browser viewer's files, answered over plain HTTP on the port of the live stream or of
// m3dp view: "/" is viewer/index.html, "/viewer/..." its modules, "/vendor/three/...",
// "/vendor/uplot/..." and "/vendor/protobufjs/..." the libraries npm ci installed in the
// project's node_modules, "/schemas/..." the messages' .proto files. Nothing outside those
// folders, and only known kinds of file.
#include <optional>
#include <string_view>

#include "m3dp/record/foxglove_server.hpp"

namespace m3dp::app {

[[nodiscard]] std::optional<record::HttpFile> viewer_file(std::string_view path);

}  // namespace m3dp::app
