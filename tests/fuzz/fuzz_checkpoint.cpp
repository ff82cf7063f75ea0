// libFuzzer target: the checkpoint reader on arbitrary bytes written to a temporary file. read_checkpoint_header
// and then read_checkpoint_state (against a fixed 3x3x3 model) must either succeed or throw InputError; a crash,
// another exception or a sanitizer report is a bug. MPI and PETSc are initialised once (one rank).
//
// Every file tissue writes is sealed (io/hdf5_file.cpp: size + hash in a 512-byte user block, checked before HDF5
// parses anything), so a mutated file is refused at the seal and the default run explores the seal check only. With
// TISSUE_FUZZ_RESEAL=1 the target writes a fresh seal over the input's first 512 bytes before reading it, so that
// the mutations reach HDF5 and the checkpoint reader behind the seal (what a hand-crafted, validly sealed file could
// do). HDF5 1.10 itself still crashes on some corrupt metadata, so the reader first parses the file's metadata in a
// child process (io/isolated_parse.cpp, the same path as `tissue restart`): an input that crashes HDF5 there kills
// the child (its ASan report is printed, and libFuzzer's death callback, inherited, saves the input as crash-*) and
// comes back here as an InputError. What fails the run is a crash of this process: HDF5 crashing on metadata that
// the child walked without harm, or any bug of ours.
#include <petscsys.h>
#include <unistd.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "io/checkpoint.hpp"
#include "io/gmsh_mesh.hpp"
#include "io/row_stream.hpp"
#include "io/scene.hpp"
#include "partition/local_model.hpp"
#include "partition/metis_partition.hpp"
#include "src/model/body.hpp"
#include "src/solvers/solver.hpp"

using namespace tissue;

namespace {
struct Fixture {
  Scene scene;
  LocalModel model;
  std::unique_ptr<RowStream> molecules, connections;
  std::string path;
};
Fixture* fx = nullptr;

const char* scene_text = R"(title = "fuzz"
[body]
molecules = [3, 3, 3]
spacing = [0.1, 0.1, 0.1]
youngs_modulus = 1e5
[[fix]]
face = "z+"
[[load]]
face = "z-"
force = [0, 0, -1]
)";
}  // namespace

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
  // PETSc's own SEGV handler would hide the sanitizer's report: off.
  int pargc = 2;
  char* name = (*argv)[0];
  char no_handler[] = "-no_signal_handler";
  char* args[] = {name, no_handler, nullptr};
  char** pargv = args;
  if (PetscInitialize(&pargc, &pargv, nullptr, nullptr)) std::abort();
  fx = new Fixture;
  fx->scene = parse_scene(scene_text, "fuzz.toml");
  CalibrationInputs inputs;  // the fixture never calibrates
  fx->model = build_local_model(fx->scene, PETSC_COMM_WORLD, inputs, read_mesh);
  const LocalModel& m = fx->model;
  // The streams a run reads its checkpoint over (Output::molecule_rows, connection_rows).
  fx->molecules = std::make_unique<RowStream>(m.comm, m.global_molecules, m.owned,
                                              [&m](std::int64_t k) { return m.id[k]; });
  fx->connections = std::make_unique<RowStream>(m.comm, m.global_connections, m.connections(), [&m](std::int64_t c) {
    return m.end_a[c] < m.owned ? m.connection_id(static_cast<int>(c)) : std::int64_t{-1};
  });
  const char* tmp = std::getenv("TMPDIR");
  fx->path = std::string(tmp ? tmp : "/tmp") + "/fuzz_checkpoint_" + std::to_string(::getpid()) + ".h5";
  return 0;
}

namespace {
// The seal of io/hdf5_file.cpp, computed in memory: FNV-1a over 1 MiB blocks after the 512-byte user block, each
// block's hash started with its offset, summed.
std::vector<std::uint8_t> resealed(const std::uint8_t* data, std::size_t size) {
  const std::size_t user_block = 512, block = 1 << 20;
  std::vector<std::uint8_t> out(data, data + size);
  if (out.size() < user_block) out.resize(user_block, 0);
  std::uint64_t sum = 0;
  for (std::size_t offset = user_block; offset < out.size(); offset += block) {
    const std::size_t n = std::min(block, out.size() - offset);
    std::uint64_t h = 1469598103934665603ULL;
    for (int i = 0; i < 8; ++i) h = (h ^ ((static_cast<std::uint64_t>(offset) >> (8 * i)) & 0xff)) * 1099511628211ULL;
    for (std::size_t i = 0; i < n; ++i) h = (h ^ out[offset + i]) * 1099511628211ULL;
    sum += h;
  }
  char header[512] = {0};
  std::snprintf(header, sizeof header, "TISSUE-HDF5-SEAL 1 %llu %016llx\n", static_cast<unsigned long long>(out.size()),
                static_cast<unsigned long long>(sum));
  std::copy(header, header + user_block, out.begin());
  return out;
}
const bool reseal = [] {
  const char* v = std::getenv("TISSUE_FUZZ_RESEAL");
  return v && *v && std::string(v) != "0";
}();
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::vector<std::uint8_t> sealed;
  if (reseal) {
    sealed = resealed(data, size);
    data = sealed.data();
    size = sealed.size();
  }
  FILE* f = std::fopen(fx->path.c_str(), "wb");
  if (!f) std::abort();
  if (size) std::fwrite(data, 1, size, f);
  std::fclose(f);
  try {
    CheckpointHeader h = read_checkpoint_header(fx->path, PETSC_COMM_WORLD);
    SolverState state(fx->model);
    read_checkpoint_state(fx->path, fx->model, *fx->molecules, *fx->connections, state);
  } catch (const InputError& e) {
    if (std::string(e.what()).find('\n') != std::string::npos) {
      std::fprintf(stderr, "InputError message is not one line: %s\n", e.what());
      std::abort();
    }
  }
  std::remove(fx->path.c_str());
  return 0;
}
