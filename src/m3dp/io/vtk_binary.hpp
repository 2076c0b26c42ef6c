#pragma once
// The binary payload of a VTK XML DataArray: base64 text (what readers built on expat parse, see
// docs/architecture.md) with VTK's byte-count header, optionally zlib-compressed in blocks with
// the header layout of vtkZLibDataCompressor: [block count, block size, last block's size,
// compressed size of each block], each a UInt64 here (header_type="UInt64").
#include <cstddef>
#include <cstdint>
#include <string>
#include <span>
#include <string_view>
#include <vector>

namespace m3dp::io {

/// RFC 4648 base64 with '=' padding, appended to `out`.
void append_base64(std::string_view bytes, std::string& out);

/// Decodes base64 text, skipping whitespace. Returns false on any other character or bad padding.
[[nodiscard]] bool decode_base64(std::string_view text, std::string& out);

/// The base64 text of one array's `bytes` as VTK writes it in `format="appended"` or
/// `format="binary"` with header_type="UInt64": uncompressed, one base64 stream of the byte count
/// and the bytes; compressed, the header and the blocks each encoded on their own (VTK's
/// reader decodes them separately). Compressed blocks of `block_bytes` are deflated in parallel at
/// zlib `level` (0–9; negative: uncompressed).
[[nodiscard]] std::string encode_vtk_array(std::string_view bytes, int level, std::size_t block_bytes = 1 << 16);

/// The same for several arrays at once, their blocks deflated in one parallel loop (a frame's
/// small arrays alone hold too few blocks to keep the cores busy).
[[nodiscard]] std::vector<std::string> encode_vtk_arrays(std::span<const std::string_view> arrays, int level,
                                                         std::size_t block_bytes = 1 << 16);

/// How an array's payload is stored in a file.
struct VtkPayloadFormat {
  bool base64 = true;            // base64 text; false: raw bytes (format="appended" encoding="raw")
  bool zlib = false;             // compressor="vtkZLibDataCompressor"
  std::size_t header_bytes = 8;  // header_type: 4 (UInt32) or 8 (UInt64)
};

/// Decodes one array's payload starting at `data` (its first character or byte) into its
/// uncompressed bytes. On failure returns false and says why in `error`.
[[nodiscard]] bool decode_vtk_array(std::string_view data, const VtkPayloadFormat& format, std::string& out, std::string& error);

}  // namespace m3dp::io
