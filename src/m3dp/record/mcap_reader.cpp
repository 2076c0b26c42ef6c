#include "m3dp/record/mcap_reader.hpp"

#include <fmt/format.h>
#include <zstd.h>

#include <algorithm>
#include <cstring>

#include "m3dp/core/error.hpp"

namespace m3dp::record {

namespace {

constexpr std::string_view kMagic("\x89MCAP0\r\n", 8);
constexpr std::uint8_t kSchema = 0x03, kChannel = 0x04, kMessage = 0x05, kChunk = 0x06, kDataEnd = 0x0F, kFooter = 0x02;
constexpr std::size_t kKeptChunks = 4;

/// Little-endian fields, read from the front of `bytes` (throws when it is too short).
struct Cursor {
  std::string_view bytes;
  const std::filesystem::path* file;
  template <typename T>
  T take() {
    if (bytes.size() < sizeof(T)) throw Error(fmt::format("{}: an MCAP record ends early", file->string()));
    T value;
    std::memcpy(&value, bytes.data(), sizeof(T));
    bytes.remove_prefix(sizeof(T));
    return value;
  }
  std::string_view take_bytes(std::size_t count) {
    if (bytes.size() < count) throw Error(fmt::format("{}: an MCAP record ends early", file->string()));
    const std::string_view taken = bytes.substr(0, count);
    bytes.remove_prefix(count);
    return taken;
  }
  std::string take_string() { return std::string(take_bytes(take<std::uint32_t>())); }
};

}  // namespace

McapReader::McapReader(const std::filesystem::path& file) : file_(file), stream_(file, std::ios::binary) {
  if (!stream_) throw Error(fmt::format("{}: cannot open it", file.string()));
  stream_.seekg(0, std::ios::end);
  const auto size = static_cast<std::uint64_t>(stream_.tellg());
  stream_.seekg(0);
  std::string magic(kMagic.size(), '\0');
  stream_.read(magic.data(), static_cast<std::streamsize>(magic.size()));
  if (!stream_ || magic != kMagic) throw Error(fmt::format("{}: not an MCAP file (no MCAP magic at its start)", file.string()));

  // The data section record by record; a record cut short (a killed run) ends it.
  std::uint64_t offset = kMagic.size();
  std::string content;
  while (offset + 9 <= size) {
    char head[9];
    stream_.seekg(static_cast<std::streamoff>(offset));
    stream_.read(head, 9);
    const auto opcode = static_cast<std::uint8_t>(head[0]);
    std::uint64_t length;
    std::memcpy(&length, head + 1, 8);
    if (length > size - offset - 9) break;
    const std::uint64_t content_offset = offset + 9;
    offset = content_offset + length;
    if (opcode == kDataEnd) {
      complete_ = true;
      break;
    }
    if (opcode == kFooter) break;
    if (opcode != kSchema && opcode != kChannel && opcode != kMessage && opcode != kChunk) continue;
    content.resize(length);
    stream_.read(content.data(), static_cast<std::streamsize>(length));
    if (!stream_) throw Error(fmt::format("{}: reading it failed", file.string()));
    if (opcode == kChunk) {
      Cursor cursor{content, &file_};
      cursor.take<std::uint64_t>();  // start and end time
      cursor.take<std::uint64_t>();
      Chunk chunk;
      chunk.uncompressed_size = cursor.take<std::uint64_t>();
      cursor.take<std::uint32_t>();  // uncompressed CRC
      const std::string compression = cursor.take_string();
      if (compression != "zstd" && !compression.empty())
        throw Error(fmt::format("{}: chunk compression '{}' is not supported (zstd or none)", file.string(), compression));
      chunk.zstd = compression == "zstd";
      chunk.stored_size = cursor.take<std::uint64_t>();
      chunk.data_offset = content_offset + (length - cursor.bytes.size());
      chunks_.push_back(chunk);
      read_chunk_records(static_cast<std::uint32_t>(chunks_.size() - 1), chunk_bytes(static_cast<std::uint32_t>(chunks_.size() - 1)));
    } else if (opcode == kMessage) {
      // A message outside any chunk: its own stored region.
      chunks_.push_back(Chunk{content_offset - 9, length + 9, length + 9, false});
      read_chunk_records(static_cast<std::uint32_t>(chunks_.size() - 1), chunk_bytes(static_cast<std::uint32_t>(chunks_.size() - 1)));
    } else {
      std::string record(1, static_cast<char>(opcode));
      record.append(reinterpret_cast<const char*>(&length), 8);
      record += content;
      read_chunk_records(~0u, record);
    }
  }
  std::stable_sort(messages_.begin(), messages_.end(), [](const Message& a, const Message& b) { return a.log_time < b.log_time; });
  // Each channel with its schema's name and data (a schema may come after its channel in a chunk).
  for (auto& channel : channels_) {
    const auto schema = schemas_.find(channel_schema_[channel.id]);
    if (schema == schemas_.end()) continue;
    channel.schema_name = schema->second.first;
    channel.schema_encoding = schema->second.second.first;
    channel.schema_data = schema->second.second.second;
  }
}

void McapReader::read_chunk_records(std::uint32_t chunk, std::string_view records) {
  Cursor cursor{records, &file_};
  while (cursor.bytes.size() >= 9) {
    const auto record_start = static_cast<std::uint64_t>(records.size() - cursor.bytes.size());
    const auto opcode = cursor.take<std::uint8_t>();
    const auto length = cursor.take<std::uint64_t>();
    Cursor content{cursor.take_bytes(length), &file_};
    if (opcode == kSchema) {
      const auto id = content.take<std::uint16_t>();
      std::string name = content.take_string(), encoding = content.take_string(), data = content.take_string();
      schemas_[id] = {std::move(name), {std::move(encoding), std::move(data)}};
    } else if (opcode == kChannel) {
      Channel channel;
      channel.id = content.take<std::uint16_t>();
      const auto schema = content.take<std::uint16_t>();
      channel.topic = content.take_string();
      channel.message_encoding = content.take_string();
      channel_schema_[channel.id] = schema;
      if (!channel_index_.contains(channel.id)) {
        channel_index_[channel.id] = channels_.size();
        channels_.push_back(std::move(channel));
      }
    } else if (opcode == kMessage && chunk != ~0u) {
      Message message;
      message.channel = content.take<std::uint16_t>();
      content.take<std::uint32_t>();  // sequence
      message.log_time = content.take<std::uint64_t>();
      content.take<std::uint64_t>();  // publish time
      message.chunk = chunk;
      message.offset = record_start + 9 + 2 + 4 + 8 + 8;
      message.length = content.bytes.size();
      messages_.push_back(message);
    }
  }
}

const std::string& McapReader::chunk_bytes(std::uint32_t index) {
  for (std::size_t k = 0; k < kept_.size(); ++k)
    if (kept_[k].first == index) {
      std::rotate(kept_.begin(), kept_.begin() + static_cast<std::ptrdiff_t>(k), kept_.begin() + static_cast<std::ptrdiff_t>(k) + 1);
      return kept_.front().second;
    }
  const Chunk& chunk = chunks_.at(index);
  std::string stored(chunk.stored_size, '\0');
  stream_.clear();
  stream_.seekg(static_cast<std::streamoff>(chunk.data_offset));
  stream_.read(stored.data(), static_cast<std::streamsize>(stored.size()));
  if (!stream_) throw Error(fmt::format("{}: reading a chunk failed", file_.string()));
  std::string bytes;
  if (chunk.zstd) {
    bytes.resize(chunk.uncompressed_size);
    const std::size_t size = ZSTD_decompress(bytes.data(), bytes.size(), stored.data(), stored.size());
    if (ZSTD_isError(size) || size != bytes.size())
      throw Error(fmt::format("{}: a chunk does not decompress: {}", file_.string(), ZSTD_isError(size) ? ZSTD_getErrorName(size) : "wrong size"));
  } else {
    bytes = std::move(stored);
  }
  kept_.insert(kept_.begin(), {index, std::move(bytes)});
  if (kept_.size() > kKeptChunks) kept_.pop_back();
  return kept_.front().second;
}

std::string_view McapReader::data(const Message& message) {
  const std::string& bytes = chunk_bytes(message.chunk);
  if (message.offset + message.length > bytes.size()) throw Error(fmt::format("{}: a message reaches past its chunk", file_.string()));
  return std::string_view(bytes).substr(message.offset, message.length);
}

}  // namespace m3dp::record
