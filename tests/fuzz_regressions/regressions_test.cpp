// Replays the fuzzing corpus in the normal (g++) build: every file in tests/fuzz_regressions/scene/ (and the
// seed scenes) fed to parse_scene, every file in .../scene_set/ as --set items on a valid scene, and every file
// in .../checkpoint/ to the checkpoint reader. Each must give a result or one one-line InputError: never a crash,
// a hang or another exception. A crash that run_scripts/fuzz.sh finds is copied here and stays a test.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "io/checkpoint.hpp"
#include "io/scene.hpp"

using namespace tissue;
namespace fs = std::filesystem;

namespace {

std::vector<fs::path> files_in(const std::string& sub) {
  std::vector<fs::path> out;
  fs::path dir = fs::path(TISSUE_SOURCE_DIR) / "tests" / "fuzz_regressions" / sub;
  if (!fs::is_directory(dir)) return out;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file() && e.path().filename().string()[0] != '.') out.push_back(e.path());
  std::sort(out.begin(), out.end());
  return out;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// "" when accepted, else the InputError's message; any other exception fails the test.
template <typename F>
std::string outcome(const fs::path& p, F f) {
  try {
    f();
  } catch (const InputError& e) {
    std::string msg = e.what();
    EXPECT_EQ(msg.find('\n'), std::string::npos) << p << ": not one line: " << msg;
    return msg;
  } catch (const std::exception& e) {
    ADD_FAILURE() << p << ": not an InputError: " << e.what();
  }
  return "";
}

}  // namespace

TEST(FuzzRegressions, Scenes) {
  auto files = files_in("scene");
  EXPECT_GE(files.size(), 5u);
  for (const auto& p : files) {
    const std::string text = slurp(p);
    outcome(p, [&] {
      Scene s = parse_scene(text, p.filename().string());
      Scene again = parse_scene(s.text, "again.toml");
      EXPECT_EQ(again.text, s.text) << p;
    });
  }
}

TEST(FuzzRegressions, SetOverrides) {
  const std::string base = "[body]\nmolecules = [3, 3, 3]\nspacing = [0.1, 0.1, 0.1]\nyoungs_modulus = 1e5\n"
                           "[[fix]]\nface = \"z+\"\n[[load]]\nface = \"z-\"\nforce = [0, 0, -1]\n";
  for (const auto& p : files_in("scene_set")) {
    std::vector<std::string> items;
    std::istringstream in(slurp(p));
    for (std::string line; std::getline(in, line) && items.size() < 16;) items.push_back(line);
    outcome(p, [&] { parse_scene(base, "base.toml", items); });
  }
}

TEST(FuzzRegressions, CheckpointHeaders) {
  auto files = files_in("checkpoint");
  EXPECT_GE(files.size(), 18u);
  for (const auto& p : files) {
    // The header must be refused (or read) cleanly; a refused header stops a restart before the state is read.
    // HDF5 first parses the file in a child process (io/isolated_parse.cpp): an input that crashes HDF5 (every
    // crash-* here did, in the ASan build of its day) kills that child, not this test.
    const std::string name = p.filename().string();
    const std::string msg = outcome(p, [&] { read_checkpoint_header(p.string(), PETSC_COMM_WORLD); });
    const bool refused = name.rfind("crash-", 0) == 0 || name.find("vlen") != std::string::npos ||
                         name.find("snapshot") != std::string::npos;
    if (refused) EXPECT_EQ(msg.rfind(p.string() + ": ", 0), 0u) << p << ": not refused with a line naming it: " << msg;
    if (name == "seed_sealed_checkpoint_3x3x3.h5") EXPECT_EQ(msg, "") << p << ": the current seed is refused";
  }
}
