// libFuzzer target: --set overrides on a valid scene. The input is split at newlines into KEY=VALUE items (as
// `tissue run scene.toml --set ITEM ...` would pass them); each run must give a Scene or one one-line InputError.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "io/scene.hpp"

namespace {
const char* base = R"(title = "fuzz base"
[body]
molecules = [3, 3, 3]
spacing = [0.1, 0.1, 0.1]
youngs_modulus = 1e5
[[body.region]]
lo = [0, 0, 0]
hi = [0.1, 0.1, 0.1]
youngs_modulus = 1e6
[[fix]]
face = "z+"
[[load]]
face = "z-"
force = [0, 0, -1]
[solver]
kind = "dynamic"
steps = 10
[output]
directory = "out/fuzz"
)";
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::vector<std::string> items;
  std::string cur;
  for (std::size_t i = 0; i < size && items.size() < 16; ++i) {
    if (data[i] == '\n') items.push_back(cur), cur.clear();
    else cur += static_cast<char>(data[i]);
  }
  if (!cur.empty() && items.size() < 16) items.push_back(cur);
  try {
    tissue::Scene s = tissue::parse_scene(base, "base.toml", items);
    tissue::Scene again = tissue::parse_scene(s.text, "base.toml");
    if (again.text != s.text) {
      std::fprintf(stderr, "round trip changed the scene text\n");
      std::abort();
    }
  } catch (const tissue::InputError& e) {
    if (std::string(e.what()).find('\n') != std::string::npos) {
      std::fprintf(stderr, "InputError message is not one line: %s\n", e.what());
      std::abort();
    }
  }
  return 0;
}
