#include "m3dp/io/image_files.hpp"

#include <fmt/format.h>
#include <png.h>

#include <cstring>
#include <string>
#include <vector>

#include "m3dp/core/error.hpp"
#include "m3dp/io/atomic_file.hpp"

namespace m3dp::io {

namespace {

/// libpng writes through this into memory; the file is then written atomically.
void append_to_string(png_structp png, png_bytep data, png_size_t length) {
  static_cast<std::string*>(png_get_io_ptr(png))->append(reinterpret_cast<const char*>(data), length);
}
void flush_nothing(png_structp /*png*/) {}

}  // namespace

void write_png(const std::filesystem::path& file, int width, int height, int channels, int bit_depth, const void* pixels) {
  if (width <= 0 || height <= 0 || (channels != 1 && channels != 3) || (bit_depth != 8 && bit_depth != 16))
    throw Error(fmt::format("{}: cannot write a {}x{} PNG of {} channels at {} bits", file.string(), width, height, channels, bit_depth));
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info) {
    png_destroy_write_struct(&png, &info);
    throw Error(fmt::format("{}: libpng could not start", file.string()));
  }
  std::string encoded;
  const std::size_t row_bytes = static_cast<std::size_t>(width) * channels * (bit_depth / 8);
  std::vector<unsigned char> row(row_bytes);
  if (setjmp(png_jmpbuf(png))) {  // libpng's errors land here
    png_destroy_write_struct(&png, &info);
    throw Error(fmt::format("{}: libpng failed to encode the image", file.string()));
  }
  png_set_write_fn(png, &encoded, append_to_string, flush_nothing);
  png_set_IHDR(png, info, static_cast<png_uint_32>(width), static_cast<png_uint_32>(height), bit_depth,
               channels == 3 ? PNG_COLOR_TYPE_RGB : PNG_COLOR_TYPE_GRAY, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_set_compression_level(png, 1);  // fast: cameras write many frames
  png_set_filter(png, 0, PNG_FILTER_SUB);
  png_write_info(png, info);
  const auto* source = static_cast<const unsigned char*>(pixels);
  for (int y = 0; y < height; ++y) {
    std::memcpy(row.data(), source + static_cast<std::size_t>(y) * row_bytes, row_bytes);
    if (bit_depth == 16)
      for (std::size_t i = 0; i + 1 < row_bytes; i += 2) std::swap(row[i], row[i + 1]);  // to big-endian (x86, ARM are little)
    png_write_row(png, row.data());
  }
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  write_file_atomically(file, [&](std::ostream& stream) { stream.write(encoded.data(), static_cast<std::streamsize>(encoded.size())); }, true);
}

void write_npy(const std::filesystem::path& file, int rows, int columns, std::span<const float> values) {
  if (values.size() != static_cast<std::size_t>(rows) * static_cast<std::size_t>(columns))
    throw Error(fmt::format("{}: {} values for a {}x{} array", file.string(), values.size(), rows, columns));
  // The header: magic, version 1.0, its length, a Python dict literal padded with spaces to a
  // multiple of 64 bytes and ended by a newline.
  std::string header = fmt::format("{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}), }}", rows, columns);
  const std::size_t preamble = 10;
  header.append(64 - (preamble + header.size() + 1) % 64, ' ');
  header += '\n';
  write_file_atomically(file, [&](std::ostream& stream) {
    stream.write("\x93NUMPY\x01\x00", 8);
    const auto length = static_cast<std::uint16_t>(header.size());
    const char length_bytes[2] = {static_cast<char>(length & 0xFF), static_cast<char>(length >> 8)};
    stream.write(length_bytes, 2);
    stream << header;
    stream.write(reinterpret_cast<const char*>(values.data()), static_cast<std::streamsize>(values.size() * sizeof(float)));
  }, true);
}

}  // namespace m3dp::io
