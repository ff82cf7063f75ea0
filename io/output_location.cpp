#include "io/output_location.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "partition/agreement.hpp"
#include "src/model/topology.hpp"
#include "src/solvers/solver.hpp"

namespace tissue {

namespace {

// Connections per molecule (each counted once) of an interior molecule: half its topology's stencil (which holds
// both signs of every offset); a random cloud or a mesh about 7, as a Delaunay tetrahedralization has.
double connections_per_molecule(const std::string& topology) {
  if (const TopologyStyle* lattice = find_topology(topology)) return 0.5 * static_cast<double>(lattice->stencil.size());
  return 7;
}

std::string megabytes(double bytes) {
  char s[32];
  std::snprintf(s, sizeof s, "%.1f MB", bytes / 1e6);
  return s;
}

}  // namespace

OutputEstimate estimate_output(const Scene& scene) {
  OutputEstimate e;
  double connections = 0;
  for (const BodySpec& b : scene.bodies.empty() ? std::vector<BodySpec>{scene.body} : scene.bodies) {
    const bool mesh = b.shape == BodySpec::Shape::mesh;
    std::int64_t n = mesh ? b.interior_molecules : b.molecules[0] * b.molecules[1] * b.molecules[2];
    if (b.random && !mesh) n = std::max<std::int64_t>(n, b.interior_molecules);
    e.molecules += n;
    connections += connections_per_molecule(b.topology) * static_cast<double>(n);
  }
  e.connections = static_cast<std::int64_t>(connections);
  // A snapshot: 24 bytes per molecule and field, the endpoints (16 bytes) and 8 per connection field; HDF5's
  // metadata and the seal block are a few kB.
  const auto& fields = scene.output.fields;
  auto has = [&](const char* f) { return std::find(fields.begin(), fields.end(), f) != fields.end(); };
  std::int64_t per_molecule = 24;  // positions are always written
  for (const char* f : {"displacements", "velocities", "forces"}) per_molecule += has(f) ? 24 : 0;
  std::int64_t per_connection = 16;
  for (const char* f : {"connection_strain", "connection_force"}) per_connection += has(f) ? 8 : 0;
  const std::int64_t overhead = 16384 + static_cast<std::int64_t>(scene.text.size());
  e.snapshot_bytes = fields.empty() ? 0 : per_molecule * e.molecules + per_connection * e.connections + overhead;
  e.checkpoint_bytes = 48 * e.molecules + 32 * e.connections + overhead;
  const bool checkpoints = scene.output.checkpoint_every > 0;
  e.first_bytes = std::max(e.snapshot_bytes, checkpoints ? e.checkpoint_bytes : 0);
  std::int64_t snapshots = 1;  // final.h5
  const SolverStyle* kind = find_solver(scene.solver.kind);  // steps with snapshots: a time line
  if (scene.output.snapshot_every > 0 && kind && kind->time_line)
    snapshots += scene.solver.steps / scene.output.snapshot_every + 1;
  // Two checkpoints are kept, and a third is written before the oldest goes.
  e.run_bytes = snapshots * e.snapshot_bytes + (checkpoints ? 3 * e.checkpoint_bytes : 0) + 65536;
  return e;
}

void check_output_location(const Scene& scene, MPI_Comm comm) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  const std::string dir = scene.output.directory;
  auto refuse = [&](const std::string& problem) {
    throw InputError(scene.file, "output.directory", "\"" + dir + "\": " + problem);
  };
  std::vector<std::string> created;  // rank 0: the directories made here, outermost first
  auto remove_created = [&] {
    for (auto it = created.rbegin(); it != created.rend(); ++it) ::rmdir(it->c_str());
    created.clear();
  };
  try {
    // 1. Rank 0 creates the directory (and its parents) or finds it.
    agree(comm, [&] {
      if (rank != 0) return;
      std::string partial;
      for (std::size_t i = 0; i <= dir.size(); ++i) {
        if ((i == dir.size() || dir[i] == '/') && !partial.empty()) {
          struct stat st;
          if (::stat(partial.c_str(), &st) == 0) {
            if (!S_ISDIR(st.st_mode))
              refuse(partial == dir ? "exists and is not a directory" : partial + " is not a directory");
          } else if (::mkdir(partial.c_str(), 0755) == 0) {
            created.push_back(partial);
          } else if (errno != EEXIST) {
            refuse("cannot create directory " + partial + ": " + std::strerror(errno));
          }
        }
        if (i < dir.size()) partial += dir[i];
      }
    });
    // 2. Every rank writes a probe file there: created, written, synced, renamed, removed.
    agree(comm, [&] {
      const std::string base = dir + "/.tissue-probe-" + std::to_string(rank) + "-" + std::to_string(::getpid());
      const std::string tmp = base + ".tmp";
      const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
      if (fd < 0) refuse("rank " + std::to_string(rank) + " cannot create a file in it: " + std::strerror(errno));
      char block[512] = "tissue output probe\n";
      const bool wrote = ::write(fd, block, sizeof block) == static_cast<ssize_t>(sizeof block);
      int err = errno;
      const bool synced = wrote && ::fsync(fd) == 0;
      if (wrote && !synced) err = errno;
      ::close(fd);
      if (!wrote || !synced) {
        ::unlink(tmp.c_str());
        refuse("rank " + std::to_string(rank) + " cannot " + (wrote ? "fsync" : "write") + " a file in it: " +
               std::strerror(err ? err : EIO));
      }
      if (std::rename(tmp.c_str(), base.c_str()) != 0) {
        err = errno;
        ::unlink(tmp.c_str());
        refuse("rank " + std::to_string(rank) + " cannot rename a file in it: " + std::strerror(err));
      }
      ::unlink(base.c_str());
    });
    // 3. Room for the first file (error), and for the whole run (warning).
    agree(comm, [&] {
      if (rank != 0) return;
      struct statvfs fs;
      if (::statvfs(dir.c_str(), &fs) != 0) return;  // unknown: the writes will tell
      const double free_bytes = static_cast<double>(fs.f_bavail) * static_cast<double>(fs.f_frsize);
      const OutputEstimate e = estimate_output(scene);
      const bool checkpoint_first = e.checkpoint_bytes > e.snapshot_bytes && scene.output.checkpoint_every > 0;
      if (free_bytes < static_cast<double>(e.first_bytes))
        refuse("has " + megabytes(free_bytes) + " free; the first " + (checkpoint_first ? "checkpoint" : "snapshot") +
               " needs about " + megabytes(static_cast<double>(e.first_bytes)) + " (" +
               std::to_string(e.molecules) + " molecules, about " + std::to_string(e.connections) + " connections)");
      if (free_bytes < static_cast<double>(e.run_bytes))
        std::fprintf(stderr, "tissue: warning: output.directory \"%s\" has %s free; this run's output needs about %s "
                     "(it will stop with exit 3 when the disk is full)\n",
                     dir.c_str(), megabytes(free_bytes).c_str(), megabytes(static_cast<double>(e.run_bytes)).c_str());
    });
  } catch (...) {
    remove_created();
    throw;
  }
  remove_created();
}

}  // namespace tissue
