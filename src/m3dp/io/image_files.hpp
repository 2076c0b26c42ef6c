#pragma once
// Camera images as files that image tools read: PNG through libpng (8-bit RGB, 8- or 16-bit
// grey, e.g. depth in millimetres as ROS's 16UC1 or segment ids) and NumPy's .npy for float
// arrays (depth in metres). Written atomically, as every file of a run.
#include <cstdint>
#include <filesystem>
#include <span>

namespace m3dp::io {

/// `channels` (1 grey, 3 RGB) of `bit_depth` (8 or 16) per pixel, rows from the top; 16-bit
/// samples given in the machine's order (PNG stores them big-endian).
void write_png(const std::filesystem::path& file, int width, int height, int channels, int bit_depth, const void* pixels);

/// A C-ordered float32 array of shape (rows, columns) in NumPy's .npy format (version 1.0).
void write_npy(const std::filesystem::path& file, int rows, int columns, std::span<const float> values);

}  // namespace m3dp::io
