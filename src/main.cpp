//                         tissue: virtual tissue samples, calibrated to a Young's modulus
//
// Solves the molecular model of Maciel, Boulic & Thalmann: spherical mass regions (molecules) joined by
// spring-like connections whose stiffness is set (calibrated) from the tissue's Young's modulus, then loaded as
// the scene says and brought to equilibrium (static, relaxation) or integrated in time (dynamic). A tension
// test reports the body's measured modulus, Eq. 3: E = F l0 / (dl A).
//
// Sample runs:
//   build/tissue run run_scripts/scenes/table2.toml
//   mpirun -np 2 build/tissue run run_scripts/scenes/table2.toml --set calibration.method=divided \
//          --set calibration.divisor=3.75 --output out/divided
//   mpirun -np 2 build/tissue run run_scripts/scenes/table2.toml --set solver.kind=relaxation
//   build/tissue run run_scripts/scenes/table2.toml -- -ksp_type gmres -pc_type hypre -snes_monitor -log_view
//   build/tissue info out/table2/final.h5
//   mpirun -np 2 build/tissue fit run_scripts/scenes/fit_creep.toml --output out/fit   (src/driver/fit.hpp)
//
// Exit codes: 0 success, 2 bad input (one line naming file and key; a bad output location too), 3 the solver
// failed or a file could not be written (one line naming the file and the system error).

#include <malloc.h>
#include <unistd.h>
#include <petscsys.h>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <hdf5.h>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "io/atomic_file.hpp"
#include "io/checkpoint.hpp"
#include "io/fit_input.hpp"
#include "io/gmsh_mesh.hpp"
#include "io/hdf5_file.hpp"
#include "io/output.hpp"
#include "io/output_location.hpp"
#include "io/scene.hpp"
#include "partition/agreement.hpp"
#include "src/driver/fit.hpp"
#include "src/driver/simulation.hpp"
#include "src/model/cell_law.hpp"
#include "src/solvers/petsc_errors.hpp"
#include "src/solvers/tissue_options.hpp"

using namespace tissue;

namespace {

int rank_of(MPI_Comm comm) {
  int r;
  MPI_Comm_rank(comm, &r);
  return r;
}

// A restart may change how long a run goes and what it writes, never the model.
void check_restart_overrides(const std::vector<std::string>& overrides) {
  for (const auto& o : overrides) {
    const std::string key = o.substr(0, o.find('='));
    const bool allowed = key == "solver.steps" || key == "solver.max_iterations" || key.rfind("output.", 0) == 0;
    if (!allowed)
      throw InputError("--set", key, "a restart may change solver.steps, solver.max_iterations and output.*, "
                                     "not the model");
  }
}

void on_signal(int) { stop_requested = 1; }

// The pipeline's stages as PETSc log stages: -log_view then gives each its time, flops and messages (what the
// set-up costs beside the solve; docs/benchmarks.md). Registered once (a fit runs many scenes); free otherwise.
class LogStage {
public:
  explicit LogStage(const char* name) {
    static std::vector<std::pair<std::string, PetscLogStage>> known;
    PetscLogStage stage = -1;
    for (const auto& [n, s] : known)
      if (n == name) stage = s;
    if (stage < 0 && PetscLogStageRegister(name, &stage) == 0) known.emplace_back(name, stage);
    pushed_ = stage >= 0 && PetscLogStagePush(stage) == 0;
  }
  ~LogStage() {
    if (pushed_) (void)PetscLogStagePop();
  }
  LogStage(const LogStage&) = delete;
  LogStage& operator=(const LogStage&) = delete;

private:
  bool pushed_ = false;
};

// A static solve (and each step of a quasi-static one) frees and makes again its 12-35 MB work arrays between
// the stages (set-up, Newton, finish): with them in the heap up to 64 MB, the pages are reused, and the heap is one
// region on huge pages (src/huge_pages.cpp), while a mapping of its own gets them only on its 2 MB-aligned
// interior: its two ends, 2 MB on average, are first-touched on 4 kB pages (512 faults for a 12 MB vector). The
// explicit and relaxation solvers allocate once; for them the heap's holes only raise the peak: 8 MB.
void set_mmap_threshold(const Scene& scene) {
  const bool static_solve = scene.solver.kind == "static" || scene.solver.kind == "quasi-static";
  if (!static_solve || mallopt(M_MMAP_THRESHOLD, 64 << 20) == 0) mallopt(M_MMAP_THRESHOLD, 8 << 20);
}

// Runs one scene end to end, from its start or from a checkpoint. Returns the exit code. A fit's forward runs
// give the scene as text (`scene_text`, named scene_path in messages) and run `quiet` (no lines but failures).
int run(const std::string& scene_path, const std::string& checkpoint, const std::vector<std::string>& overrides,
        const std::string& output, const std::string& scene_text = "", bool quiet = false) {
  const MPI_Comm comm = PETSC_COMM_WORLD;
  const bool root = rank_of(comm) == 0;
  const auto start = std::chrono::steady_clock::now();
  // Batch schedulers warn with SIGTERM before the time limit: from here on a signal means "checkpoint at the
  // next step boundary and stop" (set-up included: the flag waits for the first boundary).
  std::signal(SIGTERM, on_signal);
  std::signal(SIGINT, on_signal);

  // 1. Read the scene (every rank reads the same file; a bad one stops every rank with the same line). A
  //    restart reads the scene text the checkpoint carries.
  Scene scene;
  if (!scene_text.empty()) {
    scene = parse_scene(scene_text, scene_path, overrides);
  } else if (checkpoint.empty()) {
    scene = read_scene(scene_path, overrides);
  } else {
    check_restart_overrides(overrides);
    // Agreed (partition/agreement.hpp): a file one rank cannot read stops every rank with the same line.
    CheckpointHeader header = agree(comm, [&] { return read_checkpoint_header(checkpoint, comm); });
    scene = parse_scene(header.scene_text, checkpoint, overrides);
    int ranks;
    MPI_Comm_size(comm, &ranks);
    if (root)
      std::printf("tissue: restarting \"%s\" at step %ld (written by %d ranks) on %d ranks\n",
                   header.title.c_str(), header.step, header.ranks, ranks);
  }
  // Every rank read the scene itself: the same text on every rank, or bad input (a shared file system that shows
  // the nodes different versions of the file, or a launcher that gave the ranks different arguments).
  {
    std::uint64_t digest = 1469598103934665603ull;  // FNV-1a of the scene text after --set
    for (const char c : scene.text) digest = (digest ^ static_cast<unsigned char>(c)) * 1099511628211ull;
    std::uint64_t low = 0, high = 0;
    MPI_Allreduce(&digest, &low, 1, MPI_UINT64_T, MPI_MIN, comm);
    MPI_Allreduce(&digest, &high, 1, MPI_UINT64_T, MPI_MAX, comm);
    if (low != high)
      throw InputError(checkpoint.empty() ? scene_path : checkpoint, "",
                       "the ranks read different scenes (the file differs between nodes, or the ranks were given "
                       "different --set or files)");
  }
  if (!output.empty()) scene.output.directory = output;
  // A restart goes on where its checkpoint is, whatever directory the scene names (the run may have had --output,
  // or been started from another directory): `tissue restart DIR/checkpoint_S.h5` continues DIR.
  else if (!checkpoint.empty())
    scene.output.directory = std::filesystem::path(checkpoint).parent_path().empty()
                                 ? std::string(".")
                                 : std::filesystem::path(checkpoint).parent_path().string();
  if (quiet) scene.output.progress = false;
  // The output location is input: checked before any work (exists or can be created, a directory, writable by
  // every rank, room for the first file), so that a bad one is exit 2 in a second, not after the solve.
  check_output_location(scene, comm);
  set_mmap_threshold(scene);
  Simulation sim(std::move(scene), comm);

  // 2-3. Build this rank's share of the bodies: METIS partitions the connection graph; each rank keeps its
  //      molecules, their ghosts and their connections, with material and mass per molecule. Box lattices are
  //      generated rank by rank from the topology's stencil: no rank holds the whole body. Mesh files are read
  //      by io's reader (io/gmsh_mesh.hpp).
  {
    LogStage stage("Build model");
    sim.build(read_mesh);
  }
  const LocalModel& model = sim.model();
  if (root && !quiet)
    std::printf("tissue: %lld molecules, %lld connections on %d ranks; edge cut %ld, imbalance %.3f, "
                         "ghosts/owned %.3f\n",
                 static_cast<long long>(model.global_molecules), static_cast<long long>(model.global_connections),
                 model.size, model.partition.edge_cut, model.partition.imbalance,
                 model.partition.surface_to_volume);

  // 4. Calibrate: a stiffness per connection from the material (one method per file), each body by its own
  //    method (Scene::calibrations). A k that no longer changes is stored by connection type: 2 bytes a
  //    connection instead of 16, and less memory traffic in the force kernel; what only calibration reads goes.
  {
    LogStage stage("Calibrate");
    sim.calibrate();
  }

  // 5. The force model: the connection forces plus only the terms the scene lists; loads and holds.
  {
    LogStage stage("Force model");
    sim.make_forces();
  }
  if (root && !quiet) {
    std::printf("tissue: critical time step %.6e s\n", sim.critical_time_step());
    std::fflush(stdout);
  }

  // 6. Solve, writing snapshots and checkpoints as the scene asks; a restart loads its state first. A method
  //    that follows the deformation (angles-update) refreshes k during the solve; one that wraps the solver
  //    (iterative) runs it.
  Output out(sim.scene(), model);
  if (!checkpoint.empty())
    agree(comm, [&] {
      read_checkpoint_state(checkpoint, model, out.molecule_rows(), out.connection_rows(), sim.state(),
                            /*check_stiffness=*/!sim.refresh(), &sim.forces());
      out.continue_history(sim.state().step);
    });
  SolverHooks hooks;
  hooks.snapshot = [&](const SolverState& s) { out.snapshot(s, sim.forces()); };
  std::string last_checkpoint;
  hooks.checkpoint = [&](const SolverState& s) {
    last_checkpoint = out.checkpoint(s, &sim.forces());
    sim.write_checkpoint_summary(out, s, last_checkpoint,
                                 std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  };
  hooks.record = [&](const SolverState& s) { out.history_row(s, sim.forces(), sim.test()); };
  {
    LogStage stage("Solve");
    sim.solve(hooks);
  }
  const SolveReport& report = sim.report();
  if (report.interrupted && root)
    std::fprintf(stderr, "tissue: stop requested (SIGTERM/SIGINT): checkpoint written at step %ld; continue "
                         "with: tissue restart %s\n", sim.state().step, last_checkpoint.c_str());

  // 7. Measure: Eq. 3, Poisson ratio, centre of mass, kinetic energy.
  {
    LogStage stage("Measure");
    sim.measure();
  }

  // 8. Write the final state (unless it is not finite) and summary.json.
  {
    LogStage stage("Write");
    sim.write(out, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  }
  if (root && !quiet) {
    const Scene& sc = sim.scene();
    const TensionTest& test = sim.test();
    const Measurements& measured = sim.measured();
    const double target = test.valid ? youngs_modulus_along(sc.bodies[test.body], test.axis) : 0.0;
    if (test.valid && measured.youngs_modulus)
      std::printf("%s\n  E target %.6g Pa, measured %.6g Pa, error %+.4f %%; elongation %.6e m; %s %ld iterations, "
                  "residual %.2e\n",
                  sc.title.c_str(), target, *measured.youngs_modulus,
                  100.0 * (*measured.youngs_modulus - target) / target,
                  *measured.elongation, kind_name(report), report.iterations, report.residual);
    else
      std::printf("%s\n  %s: %ld steps, kinetic energy %.6e J\n", sc.title.c_str(), kind_name(report),
                  report.iterations, measured.kinetic_energy);
    if (sim.failed()) std::fprintf(stderr, "tissue: %s\n", sim.failure().c_str());
  }
  return sim.failed() ? 3 : 0;
}

// `tissue fit`: the scene of the experiment plus [fit] (io/fit_input.hpp), fitted by src/driver/fit.hpp. Writes
// DIR/fit.json, DIR/fitted.toml and, in DIR itself, the run of the fitted scene (history.csv, summary.json).
// "elongation", or "elongation, lateral_strain" for several y columns (the progress line).
std::string join_names(const std::vector<std::string>& names) {
  std::string out;
  for (const auto& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}

int fit(const std::string& fit_path, const std::vector<std::string>& overrides, const std::string& output) {
  const MPI_Comm comm = PETSC_COMM_WORLD;
  const bool root = rank_of(comm) == 0;
  const auto start = std::chrono::steady_clock::now();
  // 1. The [fit] table, the measured curve and the scene, checked before any forward run (bad input: exit 2).
  FitInput input = agree(comm, [&] { return read_fit_input(fit_path, overrides); });
  Scene scene = parse_scene(input.scene_text, fit_path);
  if (!output.empty()) scene.output.directory = output;
  check_output_location(scene, comm);
  const std::string dir = scene.output.directory;
  if (root)
    std::printf("tissue fit: %zu parameters to the %zu points of %s (%s against %s)\n", input.parameters.size(),
                input.data_x.size(), input.data_path.c_str(), join_names(input.y).c_str(), input.x.c_str());

  // 2. Forward runs, each the ordinary run on every rank, into DIR/forward; the optimizer (TAO POUNDERS).
  ForwardRun forward = [&](const std::vector<std::string>& set, const std::string& directory) {
    try {
      return run(fit_path, "", set, directory, input.scene_text, /*quiet=*/true);
    } catch (const InputError&) {
      return 2;
    } catch (const std::exception&) {
      return 3;
    }
  };
  const FitResult r = fit_parameters(input, forward, dir + "/forward", comm, scene.output.progress);

  // 3. The fitted scene, runnable as is, and its run in DIR; fit.json.
  const int last = run(fit_path, "", fit_overrides(input, r.values), dir, input.scene_text, /*quiet=*/true);
  nlohmann::json j;
  j["parameters"] = nlohmann::json::object();
  j["standard_errors"] = nlohmann::json::object();
  j["on_bound"] = nlohmann::json::object();
  auto number = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  for (std::size_t i = 0; i < input.parameters.size(); ++i) {
    const std::string& key = input.parameters[i].key;
    j["parameters"][key] = r.values[i];
    j["standard_errors"][key] = number(r.standard_errors[i]);
    j["on_bound"][key] = static_cast<bool>(r.on_bound[i]);
    j["bounds"][key] = {input.parameters[i].lower, input.parameters[i].upper};
    j["start"][key] = input.parameters[i].start;
  }
  nlohmann::json corr = nlohmann::json::array();
  for (const auto& row : r.correlation) {
    nlohmann::json line = nlohmann::json::array();
    for (double v : row) line.push_back(number(v));
    corr.push_back(line);
  }
  j["correlation"] = corr;
  j["residual_norm"] = r.residual_norm;
  j["points"] = r.residuals;
  j["forward_runs"] = r.forward_runs;
  j["failed_runs"] = r.failed_runs;
  j["converged"] = r.converged;
  j["reason"] = r.reason;
  j["identifiable"] = r.identifiable;
  j["notes"] = r.notes;
  j["data"] = input.data_path;
  j["x"] = input.x;
  j["y"] = input.y.size() == 1 ? nlohmann::json(input.y[0]) : nlohmann::json(input.y);
  for (std::size_t k = 0; k < input.y.size(); ++k) j["residual_norms"][input.y[k]] = r.column_norms[k];
  j["fitted_run_exit_code"] = last;
  j["wall_seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  agree(comm, [&] {
    if (!root) return;
    write_file_atomically(dir + "/fitted.toml", fitted_scene_text(input, r.values));
    write_file_atomically(dir + "/fit.json", j.dump(2) + "\n");
    std::error_code ec;
    std::filesystem::remove_all(dir + "/forward", ec);  // the last forward run: a finite-difference probe
  });
  if (root) {
    std::printf("tissue fit: %s after %ld forward runs (%ld failed); |r| = %.6e over %ld points\n",
                r.converged ? "converged" : "stopped", r.forward_runs, r.failed_runs, r.residual_norm, r.residuals);
    for (std::size_t i = 0; i < input.parameters.size(); ++i)
      std::printf("  %s = %.8g +- %.3g%s\n", input.parameters[i].key.c_str(), r.values[i], r.standard_errors[i],
                  r.on_bound[i] ? " (on a bound)" : "");
    if (!r.notes.empty()) std::printf("  notes: %s\n", r.notes.c_str());
    std::printf("  wrote %s/fit.json, %s/fitted.toml\n", dir.c_str(), dir.c_str());
  }
  return last == 0 ? 0 : 3;
}

// PETSc ignores options it does not know: a typo after -- (-ksp_typ gmres) would go unnoticed. After the run,
// rank 0 names every option nothing has read (a warning, not an error: which options are read depends on the
// solver kind, and relaxation and dynamic runs read none). Options read only by PetscFinalize are skipped.
void warn_unused_petsc_options(int code) {
  if (code == 2) return;  // bad input: the one line already said what is wrong
  PetscInt n = 0;
  char **names = nullptr, **values = nullptr;
  if (PetscOptionsLeftGet(nullptr, &n, &names, &values)) return;
  const bool root = rank_of(PETSC_COMM_WORLD) == 0;
  for (PetscInt i = 0; i < n; ++i) {
    const std::string name = names[i];
    bool finalize_only = false;
    for (const char* f : {"options_left", "malloc_dump", "memory_view", "objects_dump", "log_view", "malloc_debug"})
      finalize_only = finalize_only || name == f;
    if (root && !finalize_only)
      std::fprintf(stderr, "tissue: warning: PETSc option -%s was never used (misspelt? PETSc options act on the "
                           "static solver only)\n", names[i]);
  }
  PetscOptionsLeftRestore(nullptr, &n, &names, &values);
}

}  // namespace

int main(int argc, char** argv) {
  // PETSc options follow "--": they go to PETSc untouched, the rest to our command line.
  std::vector<char*> ours{argv[0]}, petsc{argv[0]};
  bool after = false;
  for (int i = 1; i < argc; ++i) {
    if (!after && std::string(argv[i]) == "--") { after = true; continue; }
    (after ? petsc : ours).push_back(argv[i]);
  }

  CLI::App app{"tissue: molecular model of biological soft tissue, calibrated to a Young's modulus.\n"
               "PETSc options follow --, e.g. tissue run s.toml -- -ksp_type gmres -log_view"};
  app.require_subcommand(1);
  app.set_version_flag("--version", [] {
    return fmt::format("tissue {} (PETSc {}.{}.{}, HDF5 {}.{}.{}, Gmsh {})", TISSUE_VERSION, PETSC_VERSION_MAJOR,
                       PETSC_VERSION_MINOR, PETSC_VERSION_SUBMINOR, H5_VERS_MAJOR, H5_VERS_MINOR, H5_VERS_RELEASE,
                       gmsh_library_version());
  });
  std::string scene_path, checkpoint_path, info_path, output;
  std::vector<std::string> overrides;
  // (given, --output names a directory: "" would fall back to the scene's without a word)
  const CLI::Validator directory_name(
      [](std::string& d) { return d.empty() ? std::string("an empty directory name") : std::string(); },
      "DIR");
  auto* run_cmd = app.add_subcommand("run", "run a scene");
  run_cmd->add_option("scene", scene_path, "scene file (TOML)")->required();
  run_cmd->add_option("--set", overrides, "override a scene key: --set body.molecules=[20,20,20]");
  run_cmd->add_option("--output", output, "output directory (default: the scene's output.directory)")
      ->check(directory_name);
  auto* restart_cmd = app.add_subcommand("restart", "continue a run from its checkpoint, on any number of ranks");
  restart_cmd->add_option("checkpoint", checkpoint_path, "checkpoint file (HDF5)")->required();
  restart_cmd->add_option("--set", overrides, "change solver.steps, solver.max_iterations or output.*");
  restart_cmd->add_option("--output", output, "output directory (default: the checkpoint's directory)")
      ->check(directory_name);
  auto* fit_cmd = app.add_subcommand("fit", "fit material parameters so that the scene reproduces a measured curve");
  fit_cmd->add_option("fit", scene_path, "the scene plus a [fit] table (TOML)")->required();
  fit_cmd->add_option("--set", overrides, "override a key of FIT.toml");
  fit_cmd->add_option("--output", output, "output directory (default: the scene's output.directory)")
      ->check(directory_name);
  auto* info_cmd = app.add_subcommand("info", "say what a snapshot or checkpoint holds");
  info_cmd->add_option("file", info_path, "HDF5 file")->required();
  // Bad input before MPI is up: one line, from one rank (the launcher's rank variable tells).
  auto refuse = [](const std::string& line) {
    const char* rank = std::getenv("OMPI_COMM_WORLD_RANK");
    if (!rank) rank = std::getenv("PMI_RANK");
    if (!rank || std::string(rank) == "0") std::fprintf(stderr, "tissue: %s\n", line.c_str());
    return 2;
  };
  try {
    app.parse(static_cast<int>(ours.size()), ours.data());
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);  // --help
    return refuse(std::string("command line: ") + e.what() + " (see tissue --help)");
  }
  // PETSc reads -options_file in PetscInitialize, where a file it cannot read ends the job with a traceback.
  for (std::size_t i = 1; i + 1 < petsc.size(); ++i)
    if (std::string(petsc[i]) == "-options_file" || std::string(petsc[i]) == "-options_file_yaml") {
      std::error_code ec;
      if (!std::filesystem::is_regular_file(petsc[i + 1], ec) || access(petsc[i + 1], R_OK) != 0)
        return refuse(std::string("PETSc options: ") + petsc[i] + ": cannot read \"" + petsc[i + 1] + "\"");
    }

  // argv ends in a null pointer, as main's does: MPI walks it to the end (Open MPI's MPI_Init crashed without).
  int petsc_argc = static_cast<int>(petsc.size());
  petsc.push_back(nullptr);
  char** petsc_argv = petsc.data();
  PetscCall(PetscInitialize(&petsc_argc, &petsc_argv, nullptr, nullptr));
  install_petsc_error_handler();  // PETSc's errors end in our one line, on every rank alike
  {
    std::string given = std::getenv("PETSC_OPTIONS") ? std::getenv("PETSC_OPTIONS") : "";
    for (std::size_t i = 1; i + 1 < petsc.size(); ++i) given += (given.empty() ? "" : " ") + std::string(petsc[i]);
    remember_user_options(given);
  }
  // Large arrays (model set-up temporaries, tens of MB) in their own mappings, so freeing one gives its memory
  // back at once: in the heap, freed pages stay resident and raise the peak. Arrays up to 8 MB stay in the heap:
  // those freed and allocated again between the stages (vectors, per-molecule arrays) then reuse pages already
  // touched instead of faulting and zeroing fresh ones. Set after MPI start-up, which resets them; a static solve
  // raises the threshold (set_mmap_threshold). docs/benchmarks.md.
  mallopt(M_MMAP_MAX, 1 << 16);
  mallopt(M_MMAP_THRESHOLD, 8 << 20);
  const bool root = rank_of(PETSC_COMM_WORLD) == 0;
  int code = 0;
  try {
    // The whole command is one agreed stage (partition/agreement.hpp): its own stages agree as they go, and a
    // failure anywhere else on one rank still reaches every rank, or ends the job (MPI_Abort), never a hang.
    code = agree(PETSC_COMM_WORLD, [&] {
      if (*run_cmd || *restart_cmd || *fit_cmd) check_tissue_options();  // bad -static_* / -tissue_*: exit 2
      if (*run_cmd) return run(scene_path, "", overrides, output);
      if (*restart_cmd) return run("", checkpoint_path, overrides, output);
      if (*info_cmd) return info(info_path, PETSC_COMM_WORLD);
      if (*fit_cmd) return fit(scene_path, overrides, output);
      return 0;
    });
  } catch (const InputError& e) {
    if (root) std::fprintf(stderr, "%s\n", e.what());
    code = 2;
  } catch (const std::exception& e) {
    if (root) std::fprintf(stderr, "tissue: %s\n", e.what());
    code = 3;
  }
  if (hdf5_files_abandoned()) {
    // A write failed and left HDF5 holding a file it cannot close (io/hdf5_file.hpp): finalizing would hang in
    // its collectives. Every rank is here (the failure was agreed): the one line is out, end without finalizing.
    std::fflush(stdout);
    std::fflush(stderr);
    MPI_Barrier(PETSC_COMM_WORLD);
    std::_Exit(code);
  }
  warn_unused_petsc_options(code);
  PetscCall(PetscFinalize());
  return code;
}
