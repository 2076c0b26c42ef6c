#include "m3dp/record/mcap_writer.hpp"

#include <fmt/format.h>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <cstring>
#include <limits>

#include "m3dp/core/error.hpp"

namespace m3dp::record {

namespace {

constexpr std::string_view kMagic("\x89MCAP0\r\n", 8);
enum Opcode : std::uint8_t {
  header = 0x01, footer = 0x02, schema = 0x03, channel = 0x04, message = 0x05, chunk = 0x06, message_index = 0x07,
  chunk_index = 0x08, statistics = 0x0B, summary_offset = 0x0E, data_end = 0x0F,
};

// Little-endian fields as the spec lays them out.
template <typename T>
void put(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));  // x86 and ARM are little-endian
  out.append(bytes, sizeof(T));
}
void put_string(std::string& out, std::string_view text) {
  put(out, static_cast<std::uint32_t>(text.size()));
  out.append(text);
}
void put_record(std::string& out, Opcode opcode, std::string_view content) {
  put(out, static_cast<std::uint8_t>(opcode));
  put(out, static_cast<std::uint64_t>(content.size()));
  out.append(content);
}
std::uint32_t crc32_of(std::uint32_t crc, std::string_view bytes) {
  // zlib's crc32 takes uInt lengths: feed it in pieces.
  while (!bytes.empty()) {
    const std::size_t piece = std::min<std::size_t>(bytes.size(), std::numeric_limits<unsigned>::max());
    crc = static_cast<std::uint32_t>(::crc32(crc, reinterpret_cast<const Bytef*>(bytes.data()), static_cast<uInt>(piece)));
    bytes.remove_prefix(piece);
  }
  return crc;
}

}  // namespace

McapWriter::McapWriter(const std::filesystem::path& file, const McapOptions& options)
    : file_(file), stream_(file, std::ios::binary | std::ios::trunc), options_(options) {
  if (!stream_) throw Error(fmt::format("{}: cannot create the MCAP file", file.string()));
  std::string start(kMagic);
  std::string content;
  put_string(content, options_.profile);
  put_string(content, "m3dp");
  put_record(start, header, content);
  write_bytes(start);
}

McapWriter::~McapWriter() {
  try {
    close();
  } catch (...) {  // a destructor must not throw; close() reports errors to callers that call it
  }
}

void McapWriter::write_bytes(std::string_view bytes) {
  stream_.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!stream_) throw Error(fmt::format("{}: writing failed (disk full?)", file_.string()));
  data_crc_ = crc32_of(data_crc_, bytes);
  offset_ += bytes.size();
}

std::uint16_t McapWriter::add_schema(std::string_view name, std::string_view encoding, std::string_view data) {
  const auto id = static_cast<std::uint16_t>(++schema_count_);
  std::string content;
  put(content, id);
  put_string(content, name);
  put_string(content, encoding);
  put_string(content, data);
  std::string record;
  put_record(record, schema, content);
  // Outside any chunk, before the messages that need it: a streaming reader meets it first.
  write_bytes(record);
  schemas_ += record;
  return id;
}

std::uint16_t McapWriter::add_channel(std::string_view topic, std::string_view message_encoding, std::uint16_t schema_id,
                                      const std::map<std::string, std::string>& metadata) {
  const auto id = static_cast<std::uint16_t>(channel_count_++);
  std::string content;
  put(content, id);
  put(content, schema_id);
  put_string(content, topic);
  put_string(content, message_encoding);
  std::string pairs;
  for (const auto& [key, value] : metadata) {
    put_string(pairs, key);
    put_string(pairs, value);
  }
  put_string(content, pairs);
  std::string record;
  put_record(record, channel, content);
  write_bytes(record);
  channels_ += record;
  sequence_.push_back(0);
  channel_message_counts_[id] = 0;
  return id;
}

void McapWriter::write(std::uint16_t channel_id, std::uint64_t log_time, std::string_view data) {
  if (closed_) throw Error(fmt::format("{}: a message after the file was closed", file_.string()));
  if (channel_id >= channel_count_) throw Error(fmt::format("{}: no channel {}", file_.string(), channel_id));
  if (chunk_messages_.empty() && chunk_.empty()) chunk_start_time_ = chunk_end_time_ = log_time;
  chunk_start_time_ = std::min(chunk_start_time_, log_time);
  chunk_end_time_ = std::max(chunk_end_time_, log_time);
  chunk_messages_[channel_id].emplace_back(log_time, chunk_.size());
  put(chunk_, static_cast<std::uint8_t>(message));
  put(chunk_, static_cast<std::uint64_t>(2 + 4 + 8 + 8 + data.size()));
  put(chunk_, channel_id);
  put(chunk_, sequence_[channel_id]++);
  put(chunk_, log_time);
  put(chunk_, log_time);
  chunk_.append(data);
  if (message_count_ == 0) first_time_ = last_time_ = log_time;
  first_time_ = std::min(first_time_, log_time);
  last_time_ = std::max(last_time_, log_time);
  ++message_count_;
  ++channel_message_counts_[channel_id];
  if (chunk_.size() >= options_.chunk_bytes) close_chunk();
}

void McapWriter::close_chunk() {
  if (chunk_.empty()) return;
  const bool compress = options_.zstd_level > 0;
  std::string_view stored = chunk_;
  if (compress) {
    compressed_.resize(ZSTD_compressBound(chunk_.size()));
    const std::size_t size = ZSTD_compress(compressed_.data(), compressed_.size(), chunk_.data(), chunk_.size(), options_.zstd_level);
    if (ZSTD_isError(size)) throw Error(fmt::format("{}: zstd: {}", file_.string(), ZSTD_getErrorName(size)));
    stored = std::string_view(compressed_.data(), size);
  }
  std::string record;
  put(record, static_cast<std::uint8_t>(chunk));
  put(record, static_cast<std::uint64_t>(8 + 8 + 8 + 4 + 4 + (compress ? 4 : 0) + 8 + stored.size()));
  put(record, chunk_start_time_);
  put(record, chunk_end_time_);
  put(record, static_cast<std::uint64_t>(chunk_.size()));
  put(record, crc32_of(0, chunk_));
  put_string(record, compress ? "zstd" : "");
  put(record, static_cast<std::uint64_t>(stored.size()));
  ChunkIndex index{chunk_start_time_, chunk_end_time_, offset_, 0, 0, stored.size(), chunk_.size(), {}};
  write_bytes(record);
  write_bytes(stored);
  index.length = offset_ - index.offset;
  // One message index per channel in the chunk, right after it.
  const std::uint64_t indexes_start = offset_;
  std::string indexes;
  for (const auto& [channel_id, entries] : chunk_messages_) {
    index.message_index_offsets[channel_id] = indexes_start + indexes.size();
    std::string content;
    put(content, channel_id);
    put(content, static_cast<std::uint32_t>(entries.size() * 16));
    for (const auto& [time, offset] : entries) {
      put(content, time);
      put(content, offset);
    }
    put_record(indexes, message_index, content);
  }
  write_bytes(indexes);
  index.message_index_length = indexes.size();
  chunk_indexes_.push_back(std::move(index));
  stream_.flush();
  chunk_.clear();
  chunk_messages_.clear();
}

void McapWriter::flush() {
  close_chunk();
  stream_.flush();
}

void McapWriter::close() {
  if (closed_) return;
  closed_ = true;
  close_chunk();
  std::string end;
  std::string content;
  put(content, data_crc_);
  put_record(end, data_end, content);
  write_bytes(end);

  // The summary: schemas and channels again, statistics, chunk indexes; then where each group is.
  const std::uint64_t summary_start = offset_;
  std::string summary;
  struct Group {
    Opcode opcode;
    std::uint64_t start, length;
  };
  std::vector<Group> groups;
  auto add_group = [&](Opcode opcode, const std::string& records) {
    if (records.empty()) return;
    groups.push_back({opcode, summary_start + summary.size(), records.size()});
    summary += records;
  };
  add_group(schema, schemas_);
  add_group(channel, channels_);
  std::string stats;
  {
    std::string c;
    put(c, message_count_);
    put(c, schema_count_);
    put(c, static_cast<std::uint32_t>(channel_count_));
    put(c, std::uint32_t(0));  // attachments
    put(c, std::uint32_t(0));  // metadata
    put(c, static_cast<std::uint32_t>(chunk_indexes_.size()));
    put(c, first_time_);
    put(c, last_time_);
    std::string counts;
    for (const auto& [channel_id, count] : channel_message_counts_) {
      put(counts, channel_id);
      put(counts, count);
    }
    put_string(c, counts);
    put_record(stats, statistics, c);
  }
  add_group(statistics, stats);
  std::string chunk_index_records;
  for (const ChunkIndex& index : chunk_indexes_) {
    std::string c;
    put(c, index.start_time);
    put(c, index.end_time);
    put(c, index.offset);
    put(c, index.length);
    std::string offsets;
    for (const auto& [channel_id, offset] : index.message_index_offsets) {
      put(offsets, channel_id);
      put(offsets, offset);
    }
    put_string(c, offsets);
    put(c, index.message_index_length);
    put_string(c, options_.zstd_level > 0 ? "zstd" : "");
    put(c, index.compressed_size);
    put(c, index.uncompressed_size);
    put_record(chunk_index_records, chunk_index, c);
  }
  add_group(chunk_index, chunk_index_records);
  const std::uint64_t summary_offset_start = summary_start + summary.size();
  for (const Group& group : groups) {
    std::string c;
    put(c, static_cast<std::uint8_t>(group.opcode));
    put(c, group.start);
    put(c, group.length);
    put_record(summary, summary_offset, c);
  }
  // Footer: its CRC covers the summary and the footer up to the CRC itself.
  std::string tail = summary;
  put(tail, static_cast<std::uint8_t>(footer));
  put(tail, static_cast<std::uint64_t>(8 + 8 + 4));
  put(tail, summary.empty() ? std::uint64_t(0) : summary_start);
  put(tail, summary_offset_start);
  put(tail, crc32_of(0, tail));
  tail.append(kMagic);
  write_bytes(tail);
  stream_.close();
  if (!stream_) throw Error(fmt::format("{}: closing failed", file_.string()));
}

}  // namespace m3dp::record
