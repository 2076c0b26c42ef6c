#pragma once
// An MCAP file (mcap.dev/spec, version 0) written as the run goes: schemas and channels as they are
// added, messages into chunks compressed with zstd, each chunk followed by its message indexes and
// flushed when it is full, so a killed run leaves a file readable up to its last chunk. close() adds
// the data-end CRC and the summary (schemas, channels, statistics, chunk indexes, summary offsets)
// that indexed readers seek with. Messages stream into the compressor as they come (a chunk is
// never copied uncompressed), on zstd's own threads.
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "m3dp/core/state_io.hpp"

namespace m3dp::record {

struct McapOptions {
  std::size_t chunk_bytes = 4 << 20;  // uncompressed bytes at which a chunk is closed
  int zstd_level = 1;                 // 1 fastest … 19; 0 stores chunks uncompressed
  int zstd_threads = 0;               // zstd's compression threads (0: as many as the run's threads)
  std::string profile = {};           // the Header's profile ("" = none)
};

class McapWriter {
 public:
  /// Creates `file` (its folder must exist) and writes the magic and the header. Throws m3dp::Error.
  McapWriter(const std::filesystem::path& file, const McapOptions& options = {});
  /// Goes on with `file` from a checkpoint (save()): cut back to its length then, and appended to, so
  /// that the recording ends as if the run had never stopped. Throws InputError if it is shorter.
  McapWriter(const std::filesystem::path& file, StateReader& saved, const McapOptions& options = {});
  ~McapWriter();  // closes the file if close() was not called
  McapWriter(const McapWriter&) = delete;
  McapWriter& operator=(const McapWriter&) = delete;

  /// A schema: its name ("foxglove.PointCloud"), encoding ("protobuf") and data (a FileDescriptorSet).
  std::uint16_t add_schema(std::string_view name, std::string_view encoding, std::string_view data);
  /// A channel: its topic, message encoding and schema (0: none).
  std::uint16_t add_channel(std::string_view topic, std::string_view message_encoding, std::uint16_t schema,
                            const std::map<std::string, std::string>& metadata = {});
  /// A message on a channel, at `log_time` ns (published then too).
  void write(std::uint16_t channel, std::uint64_t log_time, std::string_view data);
  /// Writes the open chunk out now (e.g. at the end of a frame a viewer should see if the run dies).
  void flush();
  /// Closes the open chunk and writes data end, summary and footer. Further calls do nothing.
  void close();
  /// A checkpoint: flushes, then saves how far the file got and what its summary will list.
  void save(StateWriter& out);

  [[nodiscard]] std::uint64_t message_count() const { return message_count_; }
  [[nodiscard]] std::uint64_t bytes_written() const { return offset_; }
  [[nodiscard]] std::uint32_t chunk_count() const { return static_cast<std::uint32_t>(chunk_indexes_.size()); }

 private:
  void start_compression();
  void write_bytes(std::string_view bytes);
  void add_to_chunk(std::string_view bytes);  // uncompressed bytes of the open chunk's records
  void close_chunk();

  struct ChunkIndex {
    std::uint64_t start_time, end_time, offset, length, message_index_length, compressed_size, uncompressed_size;
    std::map<std::uint16_t, std::uint64_t> message_index_offsets;
  };

  std::filesystem::path file_;
  std::ofstream stream_;
  McapOptions options_;
  bool closed_ = false;
  std::uint64_t offset_ = 0;       // bytes written so far
  std::uint32_t data_crc_ = 0;     // CRC32 of every byte written before the data end record
  std::string schemas_, channels_; // their records again, for the summary
  std::uint16_t schema_count_ = 0, channel_count_ = 0;
  std::vector<std::uint32_t> sequence_;  // per channel
  std::map<std::uint16_t, std::uint64_t> channel_message_counts_;
  std::uint64_t message_count_ = 0, first_time_ = 0, last_time_ = 0;
  // The open chunk: its records as stored (compressed as they come, or as they are), their
  // uncompressed size and CRC, each channel's (log time, offset) pairs, its times.
  std::string chunk_;
  std::uint64_t chunk_size_ = 0;
  std::uint32_t chunk_crc_ = 0;
  std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> chunk_messages_;
  std::uint64_t chunk_start_time_ = 0, chunk_end_time_ = 0;
  std::vector<ChunkIndex> chunk_indexes_;
  struct ZstdContext;
  std::unique_ptr<ZstdContext> zstd_;  // null: chunks stored uncompressed
};

}  // namespace m3dp::record
