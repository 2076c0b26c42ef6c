#pragma once
// Binary state for checkpoints: values, vectors and strings appended in the order a reader takes
// them back, with named sections so that a file from another version or a damaged one is an error
// that names the section, never a state read from the wrong bytes. Host byte order (a checkpoint
// continues a run on the machine that wrote it).
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "m3dp/core/error.hpp"

namespace m3dp {

template <class T>
concept PlainBytes = std::is_standard_layout_v<T> && !std::is_pointer_v<T> && std::is_copy_assignable_v<T>;

class StateWriter {
 public:
  /// A named section: the reader checks that it takes this one next.
  void section(std::string_view name) { put(std::string(name)); }
  template <PlainBytes T>
  void put(const T& value) {
    bytes_.append(reinterpret_cast<const char*>(&value), sizeof(T));
  }
  template <PlainBytes T>
  void put(const std::vector<T>& values) {
    put(static_cast<std::uint64_t>(values.size()));
    bytes_.append(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(T));
  }
  void put(const std::vector<bool>& values) {
    put(static_cast<std::uint64_t>(values.size()));
    for (const bool value : values) put(static_cast<std::uint8_t>(value));
  }
  void put(const std::string& text) {
    put(static_cast<std::uint64_t>(text.size()));
    bytes_.append(text);
  }
  void put(const char* text) { put(std::string(text)); }
  [[nodiscard]] const std::string& bytes() const { return bytes_; }

 private:
  std::string bytes_;
};

class StateReader {
 public:
  /// Reads `bytes`; errors name `source` (the checkpoint file).
  StateReader(std::string_view bytes, std::string source) : bytes_(bytes), source_(std::move(source)) {}

  void section(std::string_view name) {
    std::string found;
    get(found);
    if (found != name)
      throw InputError({source_, 0}, "not a checkpoint this version of m3dp can continue (section '" + std::string(name) +
                                         "' expected, '" + found.substr(0, 40) + "' found)");
  }
  template <PlainBytes T>
  void get(T& value) {
    take(&value, sizeof(T));
  }
  template <PlainBytes T>
  [[nodiscard]] T get() {
    T value{};
    get(value);
    return value;
  }
  template <PlainBytes T>
  void get(std::vector<T>& values) {
    const auto count = get<std::uint64_t>();
    if (count > remaining() / sizeof(T)) fail("a list longer than the file");
    values.resize(count);
    take(values.data(), count * sizeof(T));
  }
  void get(std::vector<bool>& values) {
    const auto count = get<std::uint64_t>();
    if (count > remaining()) fail("a list longer than the file");
    values.resize(count);
    for (std::size_t i = 0; i < count; ++i) values[i] = get<std::uint8_t>() != 0;
  }
  void get(std::string& text) {
    const auto count = get<std::uint64_t>();
    if (count > remaining()) fail("a text longer than the file");
    text.assign(bytes_.substr(offset_, count));
    offset_ += count;
  }
  [[nodiscard]] std::size_t remaining() const { return bytes_.size() - offset_; }
  [[nodiscard]] const std::string& source() const { return source_; }
  [[noreturn]] void fail(std::string_view what) const {
    throw InputError({source_, 0}, "damaged checkpoint: " + std::string(what) + " at byte " + std::to_string(offset_));
  }

 private:
  void take(void* destination, std::size_t count) {
    if (count > remaining()) fail("the file ends early");
    if (count == 0) return;  // an empty list's data() may be null, which memcpy must not get
    std::memcpy(destination, bytes_.data() + offset_, count);
    offset_ += count;
  }

  std::string_view bytes_;
  std::string source_;
  std::size_t offset_ = 0;
};

}  // namespace m3dp
