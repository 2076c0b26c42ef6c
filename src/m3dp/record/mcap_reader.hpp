#pragma once
// Reads an MCAP file (mcap.dev/spec) for replay (m3dp view): its schemas and channels, and an index
// of every message by log time, made once by reading the chunks through; a message's bytes are
// then read on demand, its chunk decompressed (zstd or none) and a few kept. A file without its
// summary (a run that was killed) is read up to its last whole record.
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace m3dp::record {

class McapReader {
 public:
  /// Opens `file` and indexes its messages; throws m3dp::Error naming the file and what is wrong.
  explicit McapReader(const std::filesystem::path& file);

  struct Channel {
    std::uint16_t id = 0;
    std::string topic, message_encoding;
    std::string schema_name, schema_encoding, schema_data;  // the schema's record (empty: none)
  };
  struct Message {
    std::uint64_t log_time = 0;  // ns
    std::uint16_t channel = 0;
    std::uint32_t chunk = 0;     // index into the chunks found
    std::uint64_t offset = 0;    // of its data in the decompressed chunk
    std::uint64_t length = 0;
  };

  [[nodiscard]] const std::vector<Channel>& channels() const { return channels_; }
  /// Every message in log-time order (file order among equal times).
  [[nodiscard]] const std::vector<Message>& messages() const { return messages_; }
  /// Whether the file ends with its summary and footer (a run that finished).
  [[nodiscard]] bool complete() const { return complete_; }
  [[nodiscard]] std::uint64_t start_time() const { return messages_.empty() ? 0 : messages_.front().log_time; }
  [[nodiscard]] std::uint64_t end_time() const { return messages_.empty() ? 0 : messages_.back().log_time; }
  /// A message's bytes, valid until the next call (its chunk is decompressed if not kept).
  std::string_view data(const Message& message);

 private:
  struct Chunk {
    std::uint64_t data_offset = 0, stored_size = 0, uncompressed_size = 0;
    bool zstd = false;
  };
  const std::string& chunk_bytes(std::uint32_t chunk);
  void read_chunk_records(std::uint32_t chunk, std::string_view records);

  std::filesystem::path file_;
  std::ifstream stream_;
  std::vector<Channel> channels_;
  std::map<std::uint16_t, std::size_t> channel_index_;    // id → channels_ index
  std::map<std::uint16_t, std::uint16_t> channel_schema_;  // channel id → schema id
  std::map<std::uint16_t, std::pair<std::string, std::pair<std::string, std::string>>> schemas_;  // id → name, encoding, data
  std::vector<Chunk> chunks_;
  std::vector<Message> messages_;
  bool complete_ = false;
  // The last chunks decompressed, most recent first.
  std::vector<std::pair<std::uint32_t, std::string>> kept_;
};

}  // namespace m3dp::record
