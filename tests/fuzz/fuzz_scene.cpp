// libFuzzer target: the scene reader on arbitrary bytes. Any input must either parse into a Scene or throw one
// InputError whose message is a single line; anything else (a crash, another exception, a sanitizer report, a
// hang) is a bug. Built only with -DTISSUE_FUZZ=ON (clang, -fsanitize=fuzzer,address); see run_scripts/fuzz.sh.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "io/scene.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    tissue::Scene s = tissue::parse_scene(text, "fuzz.toml");
    // What was accepted must read back to the same scene (the checkpoint keeps Scene::text).
    tissue::Scene again = tissue::parse_scene(s.text, "fuzz.toml");
    if (again.text != s.text) {
      std::fprintf(stderr, "round trip changed the scene text\n--- first\n%s\n--- again\n%s\n", s.text.c_str(),
                   again.text.c_str());
      std::abort();
    }
  } catch (const tissue::InputError& e) {
    if (std::string(e.what()).find('\n') != std::string::npos) {
      std::fprintf(stderr, "InputError message is not one line: %s\n", e.what());
      std::abort();
    }
  }
  return 0;  // any other exception escapes and libFuzzer reports it as a crash
}
