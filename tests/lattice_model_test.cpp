// The lattice path (partition/lattice_model.cpp: each rank generates its share from the topology's stencil)
// against the explicit path (build_body enumerates every connection and tetrahedron of the whole body, then
// distribute() scatters it): the two must give every rank the same LocalModel, array for array. Run at 1, 2 and
// 3 ranks, so the directory exchanges, the ghost queries and the connection numbering are all exercised.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <cmath>
#include <limits>
#include <random>
#include <string>

#include "io/scene.hpp"
#include "partition/box_bisection.hpp"
#include "partition/ghosted_vector.hpp"
#include "partition/lattice_blocks.hpp"
#include "partition/lattice_model.hpp"
#include "partition/local_model.hpp"
#include "partition/metis_partition.hpp"
#include "partition/natural_order.hpp"
#include "src/calibration/calibration.hpp"
#include "src/physics/force_model.hpp"
#include "src/physics/spring_kernel.hpp"
#include "src/model/body.hpp"
#include "src/model/topology.hpp"
#include "tests/model_checks.hpp"
#include "tests/whole_body.hpp"

using namespace tissue;

namespace {

Built explicit_path(const Scene& scene, MPI_Comm comm) {
  Body body = build_body(scene);
  PartitionStats stats;
  // The partition the lattice path takes: the bisection of the box (partition.method auto or blocks on one box
  // lattice), computed whole on this rank; METIS otherwise.
  std::vector<int> part;
  const PartitionSpec::Method method = scene.partition.method;
  int size;
  MPI_Comm_size(comm, &size);
  if (size > 1 && box_bisection_chosen(body, method, size))
    part = partition_box_bisection(body, PETSC_COMM_SELF, size, stats);
  else
    part = partition_molecules(body, comm, stats);
  Built b;
  b.model = distribute(body, part, stats, comm, b.inputs);
  return b;
}

Built lattice_path(const Scene& scene, MPI_Comm comm) {
  Built b;
  b.model = build_lattice_model(scene, comm, b.inputs);
  return b;
}

// Every local connection's global id names that connection in the whole body's sorted list; each rank writes
// exactly the connections whose end a it owns, and together the ranks write each connection once.
void expect_numbering(const LocalModel& m, const Body& body) {
  for (int c = 0; c < m.connections(); ++c) {
    const std::int64_t g = m.connection_id(c);
    ASSERT_GE(g, 0);
    ASSERT_LT(g, static_cast<std::int64_t>(body.connections.size()));
    EXPECT_EQ(body.connections[g].a, m.id[m.end_a[c]]) << c;
    EXPECT_EQ(body.connections[g].b, m.id[m.end_b[c]]) << c;
  }
  long long written = 0, all = 0, prev = -1;
  bool ascending = true;
  for (int c : m.written_here()) {
    ++written;
    EXPECT_LT(m.end_a[c], m.owned);
    ascending = ascending && m.connection_id(c) > prev, prev = m.connection_id(c);
  }
  EXPECT_TRUE(ascending);
  EXPECT_EQ(static_cast<std::size_t>(written), m.written_here().size());
  MPI_Allreduce(&written, &all, 1, MPI_LONG_LONG, MPI_SUM, m.comm);
  EXPECT_EQ(all, static_cast<long long>(body.connections.size()));
}

void expect_same(const Built& bx, const Built& by) {
  const LocalModel &x = bx.model, &y = by.model;
  const CalibrationInputs &xi = bx.inputs, &yi = by.inputs;
  expect_same_molecules(bx, by);
  EXPECT_DOUBLE_EQ(x.partition.imbalance, y.partition.imbalance);
  EXPECT_DOUBLE_EQ(x.partition.surface_to_volume, y.partition.surface_to_volume);
  // The lattice finds each connection's position among its end a's from the stencil, the explicit path keeps it.
  EXPECT_TRUE(x.forward_rank.empty());
  for (int c = 0; c < x.connections(); ++c) ASSERT_EQ(x.connection_id(c), y.connection_id(c)) << "connection " << c;
  // The lattice keeps rest lengths by type (a handful), the explicit path one per connection: the same doubles.
  EXPECT_EQ(x.table.rest_length_column().type != nullptr, true);
  EXPECT_EQ(y.table.rest_length_column().type, nullptr);
  EXPECT_LE(x.table.length_types(), 13u * static_cast<std::size_t>(x.shape.bodies()));
  for (int c = 0; c < x.connections(); ++c) ASSERT_EQ(x.l0(c), y.l0(c)) << "connection " << c;
  // The classes too: the lattice's walk takes an interior molecule's from its stencil, the explicit path its body's.
  ASSERT_EQ(x.connection_class.size(), y.connection_class.size());
  for (int c = 0; c < x.connections(); ++c) ASSERT_EQ(x.connection_class[c], y.connection_class[c]) << "connection " << c;
  // The explicit path computes each tetrahedron's volume from its corners (round-off differs cell to cell); the
  // lattice path uses h_x h_y h_z / 6 for all.
  ASSERT_EQ(xi.tetra_volume.size(), yi.tetra_volume.size());
  ASSERT_EQ(xi.tetra_lloyd_sum.size(), yi.tetra_lloyd_sum.size());
  for (std::size_t c = 0; c < xi.tetra_volume.size(); ++c) {
    EXPECT_NEAR(xi.tetra_volume[c], yi.tetra_volume[c], 1e-12 * std::fabs(yi.tetra_volume[c]) + 1e-300) << c;
    EXPECT_NEAR(xi.tetra_lloyd_sum[c], yi.tetra_lloyd_sum[c], 1e-12 * std::fabs(yi.tetra_lloyd_sum[c]) + 1e-300) << c;
  }
}

// Dynamic: no fix needed, the model is all this test looks at.
const char* solver = "\n[solver]\nkind = \"dynamic\"\nsteps = 1\n";

std::string one_body(const std::string& topology) {
  return std::string(solver) + R"(
[body]
molecules = [5, 4, 6]
spacing = [0.1, 0.13, 0.07]
offset = [0.5, -0.2, 1.0]
topology = ")" + topology + R"("
youngs_modulus = 1.0e5
density = 1100.0
[[body.region]]
lo = [0.0, 0.0, 0.0]
hi = [0.25, 0.4, 0.2]
youngs_modulus = 3.0e6
density = 1900.0
)";
}

class EveryTopology : public ::testing::TestWithParam<std::string> {};

TEST_P(EveryTopology, LatticePathEqualsExplicitPath) {
  const Scene scene = parse_scene(one_body(GetParam()), "lattice.toml");
  const Built lattice = lattice_path(scene, PETSC_COMM_WORLD);
  expect_same(lattice, explicit_path(scene, PETSC_COMM_WORLD));
  expect_numbering(lattice.model, build_body(scene));
}

INSTANTIATE_TEST_SUITE_P(Topologies, EveryTopology,
                         ::testing::Values("rectangular", "face-diagonals", "body-diagonals", "tetrahedral"),
                         [](const auto& info) {
                           std::string s = info.param;
                           for (char& c : s) c = c == '-' ? '_' : c;
                           return s;
                         });

TEST(LatticeModel, SeveralBodiesOfDifferentTopologies) {
  const std::string text = std::string(solver) + R"(
[[body]]
molecules = [3, 4, 3]
spacing = [0.1, 0.1, 0.1]
topology = "tetrahedral"
youngs_modulus = 2.0e5
[[body]]
molecules = [4, 3, 5]
spacing = [0.12, 0.1, 0.08]
offset = [1.0, 0.0, 0.0]
topology = "body-diagonals"
youngs_modulus = 7.0e4
[[body]]
molecules = [2, 2, 2]
spacing = [0.1, 0.1, 0.1]
offset = [2.0, 0.0, 0.0]
topology = "face-diagonals"
youngs_modulus = 1.0e4
)";
  const Scene scene = parse_scene(text, "bodies.toml");
  const Built lattice = lattice_path(scene, PETSC_COMM_WORLD);
  expect_same(lattice, explicit_path(scene, PETSC_COMM_WORLD));
  expect_numbering(lattice.model, build_body(scene));
}

// The stencil's neighbour counts against closed forms: the paper's Fig. 8 box has 7560 connections.
TEST(LatticeModel, ConnectionCountsOfThePaperBox) {
  const Scene scene = parse_scene(std::string(solver) + R"(
[body]
molecules = [10, 10, 10]
spacing = [0.111111, 0.111111, 0.0955556]
topology = "face-diagonals"
youngs_modulus = 1.0e5
)", "fig8.toml");
  EXPECT_EQ(lattice_path(scene, PETSC_COMM_WORLD).model.global_connections, 7560);
}

}  // namespace

namespace {

// The optimized kernel (connection types, the templated loop of force_model.cpp) against a plain reference loop
// written here: per connection, the force k (l - l0) along the current direction, added to both ends, with k and
// l0 straight from the calibration's arrays. Positions perturbed at random so every spring carries a force.
TEST(LatticeModel, TypedKernelEqualsPlainReferenceLoop) {
  const Scene scene = parse_scene(std::string(solver) + R"(
[body]
molecules = [7, 6, 8]
spacing = [0.1, 0.13, 0.07]
topology = "body-diagonals"
youngs_modulus = 1.0e5
[[body.region]]
lo = [0.0, 0.0, 0.0]
hi = [0.3, 0.7, 0.2]
youngs_modulus = 2.0e7
[calibration]
method = "linear"
)", "kernel.toml");
  CalibrationInputs inputs;
  LocalModel model = build_local_model(scene, PETSC_COMM_WORLD, inputs);
  ASSERT_FALSE(calibrate_scene(scene, model, inputs));
  ASSERT_TRUE(stiffness_is_final(scene, {}));
  std::vector<double> l0(model.connections());
  for (int c = 0; c < model.connections(); ++c) l0[c] = model.l0(c);
  const std::vector<double> k = model.table.stiffness();
  ASSERT_TRUE(model.table.compact());
  EXPECT_TRUE(model.table.stiffness().empty());
  // A lattice of two materials has few distinct springs: by class, direction, boundary and material.
  EXPECT_LT(model.table.connection_types(), 200u);
  for (int c = 0; c < model.connections(); ++c) {
    ASSERT_EQ(model.k(c), k[c]);
    ASSERT_EQ(model.l0(c), l0[c]);
  }

  std::mt19937 random(7);
  std::uniform_real_distribution<double> jitter(-0.02, 0.02);
  std::vector<double> x(model.rest);
  for (int i = 0; i < model.local; ++i)  // the same perturbation of a molecule on every rank: seeded by its id
    for (int d = 0; d < 3; ++d) {
      std::mt19937 r(static_cast<unsigned>(model.id[i] * 3 + d));
      x[3 * i + d] += jitter(r);
    }
  ForceModel forces(scene, model);
  std::vector<double> f(3 * model.local);
  forces.connection_forces(x.data(), f.data());

  std::vector<double> reference(3 * model.local, 0.0);
  for (int c = 0; c < model.connections(); ++c) {
    const int a = model.end_a[c], b = model.end_b[c];
    double d[3], len = 0;
    for (int j = 0; j < 3; ++j) d[j] = x[3 * b + j] - x[3 * a + j], len += d[j] * d[j];
    len = std::sqrt(len);
    for (int j = 0; j < 3; ++j) {
      const double force = k[c] * (len - l0[c]) * d[j] / len;
      reference[3 * a + j] += force, reference[3 * b + j] -= force;
    }
  }
  double largest = 0, worst = 0;
  for (int j = 0; j < 3 * model.owned; ++j) largest = std::max(largest, std::fabs(reference[j]));
  for (int j = 0; j < 3 * model.owned; ++j) worst = std::max(worst, std::fabs(f[j] - reference[j]));
  ASSERT_GT(largest, 0.0);
  EXPECT_LT(worst, 1e-12 * largest);
}

}  // namespace

namespace {

// Two materials, so the lattice has several connection types per direction and several stencil patterns.
const char* kTwoMaterials = R"(
[body]
molecules = [13, 11, 9]
spacing = [0.1, 0.12, 0.09]
topology = "face-diagonals"
youngs_modulus = 1.0e5
[[body.region]]
lo = [0.0, 0.0, 0.0]
hi = [0.6, 0.5, 0.4]
youngs_modulus = 3.0e6
[calibration]
method = "linear"
[partition]
method = "metis"
)";
// (METIS: the bisection ("auto") cuts this small box's x axis at 3 ranks, and a part 4 molecules wide has rows
// too short for a segment (kShortest), so one rank would have none to compare.)

// Rest positions moved by up to 0.02 in each coordinate, the same for a molecule on any partition (seeded by id).
std::vector<double> jittered(const LocalModel& m) {
  std::vector<double> x(m.rest);
  for (int i = 0; i < m.local; ++i)
    for (int d = 0; d < 3; ++d) {
      std::mt19937 r(static_cast<unsigned>(m.id[i] * 3 + d));
      x[3 * i + d] += std::uniform_real_distribution<double>(-0.02, 0.02)(r);
    }
  return x;
}

// One stiffness a direction (manual calibration, as the LAMMPS peer's lattice): a box's row ends, faces and edges
// lack some of the stencil's directions; they stay in the stencil segments with those directions masked, so on
// one rank the segments span whole planes. (Calibrated lattices give the face springs their own stiffness: a
// type of their own, where a segment still ends.)
const char* kOneMaterial = R"(
[body]
molecules = [13, 11, 30]
spacing = [0.1, 0.12, 0.09]
topology = "face-diagonals"
youngs_modulus = 1.0e5
[calibration]
method = "manual"
stiffness = { edge = 100.0, face = 50.0 }
)";

// The stencil segments (end b = end a + a fixed offset, k and l0 per direction; missing directions masked)
// against the generic kernel on the same connections, untyped: the same bits on every owned molecule, on every
// partition (1, 2 and 3 ranks). `one_rank_share`: the least share of the connections in segments on one rank.
// rings: how many segments the pull form's force ring ran on (SpringKernel::pull_ring_segments).
void expect_stencil_equals_generic(const char* body, double one_rank_share, int* rings_out = nullptr) {
  int rings = 0;
  const Scene scene = parse_scene(std::string(solver) + body, "stencil.toml");
  CalibrationInputs inputs;
  LocalModel generic = build_local_model(scene, PETSC_COMM_WORLD, inputs);
  ASSERT_FALSE(calibrate_scene(scene, generic, inputs));
  LocalModel typed = generic;
  ASSERT_TRUE(typed.table.compact());
  const SpringKernel stencil_kernel(typed), generic_kernel(generic);
  EXPECT_EQ(generic_kernel.structured_connections(), 0);
  // On one rank most connections; on any partition some.
  EXPECT_GT(stencil_kernel.structured_connections(),
            typed.size == 1 ? static_cast<long>(one_rank_share * typed.connections()) : 1);
  const std::vector<double> x = jittered(typed);
  // f starts as NaN: the kernel zeroes every row itself (the owned ones just ahead of their first write), so a
  // row it missed would stay NaN.
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> f(3 * typed.local, nan), g(3 * typed.local, nan);
  stencil_kernel.forces(x.data(), f.data());
  generic_kernel.forces(x.data(), g.data());
  double largest = 0;
  for (int j = 0; j < 3 * typed.local; ++j) {
    ASSERT_TRUE(std::isfinite(f[j]) && std::isfinite(g[j])) << j;
    if (j < 3 * typed.owned) ASSERT_EQ(f[j], g[j]) << j;  // bit for bit, not within a tolerance
    largest = std::max(largest, std::fabs(g[j]));
  }
  EXPECT_GT(largest, 0.0);
  // Again on the last step's forces, as a time loop calls it: the same bits.
  const std::vector<double> first = f;
  stencil_kernel.forces(x.data(), f.data());
  for (int j = 0; j < 3 * typed.owned; ++j) ASSERT_EQ(f[j], first[j]) << j;
  // With rows handed over as final (the fused Verlet step moves them at once): each owned row once, in order,
  // already at its final bits, and never read again: its positions are spoiled (NaN) as it is handed over, and
  // every later force keeps its bits.
  struct Check {
    const std::vector<double>* expected;
    std::vector<double>* f;
    std::vector<double>* x;
    int next = 0, calls = 0;
    bool ok = true;
  };
  std::vector<double> spoiled = x, h(3 * typed.local, nan);
  Check check{&first, &h, &spoiled};
  stencil_kernel.forces(spoiled.data(), h.data(), [](void* context, int begin, int end) {
    Check& c = *static_cast<Check*>(context);
    c.ok = c.ok && begin == c.next && end > begin;
    for (int j = 3 * begin; j < 3 * end; ++j) {
      c.ok = c.ok && (*c.f)[j] == (*c.expected)[j];
      (*c.x)[j] = std::numeric_limits<double>::quiet_NaN();
    }
    c.next = end, ++c.calls;
  }, &check);
  EXPECT_TRUE(check.ok);
  EXPECT_EQ(check.next, typed.owned);
  for (int j = 0; j < 3 * typed.owned; ++j) ASSERT_EQ(h[j], first[j]) << j;
  // On one rank the rows go in many pieces (the kernel's chunks), not all at the end.
  if (typed.size == 1) EXPECT_GT(check.calls, 1);

  // x and f as three streams each (the explicit solver's fused steps), with a stride past the local molecules
  // whose padding is NaN: the same bits from both kernels, so no force reads past the local molecules, and the
  // same rows handed over in order, already final.
  const std::size_t stride = typed.local + 5;
  auto streams = [&](const std::vector<double>& interlaced) {
    std::vector<double> s(3 * stride, nan);
    for (int i = 0; i < typed.local; ++i)
      for (int d = 0; d < 3; ++d) s[d * stride + i] = interlaced[3 * i + d];
    return s;
  };
  const std::vector<double> xs = streams(x);
  std::vector<double> fs(3 * stride, nan), gs(3 * stride, nan);
  // As above, the positions of a row handed over are spoiled (the pull form reads a row's x until the rows its
  // largest offset above it are done), in the pull form (the default) and the push form.
  struct StreamCheck {
    const std::vector<double>* expected;
    const std::vector<double>* f;
    std::vector<double>* x;
    std::size_t stride;
    int next = 0;
    bool ok = true;
  };
  // The pull form with and without its force ring (the in-plane springs computed once, at end a).
  for (const int form_id : {0, 1, 2}) {
    const bool pull = form_id > 0;
    std::vector<double> xs_spoiled = xs;
    std::fill(fs.begin(), fs.end(), nan);
    StreamCheck stream_check{&first, &fs, &xs_spoiled, stride};
    SpringKernel form(typed);
    form.set_pull(pull);
    form.set_pull_ring(form_id == 2);
    if (form_id == 2) rings = form.pull_ring_segments();
    form.forces_streams(xs_spoiled.data(), fs.data(), stride, [](void* context, int begin, int end) {
      StreamCheck& c = *static_cast<StreamCheck*>(context);
      c.ok = c.ok && begin == c.next && end > begin;
      for (int i = begin; i < end; ++i)
        for (int d = 0; d < 3; ++d) {
          c.ok = c.ok && (*c.f)[d * c.stride + i] == (*c.expected)[3 * i + d];
          (*c.x)[d * c.stride + i] = std::numeric_limits<double>::quiet_NaN();
        }
      c.next = end;
    }, &stream_check);
    EXPECT_TRUE(stream_check.ok) << form_id;
    EXPECT_EQ(stream_check.next, typed.owned);
    for (int i = 0; i < typed.owned; ++i)
      for (int d = 0; d < 3; ++d) ASSERT_EQ(fs[d * stride + i], first[3 * i + d]) << form_id << " " << i;
  }
  generic_kernel.forces_streams(xs.data(), gs.data(), stride, nullptr, nullptr);
  for (int i = 0; i < typed.owned; ++i)
    for (int d = 0; d < 3; ++d) ASSERT_EQ(gs[d * stride + i], first[3 * i + d]) << i;
  if (rings_out) *rings_out = rings;
}

// A lattice's connection ends as runs of rows (what the lattice build keeps for the dynamic solver): every end,
// connection id and written connection as in the plain arrays a static scene keeps, and the kernel's forces the
// same bits, on every partition (1, 2 and 3 ranks). The lattice is long in x so that its rows are worth storing
// as runs on any of them.
TEST(SpringKernel, EndsAsRunsGiveTheSameEndsIdsAndForces) {
  const std::string body = R"(
[body]
molecules = [90, 6, 5]
spacing = [0.1, 0.12, 0.09]
topology = "face-diagonals"
youngs_modulus = 1.0e5
[calibration]
method = "linear"
)";
  auto built = [](const std::string& text) {
    const Scene scene = parse_scene(text, "runs.toml");
    CalibrationInputs inputs;
    LocalModel m = build_local_model(scene, PETSC_COMM_WORLD, inputs);
    EXPECT_FALSE(calibrate_scene(scene, m, inputs));
    EXPECT_TRUE(m.table.compact());
    return m;
  };
  const LocalModel plain = built(body + "[[fix]]\nface = \"x-\"\n"), runs = built(std::string(solver) + body);  // static, dynamic
  ASSERT_TRUE(plain.end_a.plain() && plain.end_b.plain());
  ASSERT_FALSE(runs.end_a.plain() || runs.end_b.plain());
  EXPECT_LE(runs.end_a.bytes() + runs.end_b.bytes(), (plain.end_a.bytes() + plain.end_b.bytes()) / 4);
  LocalModel again = plain;  // the same runs from the plain arrays
  ASSERT_TRUE(ConnectionEnd::to_runs(again.end_a, again.end_b));
  EXPECT_EQ(again.end_a.bytes(), runs.end_a.bytes());
  ASSERT_EQ(runs.connections(), plain.connections());
  for (int c = 0; c < plain.connections(); ++c) {  // in order (the remembered run) ...
    ASSERT_EQ(runs.end_a[c], plain.end_a[c]) << c;
    ASSERT_EQ(runs.end_b[c], plain.end_b[c]) << c;
    ASSERT_EQ(runs.connection_id(c), plain.connection_id(c)) << c;
  }
  for (int c = plain.connections() - 1; c >= 0; c -= 7) {  // ... and out of order (the binary search)
    ASSERT_EQ(runs.end_a[c], plain.end_a[c]) << c;
    ASSERT_EQ(runs.end_b[c], plain.end_b[c]) << c;
  }
  std::vector<int> written_plain, written_runs;
  for (int c : plain.written_here()) written_plain.push_back(c);
  for (int c : runs.written_here()) written_runs.push_back(c);
  EXPECT_EQ(written_runs, written_plain);
  EXPECT_EQ(written_runs.size(), plain.written_count);
  // The passes outside the kernel walk the runs (for_each_pair, for_each_written): every connection once, in
  // order, with the ends the indexed reads give.
  for (const LocalModel* m : {&plain, &runs}) {
    int next = 0;
    m->end_a.for_each_pair(m->end_b, [&](int c, int a, int b) {
      ASSERT_EQ(c, next++);
      ASSERT_EQ(a, plain.end_a[c]) << c;
      ASSERT_EQ(b, plain.end_b[c]) << c;
    });
    EXPECT_EQ(next, plain.connections());
    std::vector<int> visited;
    m->for_each_written([&](int c, int a, int b) {
      ASSERT_EQ(a, plain.end_a[c]) << c;
      ASSERT_EQ(b, plain.end_b[c]) << c;
      visited.push_back(c);
    });
    EXPECT_EQ(visited, written_plain);
  }

  const SpringKernel from_runs(runs), from_plain(plain);
  EXPECT_EQ(from_runs.structured_connections(), from_plain.structured_connections());
  const std::vector<double> x = jittered(plain);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> f(3 * plain.local, nan), g(3 * plain.local, nan);
  from_runs.forces(x.data(), f.data());
  from_plain.forces(x.data(), g.data());
  double largest = 0;
  for (int j = 0; j < 3 * plain.local; ++j) {
    ASSERT_TRUE(std::isfinite(f[j])) << j;
    ASSERT_EQ(f[j], g[j]) << j;  // bit for bit, ghost rows too
    largest = std::max(largest, std::fabs(g[j]));
  }
  EXPECT_GT(largest, 0.0);
}

// The ghost update of positions held as three streams (StreamGhosts, the fused explicit step's) gives every ghost
// slot the bits PETSc's update of the interlaced vector gives it, at 1, 2 and 3 ranks, and leaves the owned
// values alone.
TEST(StreamGhosts, GiveTheGhostsPetscsValues) {
  const Scene scene = parse_scene(std::string(solver) + kOneMaterial, "ghosts.toml");
  CalibrationInputs inputs;
  const LocalModel model = build_local_model(scene, PETSC_COMM_WORLD, inputs);
  GhostedVector x(model);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::size_t stride = model.local + 3;
  std::vector<double> xs(3 * stride, nan);
  for (int i = 0; i < model.local; ++i)
    for (int d = 0; d < 3; ++d) {
      // Owned: a value of the molecule's id that no other molecule has; ghosts: NaN until updated.
      const double value = i < model.owned ? 1.0 + 1e-3 * static_cast<double>(model.id[i]) + 0.25 * d : nan;
      x.array()[3 * i + d] = value, xs[d * stride + i] = value;
    }
  x.update_ghosts();
  StreamGhosts ghosts(model);
  ghosts.update(xs.data(), stride);
  for (int i = 0; i < model.local; ++i)
    for (int d = 0; d < 3; ++d) {
      ASSERT_TRUE(std::isfinite(xs[d * stride + i])) << i;
      ASSERT_EQ(xs[d * stride + i], x.array()[3 * i + d]) << i;
    }
  for (std::size_t j = model.local; j < stride; ++j) EXPECT_TRUE(std::isnan(xs[j]));  // the padding untouched
  if (model.size > 1) {
    int ghosts_here = model.local - model.owned, any = 0;
    MPI_Allreduce(&ghosts_here, &any, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
    EXPECT_GT(any, 0);
  }
}

// Per-molecule integer arrays as arithmetic runs (RunArray): the same values as the plain array they came from,
// stored as runs only where that halves the bytes.
TEST(RunArray, GivesBackEveryValue) {
  std::vector<std::int64_t> ids;
  for (std::int64_t g = 100; g < 400; ++g) ids.push_back(g);          // an owned block
  for (std::int64_t g = 1000; g < 1600; g += 7) ids.push_back(g);    // a step of 7
  for (int k = 0; k < 50; ++k) ids.push_back(5);                      // constant
  ids.push_back(-3), ids.push_back(12), ids.push_back(11);            // runs of one
  RunArray<std::int64_t> runs;
  runs.assign(ids);
  ASSERT_EQ(runs.size(), ids.size());
  for (int i = 0; i < static_cast<int>(ids.size()); ++i) ASSERT_EQ(runs[i], ids[i]) << i;
  for (int i = static_cast<int>(ids.size()) - 1; i >= 0; i -= 3) ASSERT_EQ(runs[i], ids[i]) << i;
  EXPECT_EQ(runs.values(), ids);
  EXPECT_EQ(runs.slice(300, 310), std::vector<std::int64_t>(ids.begin() + 300, ids.begin() + 310));
  std::vector<int> scattered;  // no runs worth keeping: the plain array, the same values
  std::mt19937 r(7);
  for (int k = 0; k < 500; ++k) scattered.push_back(static_cast<int>(r() % 1000));
  RunArray<int> plain;
  plain.assign(scattered);
  EXPECT_EQ(plain.values(), scattered);
}

TEST(SpringKernel, StencilSegmentsEqualGenericKernelBitForBit) { expect_stencil_equals_generic(kTwoMaterials, 1.0 / 3); }

// On one rank only the last plane and a row (where the stencil would reach past the last molecule) stay generic,
// under 4 % of the connections here; with the row ends generic (12 of a row's 111 connections), as before, the
// share would be under 0.9.
TEST(SpringKernel, MaskedRowEndsEqualGenericKernelBitForBit) { expect_stencil_equals_generic(kOneMaterial, 0.95); }

// Rows of 70 molecules: the pull form's pieces hold long stretches of rows with every spring present (no mark)
// between the row ends' marks, as a large lattice's do; the same bits as the generic kernel.
TEST(SpringKernel, LongRowsEqualGenericKernelBitForBit) {
  std::string long_rows = kOneMaterial;
  long_rows.replace(long_rows.find("[13, 11, 30]"), 12, "[70, 5, 6]");
  expect_stencil_equals_generic(long_rows.c_str(), 0.95);
}

// Rows of 40 molecules in planes of 40 x 4 (offsets 39, 40, 41 in the plane, 159-201 across): the pull form reads
// the in-plane springs from its force ring (their end a's forces) on one rank; the same bits as the generic kernel
// (and as the pull form without the ring) at 1, 2 and 3 ranks, with the ring's slides (2,080 rows a plane's
// segment, a ring of 1,024) and its first rows (no end a in the segment) on the way. Also the rectangular lattice,
// whose ring holds one direction.
TEST(SpringKernel, PullFormsForceRingEqualsGenericKernelBitForBit) {
  for (const char* topology : {"face-diagonals", "rectangular"}) {
    std::string body = kOneMaterial;
    body.replace(body.find("[13, 11, 30]"), 12, "[40, 4, 13]");
    body.replace(body.find("face-diagonals"), 14, topology);
    int rings = 0;
    expect_stencil_equals_generic(body.c_str(), 0.9, &rings);
    int size = 1;
    MPI_Comm_size(PETSC_COMM_WORLD, &size);
    if (size == 1) EXPECT_GT(rings, 0) << topology;
  }
}

// The coarse (blocked) lattice partition: every molecule of a block in the block's part, every part non-empty and
// near the mean, the edge cut METIS reports equal to the connections counted between parts here, and the same
// parts whatever the number of ranks that compute it (each rank counts only its natural block's connections).
TEST(LatticeBlocks, ValidBalancedAndIndependentOfTheRankCount) {
  const Scene scene = parse_scene(std::string(solver) + kTwoMaterials, "blocks.toml");
  const Body shape = scene_shape(scene);
  const std::int64_t n = shape.molecules();
  const TopologyStyle& style = *find_topology(shape.topology);
  int rank, size;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  for (int parts : {2, 3, 5}) {
    PartitionStats stats, alone;
    const std::vector<int> mine = partition_lattice_blocks(shape, PETSC_COMM_WORLD, parts, 2, stats);
    const std::vector<int> all = partition_lattice_blocks(shape, PETSC_COMM_SELF, parts, 2, alone);
    ASSERT_EQ(static_cast<std::int64_t>(all.size()), n);
    const std::int64_t begin = NaturalOrder::block_begin(n, size, rank);
    for (std::size_t i = 0; i < mine.size(); ++i) ASSERT_EQ(mine[i], all[begin + i]) << parts << " " << i;
    EXPECT_EQ(stats.edge_cut, alone.edge_cut);
    std::vector<long> count(parts, 0);
    long cut = 0;
    std::vector<Neighbour> nb;
    for (std::int64_t g = 0; g < n; ++g) {
      ASSERT_GE(all[g], 0);
      ASSERT_LT(all[g], parts);
      ++count[all[g]];
      const auto ijk = shape.index(g);  // the block's first molecule holds the block's part
      EXPECT_EQ(all[g], all[shape.id(ijk[0] / 2 * 2, ijk[1] / 2 * 2, ijk[2] / 2 * 2)]);
      lattice_neighbours(style, shape, g, nb);
      for (const auto& x : nb) cut += x.id > g && all[x.id] != all[g];
    }
    EXPECT_EQ(stats.edge_cut, cut) << parts;
    EXPECT_GT(cut, 0);
    const long largest = *std::max_element(count.begin(), count.end());
    EXPECT_DOUBLE_EQ(stats.imbalance, static_cast<double>(largest) * parts / n);
    EXPECT_LT(stats.imbalance, 1.15) << parts;  // blocks of 8 molecules among 1287 (METIS allows 3 %)
    EXPECT_GT(*std::min_element(count.begin(), count.end()), 0);
  }
  // The block edge: the molecule graph itself up to 32,768 molecules (more parts: 128 a part), blocks past that.
  EXPECT_EQ(lattice_block_size(shape, 2), 1);
  Body edge;
  edge.n = {32, 32, 32};
  edge.topology = "face-diagonals";
  EXPECT_EQ(lattice_block_size(edge, 2), 1);    // 32,768 molecules
  edge.n = {40, 40, 40};
  EXPECT_EQ(lattice_block_size(edge, 2), 2);    // 64,000 molecules: 20^3 blocks
  EXPECT_EQ(lattice_block_size(edge, 512), 1);  // 64,000 <= 128 x 512
  Body big;
  big.n = {100, 100, 100};
  big.topology = "face-diagonals";
  EXPECT_EQ(lattice_block_size(big, 2), 4);     // 25^3 = 15,625 blocks <= 32,768 < 34^3 with b = 3
  EXPECT_EQ(lattice_block_size(big, 1024), 2);  // 50^3 = 125,000 blocks <= 131,072
}

// The stencil laid on a box (LatticeStencil, the lattice set-up's neighbour lists) gives every molecule's
// neighbours exactly as lattice_neighbours does (ids, classes, directions, order), and each one's rest distance
// bit for bit BoxGeometry::rest_distance's, on every topology, in boxes thin enough that no molecule is interior
// (sides of 1 and 2) and boxes where most are, with and without a first id.
TEST(LatticeStencil, EqualsTheNeighbourListsAndRestDistances) {
  long interior = 0;
  for (const auto& style : topology_styles())
    for (const std::array<long, 3> n : {std::array<long, 3>{1, 1, 1}, {2, 3, 1}, {2, 2, 2}, {3, 3, 3}, {5, 4, 3},
                                        {7, 6, 5}, {3, 9, 2}}) {
      BoxGeometry box;
      box.n = n, box.h = {0.3, 0.7, 1.1}, box.topology = style.name, box.first = n[0] == 5 ? 17 : 0;
      const LatticeStencil stencil(style, box);
      std::vector<Neighbour> fast, slow;
      for (std::int64_t g = box.first; g < box.first + box.molecules(); ++g) {
        stencil.neighbours(g, fast);
        lattice_neighbours(style, box, g, slow);
        ASSERT_EQ(fast.size(), slow.size()) << style.name << " " << g;
        for (std::size_t k = 0; k < fast.size(); ++k) {
          EXPECT_EQ(fast[k].id, slow[k].id) << style.name << " " << g;
          EXPECT_EQ(fast[k].cls, slow[k].cls);
          EXPECT_EQ(fast[k].direction, slow[k].direction);
          const double want = box.rest_distance(g, fast[k].id), got = stencil.rest_distance(fast[k]);
          EXPECT_EQ(std::memcmp(&want, &got, sizeof want), 0) << style.name << " " << g << " " << fast[k].id;
        }
        interior += fast.size() == style.stencil.size();
      }
    }
  EXPECT_GT(interior, 0);  // the interior shortcut ran
}

}  // namespace
