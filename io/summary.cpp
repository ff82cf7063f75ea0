#include "io/summary.hpp"

#include <sys/resource.h>

#include <cstdio>
#include <fstream>
#include <stdexcept>

namespace tissue {

void write_json_atomically(const std::string& path, const nlohmann::json& summary) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp);
    if (!out) throw std::runtime_error(tmp + ": cannot open for writing");
    out << summary.dump(2) << "\n";  // nlohmann writes doubles with 17 significant digits: they round-trip
    out.flush();
    if (!out) throw std::runtime_error(tmp + ": write failed");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) throw std::runtime_error(path + ": rename failed");
}

long peak_memory_bytes() {
  struct rusage usage;
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_maxrss * 1024L;  // Linux reports kilobytes
}

}  // namespace tissue
