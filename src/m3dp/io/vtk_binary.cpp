#include "m3dp/io/vtk_binary.hpp"

#include <fmt/format.h>
#include <libdeflate.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <zlib.h>

#include <array>
#include <bit>
#include <cstring>
#include <memory>
#include <vector>

#include "m3dp/core/error.hpp"

namespace m3dp::io {

namespace {

static_assert(std::endian::native == std::endian::little, "VTK files are written little-endian");

constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

constexpr std::array<std::int8_t, 256> decode_table() {
  std::array<std::int8_t, 256> table{};
  for (auto& value : table) value = -1;
  for (int i = 0; i < 64; ++i) table[static_cast<unsigned char>(kAlphabet[i])] = static_cast<std::int8_t>(i);
  return table;
}
constexpr auto kDecode = decode_table();

/// Encodes `bytes` (a whole number of 3-byte groups, or the last piece of a stream) into `out`.
void encode_groups(const unsigned char* bytes, std::size_t count, char* out) {
  std::size_t i = 0;
  for (; i + 3 <= count; i += 3, out += 4) {
    const std::uint32_t group = (std::uint32_t(bytes[i]) << 16) | (std::uint32_t(bytes[i + 1]) << 8) | bytes[i + 2];
    out[0] = kAlphabet[group >> 18];
    out[1] = kAlphabet[(group >> 12) & 63];
    out[2] = kAlphabet[(group >> 6) & 63];
    out[3] = kAlphabet[group & 63];
  }
  if (const std::size_t rest = count - i; rest > 0) {
    const std::uint32_t group = (std::uint32_t(bytes[i]) << 16) | (rest == 2 ? std::uint32_t(bytes[i + 1]) << 8 : 0);
    out[0] = kAlphabet[group >> 18];
    out[1] = kAlphabet[(group >> 12) & 63];
    out[2] = rest == 2 ? kAlphabet[(group >> 6) & 63] : '=';
    out[3] = '=';
  }
}

std::size_t encoded_size(std::size_t bytes) { return 4 * ((bytes + 2) / 3); }

/// Parallel over chunks of whole groups: the text of a 10 MB frame takes a few milliseconds.
void append_base64_parallel(std::string_view bytes, std::string& out) {
  constexpr std::size_t kChunk = 3 * 16384;
  const std::size_t start = out.size();
  out.resize(start + encoded_size(bytes.size()));
  const auto* data = reinterpret_cast<const unsigned char*>(bytes.data());
  const std::size_t chunks = (bytes.size() + kChunk - 1) / kChunk;
  tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t c) {
    const std::size_t first = c * kChunk;
    const std::size_t count = std::min(kChunk, bytes.size() - first);
    encode_groups(data + first, count, out.data() + start + first / 3 * 4);
  });
}

template <class Word>
Word read_word(const char* bytes) {
  Word word;
  std::memcpy(&word, bytes, sizeof(Word));
  return word;
}

std::uint64_t read_header_word(const char* bytes, std::size_t header_bytes) {
  return header_bytes == 8 ? read_word<std::uint64_t>(bytes) : read_word<std::uint32_t>(bytes);
}

/// The first `bytes` decoded bytes of base64 `text` (which must hold them): VTK's headers.
bool decode_prefix(std::string_view text, std::size_t bytes, std::string& out) {
  const std::size_t chars = encoded_size(bytes);
  if (chars > text.size()) return false;
  return decode_base64(text.substr(0, chars), out) && out.size() >= bytes;
}

}  // namespace

void append_base64(std::string_view bytes, std::string& out) { append_base64_parallel(bytes, out); }

bool decode_base64(std::string_view text, std::string& out) {
  out.clear();
  out.reserve(text.size() / 4 * 3);
  char quad[4];
  int have = 0;
  bool padded = false;  // a padded group ends the stream
  for (const char character : text) {
    if (character == ' ' || character == '\n' || character == '\r' || character == '\t') continue;
    if (padded) return false;
    quad[have++] = character;
    if (have < 4) continue;
    have = 0;
    int value[4];
    for (int k = 0; k < 4; ++k) {
      value[k] = quad[k] == '=' ? -2 : kDecode[static_cast<unsigned char>(quad[k])];
      if (value[k] == -1) return false;
    }
    if (value[0] < 0 || value[1] < 0 || (value[2] < 0 && value[3] >= 0)) return false;
    const int padding = (value[2] < 0) + (value[3] < 0);
    const std::uint32_t group = (std::uint32_t(value[0]) << 18) | (std::uint32_t(value[1]) << 12) |
                                (padding < 2 ? std::uint32_t(value[2]) << 6 : 0) | (padding < 1 ? std::uint32_t(value[3]) : 0);
    out.push_back(static_cast<char>(group >> 16));
    if (padding < 2) out.push_back(static_cast<char>((group >> 8) & 255));
    if (padding < 1) out.push_back(static_cast<char>(group & 255));
    padded = padding > 0;
  }
  return have == 0;
}

std::string encode_vtk_array(std::string_view bytes, int level, std::size_t block_bytes) {
  return std::move(encode_vtk_arrays(std::span(&bytes, 1), level, block_bytes).front());
}

std::vector<std::string> encode_vtk_arrays(std::span<const std::string_view> arrays, int level, std::size_t block_bytes) {
  std::vector<std::string> texts(arrays.size());
  if (level < 0) {
    // One stream per array: the byte count, then the bytes.
    for (std::size_t a = 0; a < arrays.size(); ++a) {
      const std::uint64_t count = arrays[a].size();
      std::string payload(sizeof(count) + count, '\0');
      std::memcpy(payload.data(), &count, sizeof(count));
      if (count > 0) std::memcpy(payload.data() + sizeof(count), arrays[a].data(), count);
      append_base64_parallel(payload, texts[a]);
    }
    return texts;
  }
  // Every block of every array, deflated in one loop.
  struct Block {
    std::size_t array, first, size;
    std::string compressed;
  };
  std::vector<Block> blocks;
  std::vector<std::size_t> first_block(arrays.size() + 1, 0);
  for (std::size_t a = 0; a < arrays.size(); ++a) {
    first_block[a] = blocks.size();
    for (std::size_t first = 0; first < arrays[a].size(); first += block_bytes)
      blocks.push_back({a, first, std::min(block_bytes, arrays[a].size() - first), {}});
  }
  first_block[arrays.size()] = blocks.size();
  // libdeflate writes the same zlib streams as zlib, about three times as fast; one compressor a thread.
  using Compressor = std::unique_ptr<libdeflate_compressor, decltype(&libdeflate_free_compressor)>;
  tbb::enumerable_thread_specific<Compressor> compressors(
      [&] { return Compressor(libdeflate_alloc_compressor(std::min(level, 12)), &libdeflate_free_compressor); });
  tbb::parallel_for(std::size_t(0), blocks.size(), [&](std::size_t b) {
    Block& block = blocks[b];
    libdeflate_compressor* compressor = compressors.local().get();
    if (!compressor) throw Error(fmt::format("libdeflate cannot make a compressor of level {}", level));
    block.compressed.resize(libdeflate_zlib_compress_bound(compressor, block.size));
    const std::size_t compressed_size = libdeflate_zlib_compress(compressor, arrays[block.array].data() + block.first, block.size,
                                                                 block.compressed.data(), block.compressed.size());
    if (compressed_size == 0) throw Error("libdeflate could not compress a block");
    block.compressed.resize(compressed_size);
  });
  tbb::parallel_for(std::size_t(0), arrays.size(), [&](std::size_t a) {
    // [blocks, block size, last block's size, compressed sizes...], then the blocks: each
    // encoded on its own.
    std::vector<std::uint64_t> header{first_block[a + 1] - first_block[a], block_bytes, arrays[a].size() % block_bytes};
    std::string joined;
    for (std::size_t b = first_block[a]; b < first_block[a + 1]; ++b) {
      header.push_back(blocks[b].compressed.size());
      joined += blocks[b].compressed;
    }
    append_base64_parallel({reinterpret_cast<const char*>(header.data()), header.size() * sizeof(std::uint64_t)}, texts[a]);
    append_base64_parallel(joined, texts[a]);
  });
  return texts;
}

bool decode_vtk_array(std::string_view data, const VtkPayloadFormat& format, std::string& out, std::string& error) {
  const std::size_t word = format.header_bytes;
  std::string header;
  if (!format.zlib) {
    if (!format.base64) {
      if (data.size() < word) return error = "the file ends inside an array's header", false;
      const std::uint64_t count = read_header_word(data.data(), word);
      if (count > data.size() - word) return error = "the file ends inside an array's data (truncated?)", false;
      out.assign(data.substr(word, count));
      return true;
    }
    if (!decode_prefix(data, word, header)) return error = "an array's base64 header is cut short or not base64", false;
    const std::uint64_t count = read_header_word(header.data(), word);
    if (count > data.size()) return error = "the file ends inside an array's data (truncated?)", false;
    if (!decode_prefix(data, word + count, out)) return error = "an array's base64 data is cut short or not base64", false;
    out.erase(0, word);
    out.resize(count);
    return true;
  }
  // Compressed: [blocks, block size, last block's size, compressed sizes...], then the blocks.
  std::uint64_t blocks = 0;
  std::string_view payload;
  if (format.base64) {
    if (!decode_prefix(data, 3 * word, header)) return error = "a compressed array's base64 header is cut short", false;
    blocks = read_header_word(header.data(), word);
    if (blocks > data.size()) return error = "a compressed array's header names more blocks than the file holds", false;
    const std::size_t header_size = (3 + blocks) * word;
    if (!decode_prefix(data, header_size, header)) return error = "a compressed array's base64 header is cut short", false;
    data.remove_prefix(encoded_size(header_size));
  } else {
    if (data.size() < 3 * word) return error = "the file ends inside a compressed array's header", false;
    blocks = read_header_word(data.data(), word);
    if (blocks > data.size()) return error = "a compressed array's header names more blocks than the file holds", false;
    const std::size_t header_size = (3 + blocks) * word;
    if (data.size() < header_size) return error = "the file ends inside a compressed array's header", false;
    header.assign(data.substr(0, header_size));
    data.remove_prefix(header_size);
  }
  const std::uint64_t block_size = read_header_word(header.data() + word, word);
  const std::uint64_t last_size = read_header_word(header.data() + 2 * word, word);
  std::uint64_t compressed_total = 0;
  for (std::uint64_t b = 0; b < blocks; ++b) {
    const std::uint64_t size = read_header_word(header.data() + (3 + b) * word, word);
    compressed_total += size;  // cannot wrap: each size is checked against the file's size
    if (size > data.size() || compressed_total > data.size())
      return error = "a compressed array's header names more compressed bytes than the file holds (truncated?)", false;
  }
  std::string decoded;
  if (format.base64) {
    if (!decode_prefix(data, compressed_total, decoded)) return error = "a compressed array's base64 data is cut short", false;
    payload = std::string_view(decoded).substr(0, compressed_total);
  } else {
    if (compressed_total > data.size()) return error = "the file ends inside a compressed array (truncated?)", false;
    payload = data.substr(0, compressed_total);
  }
  if (block_size == 0 && blocks > 0) return error = "a compressed array with a block size of 0", false;
  const std::uint64_t total = blocks == 0 ? 0 : (blocks - 1) * block_size + (last_size > 0 ? last_size : block_size);
  // Deflate expands at most 1032:1 (RFC 1951's longest match per shortest code), plus the zlib
  // header: a header that claims more cannot be right, so nothing that large is allocated.
  if (total > compressed_total * 1032 + blocks * 64)
    return error = fmt::format("a compressed array's header claims {} bytes from {} compressed bytes, more than zlib can inflate to",
                               total, compressed_total),
           false;
  out.assign(total, '\0');
  std::size_t read = 0;
  for (std::uint64_t b = 0; b < blocks; ++b) {
    const std::uint64_t size = read_header_word(header.data() + (3 + b) * word, word);
    uLongf expected = static_cast<uLongf>(b + 1 == blocks && last_size > 0 ? last_size : block_size);
    const uLongf wanted = expected;
    const int status = uncompress(reinterpret_cast<Bytef*>(out.data() + b * block_size), &expected,
                                  reinterpret_cast<const Bytef*>(payload.data() + read), static_cast<uLong>(size));
    if (status != Z_OK || expected != wanted)
      return error = fmt::format("block {} of {} of a compressed array does not inflate to its {} bytes", b + 1, blocks, wanted), false;
    read += size;
  }
  return true;
}

}  // namespace m3dp::io
