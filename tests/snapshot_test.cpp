// Snapshots: a 4 x 3 x 2 lattice owned in a scrambled pattern is written through NaturalOrder as two frames plus
// their XDMF index, then read back with io/hdf5_file and compared with the closed forms below (which
// tests/snapshot_readers_test.py repeats in python, reading the same files with h5py and meshio).
//
// Files go to $TISSUE_SNAPSHOT_DIR if set, else to the build tree's tests/out; names carry the rank count so
// that ctest can run the 1, 2 and 3 rank variants at once. snapshot_readers_test.py runs only
// Snapshot.WritesLatticeSeries, into a directory of its own.
#include <gtest/gtest.h>
#include <mpi.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <stdexcept>

#include "io/hdf5_file.hpp"
#include "io/snapshot.hpp"
#include "io/xdmf.hpp"
#include "partition/natural_order.hpp"

#ifndef TISSUE_TEST_OUT_DIR
#define TISSUE_TEST_OUT_DIR "tests/out"
#endif

using namespace tissue;
namespace fs = std::filesystem;

namespace {

constexpr int NX = 4, NY = 3, NZ = 2;
constexpr int64_t N = NX * NY * NZ;              // 24 molecules
constexpr int64_t C = (NX - 1) * NY * NZ;        // 18 connections, along x
const int64_t STEPS[2] = {0, 10};
const double TIMES[2] = {0.0, 0.5};

// ---- the closed forms (mirrored in snapshot_readers_test.py) ----
int64_t molecule_id(int i, int j, int k) { return i + NX * (j + NY * k); }
double lattice(int64_t id, int c) {
  const int64_t ijk[3] = {id % NX, (id / NX) % NY, id / (NX * NY)};
  const double h[3] = {0.1, 0.2, 0.3};
  return h[c] * ijk[c];
}
double displacement(int64_t id, int c, int64_t step) { return 1e-3 * (step + 1) * (id + 1) * (c + 1); }
double position(int64_t id, int c, int64_t step) { return lattice(id, c) + displacement(id, c, step); }
double velocity(int64_t id, int c, int64_t step) { return (step + 1) * (-static_cast<double>(id) + 0.5 * c); }
// Connection cid joins (i, j, k) and (i + 1, j, k), with cid = i + (NX - 1) * (j + NY * k).
int64_t endpoint(int64_t cid, int e) {
  const int64_t i = cid % (NX - 1), j = (cid / (NX - 1)) % NY, k = cid / ((NX - 1) * NY);
  return molecule_id(static_cast<int>(i), static_cast<int>(j), static_cast<int>(k)) + e;
}
double strain(int64_t cid, int64_t step) { return 0.01 * cid * (step + 1); }
double connection_force(int64_t cid, int64_t step) { return 100.0 + cid + step; }

int comm_rank() {
  int r = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &r);
  return r;
}
int comm_size() {
  int s = 1;
  MPI_Comm_size(MPI_COMM_WORLD, &s);
  return s;
}

std::string out_dir() {
  const char* env = std::getenv("TISSUE_SNAPSHOT_DIR");
  const std::string dir = env && *env ? env : TISSUE_TEST_OUT_DIR;
  if (comm_rank() == 0) fs::create_directories(dir);
  MPI_Barrier(MPI_COMM_WORLD);
  return dir;
}

// Remove a previous run's output, so that every existence check below is about this run.
std::string fresh(const std::string& path) {
  if (comm_rank() == 0) {
    fs::remove(path);
    fs::remove(path + ".tmp");
  }
  MPI_Barrier(MPI_COMM_WORLD);
  return path;
}

std::string prefix() { return "snapshot_np" + std::to_string(comm_size()); }

// Scrambled ownership: id owned by rank (id * mul + add) % size, in a seeded shuffle.
std::vector<int64_t> owned(int64_t n, int mul, int add) {
  const int rank = comm_rank(), size = comm_size();
  std::vector<int64_t> ids;
  for (int64_t id = 0; id < n; ++id)
    if ((id * mul + add) % size == rank) ids.push_back(id);
  std::mt19937 rng(99 + rank);
  std::shuffle(ids.begin(), ids.end(), rng);
  return ids;
}

// The frame of one step as a solver would build it: owned values, moved to natural order.
SnapshotFrame make_frame(const NaturalOrder& mol, const std::vector<int64_t>& mol_ids, const NaturalOrder& con,
                         const std::vector<int64_t>& con_ids, int64_t step, double time) {
  std::vector<double> pos(3 * mol_ids.size()), disp(pos.size()), vel(pos.size());
  for (size_t i = 0; i < mol_ids.size(); ++i)
    for (int c = 0; c < 3; ++c) {
      pos[3 * i + c] = position(mol_ids[i], c, step);
      disp[3 * i + c] = displacement(mol_ids[i], c, step);
      vel[3 * i + c] = velocity(mol_ids[i], c, step);
    }
  std::vector<int64_t> ends(2 * con_ids.size());
  std::vector<double> eps(con_ids.size()), force(con_ids.size());
  for (size_t i = 0; i < con_ids.size(); ++i) {
    ends[2 * i] = endpoint(con_ids[i], 0);
    ends[2 * i + 1] = endpoint(con_ids[i], 1);
    eps[i] = strain(con_ids[i], step);
    force[i] = connection_force(con_ids[i], step);
  }
  SnapshotFrame f;
  f.step = step;
  f.time = time;
  f.title = "lattice 4 x 3 x 2 & <test>";
  f.molecules = N;
  f.connections = C;
  f.molecule_offset = mol.begin();
  f.molecule_rows = mol.count();
  f.positions = mol.to_natural(pos.data(), 3);
  f.displacements = mol.to_natural(disp.data(), 3);
  f.velocities = mol.to_natural(vel.data(), 3);
  // forces: deliberately absent
  f.connection_offset = con.begin();
  f.connection_rows = con.count();
  f.endpoints = con.to_natural_ids(ends.data(), 2);
  f.connection_strain = con.to_natural(eps.data(), 1);
  f.connection_force = con.to_natural(force.data(), 1);
  return f;
}

}  // namespace

TEST(Snapshot, WritesLatticeSeries) {
  const std::string dir = out_dir();
  const auto mol_ids = owned(N, 7, 0), con_ids = owned(C, 5, 1);
  NaturalOrder mol(MPI_COMM_WORLD, mol_ids, N), con(MPI_COMM_WORLD, con_ids, C);

  std::vector<XdmfEntry> entries;
  for (int s = 0; s < 2; ++s) {
    const std::string path = fresh(dir + "/" + prefix() + "_step" + std::to_string(STEPS[s]) + ".h5");
    entries.push_back(write_snapshot(path, MPI_COMM_WORLD, make_frame(mol, mol_ids, con, con_ids, STEPS[s], TIMES[s])));
    EXPECT_TRUE(fs::exists(path));
    EXPECT_FALSE(fs::exists(path + ".tmp"));
  }
  // Every rank gets the same entry, whatever its block held.
  EXPECT_EQ(entries[0].h5_file, prefix() + "_step0.h5");
  EXPECT_TRUE(entries[0].positions && entries[0].displacements && entries[0].velocities && entries[0].endpoints &&
              entries[0].connection_strain && entries[0].connection_force);
  EXPECT_FALSE(entries[0].forces);
  const std::string xdmf = fresh(dir + "/" + prefix() + ".xdmf");
  if (comm_rank() == 0) write_xdmf(xdmf, entries);
  MPI_Barrier(MPI_COMM_WORLD);

  for (int s = 0; s < 2; ++s) {
    const int64_t step = STEPS[s];
    Hdf5File f =
        Hdf5File::open(dir + "/" + prefix() + "_step" + std::to_string(step) + ".h5", MPI_COMM_WORLD, "file", nullptr);
    EXPECT_EQ(f.string_attribute("/", "kind"), "snapshot");
    EXPECT_EQ(f.string_attribute("/", "title"), "lattice 4 x 3 x 2 & <test>");
    EXPECT_EQ(f.string_attribute("/", "version"), TISSUE_VERSION);
    EXPECT_EQ(f.int64_attribute("/", "step"), step);
    EXPECT_EQ(f.double_attribute("/", "time"), TIMES[s]);
    EXPECT_EQ(f.int64_attribute("/", "molecules"), N);
    EXPECT_EQ(f.int64_attribute("/", "connections"), C);
    EXPECT_EQ(f.int64_attribute("/", "ranks"), comm_size());
    EXPECT_EQ(f.string_attribute("/molecules/velocities", "units"), "m/s");

    // Absent fields leave no dataset behind.
    EXPECT_FALSE(f.exists("/molecules/forces"));
    EXPECT_TRUE(f.exists("/molecules/positions"));
    EXPECT_FALSE(f.exists("/no/such/group"));

    EXPECT_EQ(f.shape("/molecules/positions"), (std::vector<int64_t>{N, 3}));
    EXPECT_EQ(f.shape("/connections/endpoints"), (std::vector<int64_t>{C, 2}));
    EXPECT_EQ(f.shape("/connections/strain"), (std::vector<int64_t>{C, 1}));

    // Whole datasets on every rank (fine for a test), so the check does not lean on the writer's blocks.
    const auto pos = f.read_double("/molecules/positions", 0, N);
    const auto disp = f.read_double("/molecules/displacements", 0, N);
    const auto vel = f.read_double("/molecules/velocities", 0, N);
    for (int64_t id = 0; id < N; ++id)
      for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(pos[3 * id + c], position(id, c, step)) << "id " << id;
        EXPECT_EQ(disp[3 * id + c], displacement(id, c, step)) << "id " << id;
        EXPECT_EQ(vel[3 * id + c], velocity(id, c, step)) << "id " << id;
      }
    const auto ends = f.read_int64("/connections/endpoints", 0, C);
    const auto eps = f.read_double("/connections/strain", 0, C);
    const auto force = f.read_double("/connections/force", 0, C);
    for (int64_t cid = 0; cid < C; ++cid) {
      EXPECT_EQ(ends[2 * cid], endpoint(cid, 0));
      EXPECT_EQ(ends[2 * cid + 1], endpoint(cid, 1));
      EXPECT_EQ(eps[cid], strain(cid, step));
      EXPECT_EQ(force[cid], connection_force(cid, step));
    }

    // A block read, the checkpoint way: my natural block, then back to my owned order.
    const auto block = f.read_double("/molecules/positions", mol.begin(), mol.count());
    const auto mine = mol.from_natural(block.data(), 3);
    for (size_t i = 0; i < mol_ids.size(); ++i)
      for (int c = 0; c < 3; ++c) EXPECT_EQ(mine[3 * i + c], position(mol_ids[i], c, step));
    f.close();
  }

  // The index points at both files and lists only what they hold.
  std::ifstream in(xdmf);
  std::stringstream text;
  text << in.rdbuf();
  const std::string x = text.str();
  EXPECT_NE(x.find("CollectionType=\"Temporal\""), std::string::npos);
  EXPECT_NE(x.find("TopologyType=\"Polyline\""), std::string::npos);
  EXPECT_NE(x.find(prefix() + "_step10.h5:/molecules/positions"), std::string::npos);
  EXPECT_NE(x.find("Name=\"velocity\""), std::string::npos);
  EXPECT_EQ(x.find("/molecules/forces"), std::string::npos);
  EXPECT_FALSE(fs::exists(xdmf + ".tmp"));
}

TEST(Snapshot, RanksWithoutRowsTakePart) {
  // One molecule and no connections: at 2 and 3 ranks, all but rank 0 write empty blocks.
  const std::string path = fresh(out_dir() + "/" + prefix() + "_tiny.h5");
  NaturalOrder mol(MPI_COMM_WORLD, comm_rank() == comm_size() - 1 ? std::vector<int64_t>{0} : std::vector<int64_t>{},
                   1);
  const double p[3] = {1.5, -2.5, 3.5};
  SnapshotFrame f;
  f.molecules = 1;
  f.molecule_offset = mol.begin();
  f.molecule_rows = mol.count();
  f.positions = mol.to_natural(comm_rank() == comm_size() - 1 ? p : nullptr, 3);
  const XdmfEntry e = write_snapshot(path, MPI_COMM_WORLD, f);
  EXPECT_TRUE(e.positions);
  EXPECT_FALSE(e.endpoints);
  Hdf5File h = Hdf5File::open(path, MPI_COMM_WORLD, "file", nullptr);
  EXPECT_EQ(h.read_double("/molecules/positions", 0, 1), (std::vector<double>{1.5, -2.5, 3.5}));
  EXPECT_FALSE(h.exists("/connections/endpoints"));
  EXPECT_EQ(h.int64_attribute("/", "connections"), 0);
  // An empty read on a rank is fine, too.
  EXPECT_TRUE(h.read_double("/molecules/positions", 1, 0).empty());
}

TEST(Snapshot, ErrorsAreOneLineAndLeaveNoFile) {
  const std::string dir = out_dir();
  // A frame whose positions are one value short on rank 0: every rank throws, nothing is left on disk.
  const std::string bad = fresh(dir + "/" + prefix() + "_bad.h5");
  const auto ids = owned(N, 7, 0);
  NaturalOrder mol(MPI_COMM_WORLD, ids, N);
  SnapshotFrame f;
  f.molecules = N;
  f.molecule_offset = mol.begin();
  f.molecule_rows = mol.count();
  f.positions.assign(3 * mol.count(), 0.0);
  if (comm_rank() == 0) f.positions.pop_back();
  EXPECT_THROW(write_snapshot(bad, MPI_COMM_WORLD, f), std::invalid_argument);
  f.positions.assign(3 * mol.count(), 0.0);
  f.molecule_offset += 1;  // blocks that do not tile
  EXPECT_THROW(write_snapshot(bad, MPI_COMM_WORLD, f), std::invalid_argument);
  MPI_Barrier(MPI_COMM_WORLD);
  EXPECT_FALSE(fs::exists(bad));
  EXPECT_FALSE(fs::exists(bad + ".tmp"));

  // A missing file names itself; a missing dataset names the file and the dataset.
  const std::string missing = dir + "/" + prefix() + "_missing.h5";
  try {
    Hdf5File::open(missing, MPI_COMM_WORLD, "file", nullptr);
    ADD_FAILURE() << "opened a missing file";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(missing), std::string::npos) << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
  }
  const std::string tiny = fresh(dir + "/" + prefix() + "_err.h5");
  {
    Hdf5File w = Hdf5File::create(tiny, MPI_COMM_WORLD);
    const double v[2] = {1.0, 2.0};
    w.write("/a/b", 1, 2, 0, comm_rank() == 0 ? 1 : 0, v);
    w.set_attribute("/a/b", "n", 7);
    // Shapes that disagree across ranks are caught before HDF5 sees them (at one rank, a block out of range).
    EXPECT_THROW(w.write("/a/c", 2 + comm_rank(), 1, 0, comm_rank() == 0 ? 3 : 0, v), std::runtime_error);
    // Not yet published: only the tmp file exists.
    MPI_Barrier(MPI_COMM_WORLD);
    EXPECT_FALSE(fs::exists(tiny));
    w.close();
  }
  EXPECT_TRUE(fs::exists(tiny));
  // A file abandoned before close() (an exception unwinding past it) is not published, and its tmp is removed.
  const std::string abandoned = fresh(dir + "/" + prefix() + "_abandoned.h5");
  {
    Hdf5File w = Hdf5File::create(abandoned, MPI_COMM_WORLD);
    w.set_attribute("/", "kind", "snapshot");
  }
  MPI_Barrier(MPI_COMM_WORLD);
  EXPECT_FALSE(fs::exists(abandoned));
  EXPECT_FALSE(fs::exists(abandoned + ".tmp"));
  Hdf5File r = Hdf5File::open(tiny, MPI_COMM_WORLD, "file", nullptr);
  EXPECT_EQ(r.int64_attribute("/a/b", "n"), 7);
  try {
    r.read_double("/a/nothing", 0, 1);
    ADD_FAILURE() << "read a missing dataset";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(tiny), std::string::npos) << what;
    EXPECT_NE(what.find("/a/nothing"), std::string::npos) << what;
  }
  EXPECT_THROW(r.read_double("/a/b", 0, 2), std::runtime_error);  // past the end
  EXPECT_THROW(r.string_attribute("/", "nothing"), std::runtime_error);
}
