#include "m3dp/io/atomic_file.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <system_error>

#include "m3dp/core/error.hpp"

namespace m3dp::io {

void write_file_atomically(const std::filesystem::path& target, const std::function<void(std::ostream&)>& write,
                           bool binary) {
  std::filesystem::path temporary = target;
  temporary += fmt::format(".tmp{}", static_cast<long>(getpid()));
  {
    std::ofstream stream(temporary, binary ? std::ios::out | std::ios::binary | std::ios::trunc : std::ios::out | std::ios::trunc);
    if (!stream) throw Error(fmt::format("cannot write {}: the folder is missing or not writable", temporary.string()));
    write(stream);
    stream.flush();
    if (!stream) {
      stream.close();
      std::filesystem::remove(temporary);
      throw Error(fmt::format("writing {} failed (disk full?)", target.string()));
    }
  }
  std::error_code error;
  std::filesystem::rename(temporary, target, error);
  if (error) {
    std::filesystem::remove(temporary);
    throw Error(fmt::format("cannot rename {} to {}: {}", temporary.string(), target.string(), error.message()));
  }
}

void write_text_atomically(const std::filesystem::path& target, const std::string& text) {
  write_file_atomically(target, [&](std::ostream& stream) { stream << text; });
}

}  // namespace m3dp::io
