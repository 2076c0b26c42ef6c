#pragma once
// A table the run appends a row to each step (timing.csv, hashes.csv): written as NAME.partial and
// renamed to NAME when the run ends, so that a file under the real name is always whole. A
// checkpoint keeps its length; a resumed run cuts it back there and appends again.
#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>

#include "m3dp/core/error.hpp"
#include "m3dp/core/state_io.hpp"

namespace m3dp::sim::outputs {

class PartialTextFile {
 public:
  explicit PartialTextFile(std::filesystem::path final_file)
      : final_(std::move(final_file)), partial_(final_.string() + ".partial") {}
  ~PartialTextFile() {
    if (file_) std::fclose(file_);
  }
  PartialTextFile(const PartialTextFile&) = delete;
  PartialTextFile& operator=(const PartialTextFile&) = delete;

  /// A new file with its header.
  void create(std::string_view header) {
    open("w");
    std::fwrite(header.data(), 1, header.size(), file_);
  }
  /// Its length so far, all of it on disk.
  void save(StateWriter& out) {
    if (std::fflush(file_) != 0) throw Error("cannot write " + partial_.string());
    out.put(static_cast<std::uint64_t>(std::ftell(file_)));
  }
  /// Back to the length save() kept (a run that ended renamed it: it becomes partial again).
  void resume(StateReader& in) {
    const auto length = in.get<std::uint64_t>();
    if (!std::filesystem::exists(partial_) && std::filesystem::exists(final_)) std::filesystem::rename(final_, partial_);
    std::error_code error;
    if (!std::filesystem::exists(partial_) || std::filesystem::file_size(partial_) < length)
      throw InputError({partial_.string(), 0}, "shorter than when the checkpoint was written: the run cannot be resumed");
    std::filesystem::resize_file(partial_, length);
    open("a");
  }
  [[nodiscard]] std::FILE* get() const { return file_; }
  /// Closes it and gives it its real name.
  void finish() {
    if (!file_) return;
    std::fclose(file_);
    file_ = nullptr;
    std::filesystem::rename(partial_, final_);
  }

 private:
  void open(const char* mode) {
    file_ = std::fopen(partial_.c_str(), mode);
    if (!file_) throw Error("cannot write " + partial_.string());
  }

  std::filesystem::path final_, partial_;
  std::FILE* file_ = nullptr;
};

}  // namespace m3dp::sim::outputs
