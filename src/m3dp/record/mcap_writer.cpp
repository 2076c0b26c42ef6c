#include "m3dp/record/mcap_writer.hpp"

#include <array>

#include <fmt/format.h>
#include <libdeflate.h>
#include <zstd.h>

#include <algorithm>
#include <cstring>
#include <limits>

#include "m3dp/core/error.hpp"
#include "m3dp/core/parallel.hpp"

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
/// The CRC-32 (ISO-HDLC, as MCAP and zlib) of `bytes` continuing `crc`: libdeflate's, several GB/s.
std::uint32_t crc32_of(std::uint32_t crc, std::string_view bytes) { return libdeflate_crc32(crc, bytes.data(), bytes.size()); }

/// Room for at least what zstd may give back in one call at the end of `out` (its size unchanged).
void reserve_for_zstd(std::string& out) {
  if (out.capacity() - out.size() < ZSTD_CStreamOutSize()) out.reserve(std::max(2 * out.capacity(), out.size() + ZSTD_CStreamOutSize()));
}

}  // namespace

struct McapWriter::ZstdContext {
  ZSTD_CCtx* context = ZSTD_createCCtx();
  ~ZstdContext() { ZSTD_freeCCtx(context); }
  /// Compresses `input` into the end of `out` (`end`: and closes the frame); throws with `file` named.
  void compress(std::string_view input, std::string& out, bool end, const std::filesystem::path& file) {
    ZSTD_inBuffer in{input.data(), input.size(), 0};
    for (std::size_t remaining = 1; in.pos < in.size || (end && remaining != 0);) {
      reserve_for_zstd(out);
      const std::size_t used = out.size();
      out.resize(out.capacity());
      ZSTD_outBuffer buffer{out.data(), out.size(), used};
      remaining = ZSTD_compressStream2(context, &buffer, &in, end ? ZSTD_e_end : ZSTD_e_continue);
      out.resize(buffer.pos);
      if (ZSTD_isError(remaining)) throw Error(fmt::format("{}: zstd: {}", file.string(), ZSTD_getErrorName(remaining)));
    }
  }
};

McapWriter::McapWriter(const std::filesystem::path& file, const McapOptions& options)
    : file_(file), stream_(file, std::ios::binary | std::ios::trunc), options_(options) {
  if (!stream_) throw Error(fmt::format("{}: cannot create the MCAP file", file.string()));
  start_compression();
  std::string start(kMagic);
  std::string content;
  put_string(content, options_.profile);
  put_string(content, "m3dp");
  put_record(start, header, content);
  write_bytes(start);
}

McapWriter::McapWriter(const std::filesystem::path& file, StateReader& saved, const McapOptions& options) : file_(file), options_(options) {
  saved.get(offset_);
  saved.get(data_crc_);
  saved.get(schemas_);
  saved.get(channels_);
  saved.get(schema_count_);
  saved.get(channel_count_);
  saved.get(sequence_);
  std::vector<std::pair<std::uint16_t, std::uint64_t>> counts;
  saved.get(counts);
  channel_message_counts_ = {counts.begin(), counts.end()};
  saved.get(message_count_);
  saved.get(first_time_);
  saved.get(last_time_);
  const auto chunks = saved.get<std::uint64_t>();
  if (chunks > saved.remaining()) saved.fail("more MCAP chunks than the file holds");
  chunk_indexes_.resize(chunks);
  for (ChunkIndex& chunk : chunk_indexes_) {
    const auto values = saved.get<std::array<std::uint64_t, 7>>();
    chunk.start_time = values[0], chunk.end_time = values[1], chunk.offset = values[2], chunk.length = values[3];
    chunk.message_index_length = values[4], chunk.compressed_size = values[5], chunk.uncompressed_size = values[6];
    std::vector<std::pair<std::uint16_t, std::uint64_t>> offsets;
    saved.get(offsets);
    chunk.message_index_offsets = {offsets.begin(), offsets.end()};
  }
  std::error_code error;
  const auto size = std::filesystem::file_size(file, error);
  if (error || size < offset_)
    throw InputError({file.string(), 0}, "shorter than when the checkpoint was written: the recording cannot be resumed");
  std::filesystem::resize_file(file, offset_);
  stream_.open(file, std::ios::binary | std::ios::in | std::ios::out);
  stream_.seekp(0, std::ios::end);
  if (!stream_) throw Error(fmt::format("{}: cannot reopen the MCAP file", file.string()));
  start_compression();
}

void McapWriter::save(StateWriter& out) {
  flush();
  out.put(offset_);
  out.put(data_crc_);
  out.put(schemas_);
  out.put(channels_);
  out.put(schema_count_);
  out.put(channel_count_);
  out.put(sequence_);
  out.put(std::vector<std::pair<std::uint16_t, std::uint64_t>>(channel_message_counts_.begin(), channel_message_counts_.end()));
  out.put(message_count_);
  out.put(first_time_);
  out.put(last_time_);
  out.put(static_cast<std::uint64_t>(chunk_indexes_.size()));
  for (const ChunkIndex& chunk : chunk_indexes_) {
    out.put(std::array<std::uint64_t, 7>{chunk.start_time, chunk.end_time, chunk.offset, chunk.length, chunk.message_index_length,
                                         chunk.compressed_size, chunk.uncompressed_size});
    out.put(std::vector<std::pair<std::uint16_t, std::uint64_t>>(chunk.message_index_offsets.begin(), chunk.message_index_offsets.end()));
  }
}

void McapWriter::start_compression() {
  if (options_.zstd_level > 0) {
    zstd_ = std::make_unique<ZstdContext>();
    ZSTD_CCtx_setParameter(zstd_->context, ZSTD_c_compressionLevel, options_.zstd_level);
    // Worker threads where libzstd has them (Debian's does); without, it compresses on this thread.
    const int threads = options_.zstd_threads > 0 ? options_.zstd_threads : ThreadLimit::active_threads();
    if (threads > 1) ZSTD_CCtx_setParameter(zstd_->context, ZSTD_c_nbWorkers, threads);
  }
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
  if (chunk_size_ == 0) chunk_start_time_ = chunk_end_time_ = log_time;
  chunk_start_time_ = std::min(chunk_start_time_, log_time);
  chunk_end_time_ = std::max(chunk_end_time_, log_time);
  chunk_messages_[channel_id].emplace_back(log_time, chunk_size_);
  std::string header;
  put(header, static_cast<std::uint8_t>(message));
  put(header, static_cast<std::uint64_t>(2 + 4 + 8 + 8 + data.size()));
  put(header, channel_id);
  put(header, sequence_[channel_id]++);
  put(header, log_time);
  put(header, log_time);
  add_to_chunk(header);
  add_to_chunk(data);
  if (message_count_ == 0) first_time_ = last_time_ = log_time;
  first_time_ = std::min(first_time_, log_time);
  last_time_ = std::max(last_time_, log_time);
  ++message_count_;
  ++channel_message_counts_[channel_id];
  if (chunk_size_ >= options_.chunk_bytes) close_chunk();
}

void McapWriter::add_to_chunk(std::string_view bytes) {
  chunk_crc_ = crc32_of(chunk_crc_, bytes);
  chunk_size_ += bytes.size();
  if (zstd_) zstd_->compress(bytes, chunk_, false, file_);
  else chunk_.append(bytes);
}

void McapWriter::close_chunk() {
  if (chunk_size_ == 0) return;
  if (zstd_) zstd_->compress({}, chunk_, true, file_);  // what zstd still holds, and the frame's end
  const std::string_view stored = chunk_;
  std::string record;
  put(record, static_cast<std::uint8_t>(chunk));
  put(record, static_cast<std::uint64_t>(8 + 8 + 8 + 4 + 4 + (zstd_ ? 4 : 0) + 8 + stored.size()));
  put(record, chunk_start_time_);
  put(record, chunk_end_time_);
  put(record, chunk_size_);
  put(record, chunk_crc_);
  put_string(record, zstd_ ? "zstd" : "");
  put(record, static_cast<std::uint64_t>(stored.size()));
  ChunkIndex index{chunk_start_time_, chunk_end_time_, offset_, 0, 0, stored.size(), chunk_size_, {}};
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
  chunk_size_ = 0;
  chunk_crc_ = 0;
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
    put_string(c, zstd_ ? "zstd" : "");
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
