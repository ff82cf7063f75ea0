#include "io/summary.hpp"

#include "io/atomic_file.hpp"

#include <sys/resource.h>

#include <cstdio>
#include <stdexcept>

namespace tissue {

void write_json_atomically(const std::string& path, const nlohmann::json& summary) {
  // nlohmann writes doubles with 17 significant digits: they round-trip.
  write_file_atomically(path, summary.dump(2) + "\n");
}

long peak_memory_bytes() {
  struct rusage usage;
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_maxrss * 1024L;  // Linux reports kilobytes
}

}  // namespace tissue
