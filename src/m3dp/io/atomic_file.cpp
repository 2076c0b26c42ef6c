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

std::size_t remove_leftover_temporaries(const std::filesystem::path& folder) {
  std::size_t removed = 0;
  std::error_code error;
  for (auto it = std::filesystem::recursive_directory_iterator(folder, error); !error && it != std::filesystem::recursive_directory_iterator();
       it.increment(error)) {
    if (!it->is_regular_file(error)) continue;
    const std::string extension = it->path().extension().string();  // ".tmp12345"
    if (extension.size() > 4 && extension.starts_with(".tmp") &&
        extension.find_first_not_of("0123456789", 4) == std::string::npos) {
      std::filesystem::remove(it->path(), error);
      ++removed;
    }
  }
  return removed;
}

void write_text_atomically(const std::filesystem::path& target, const std::string& text) {
  write_file_atomically(target, [&](std::ostream& stream) { stream << text; });
}

}  // namespace m3dp::io
