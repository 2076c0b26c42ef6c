#pragma once
// m3dp quality RUN_DIR: a finished run's print measured against its design (quality/).
#include <CLI/CLI.hpp>

#include <filesystem>

namespace m3dp::app {

struct QualityOptions {
  std::filesystem::path run_folder;
  double spacing = 0.01;  // m between sections along each bead
};

void add_quality_options(CLI::App& command, QualityOptions& options);
int quality_command(const QualityOptions& options);

}  // namespace m3dp::app
