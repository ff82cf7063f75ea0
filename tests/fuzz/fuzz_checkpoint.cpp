// libFuzzer target: the checkpoint reader on arbitrary bytes written to a temporary file. read_checkpoint_header
// and then read_checkpoint_state (against a fixed 3x3x3 model) must either succeed or throw InputError; a crash,
// another exception or a sanitizer report is a bug. MPI and PETSc are initialised once (one rank).
#include <petscsys.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

#include "io/checkpoint.hpp"
#include "io/scene.hpp"
#include "partition/local_model.hpp"
#include "partition/metis_partition.hpp"
#include "partition/natural_order.hpp"
#include "src/model/body.hpp"
#include "src/solvers/solver.hpp"

using namespace tissue;

namespace {
struct Fixture {
  Scene scene;
  LocalModel model;
  std::unique_ptr<NaturalOrder> molecules, connections;
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
  Body body = build_body(fx->scene);
  PartitionStats stats;
  std::vector<int> part = partition_molecules(body, PETSC_COMM_WORLD, stats);
  fx->model = distribute(body, part, stats, PETSC_COMM_WORLD);
  const LocalModel& m = fx->model;
  fx->molecules = std::make_unique<NaturalOrder>(
      m.comm, std::vector<std::int64_t>(m.id.begin(), m.id.begin() + m.owned), m.global_molecules);
  std::vector<std::int64_t> ids;
  for (int c : m.written_here) ids.push_back(m.connection_id[c]);
  fx->connections = std::make_unique<NaturalOrder>(m.comm, ids, m.global_connections);
  const char* tmp = std::getenv("TMPDIR");
  fx->path = std::string(tmp ? tmp : "/tmp") + "/fuzz_checkpoint_" + std::to_string(::getpid()) + ".h5";
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
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
