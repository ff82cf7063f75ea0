// The explicit path (partition/explicit_model.cpp: rank 0 reads the mesh or draws the cloud and hands molecules
// and tetrahedron edges out in blocks; each rank builds its share) against the whole-body reference (build_body
// holds every connection and tetrahedron on every rank, then distribute() keeps each rank's share): every rank
// must get the same LocalModel, array for array and bit for bit, and the same body geometry and named faces.
// Run at 1, 2 and 3 ranks, with METIS and PT-Scotch, on a mesh with regions, random clouds in a box and in a mesh,
// and a scene mixing a mesh with box lattices.
#include <gtest/gtest.h>
#include <petscsys.h>

#include <cmath>
#include <string>

#include "io/gmsh_mesh.hpp"
#include "io/scene.hpp"
#include "partition/explicit_model.hpp"
#include "partition/local_model.hpp"
#include "src/model/body.hpp"
#include "tests/model_checks.hpp"
#include "tests/whole_body.hpp"

using namespace tissue;

namespace {

Built reference(const Scene& scene, MPI_Comm comm) {
  Body body = build_body(scene, read_mesh);
  PartitionStats stats;
  std::vector<int> part = partition_molecules(body, comm, stats, scene.partition.method);
  Built b;
  b.model = distribute(body, part, stats, comm, b.inputs);
  LocalModel& m = b.model;
  if (scene.partition.method == PartitionSpec::Method::ptscotch) {  // counted by build_local_model on the production path
    long cut = 0;
    for (int c : m.written_here()) cut += m.end_b[c] >= m.owned;
    MPI_Allreduce(&cut, &m.partition.edge_cut, 1, MPI_LONG, MPI_SUM, comm);
  }
  return b;
}

void expect_same_geometry(const BoxGeometry& x, const BoxGeometry& y) {
  EXPECT_EQ(x.n, y.n);
  EXPECT_EQ(x.h, y.h);
  EXPECT_EQ(x.offset, y.offset);
  EXPECT_EQ(x.topology, y.topology);
  EXPECT_EQ(x.first, y.first);
  EXPECT_EQ(x.radius, y.radius);
  EXPECT_EQ(x.count, y.count);
  EXPECT_EQ(x.total_volume, y.total_volume);
}

void expect_same(const Built& bx, const Built& by) {
  const LocalModel &x = bx.model, &y = by.model;
  const CalibrationInputs &xi = bx.inputs, &yi = by.inputs;
  expect_same_molecules(bx, by);
  EXPECT_EQ(x.partition.imbalance, y.partition.imbalance);
  EXPECT_EQ(x.partition.surface_to_volume, y.partition.surface_to_volume);
  EXPECT_EQ(x.forward_rank, y.forward_rank);
  EXPECT_EQ(x.table.rest_length_column().type, nullptr);  // one rest length a connection, as the reference
  for (int c = 0; c < x.connections(); ++c) ASSERT_EQ(x.l0(c), y.l0(c)) << "connection " << c;
  EXPECT_EQ(x.table.stiffness(), y.table.stiffness());
  // Explicit bodies' tetrahedra are summed from the same corners in the same order: bit for bit. A tetrahedral box
  // in the scene takes every Kuhn tetrahedron's volume as h_x h_y h_z / 6 (as the lattice path does), the
  // whole-body builder from each one's corners: round-off apart (tests/lattice_model_test.cpp).
  ASSERT_EQ(xi.tetra_volume.size(), yi.tetra_volume.size());
  ASSERT_EQ(xi.tetra_lloyd_sum.size(), yi.tetra_lloyd_sum.size());
  for (std::size_t c = 0; c < xi.tetra_volume.size(); ++c) {
    if (x.shape.part(x.id[x.end_a[c]]).unstructured()) {
      ASSERT_EQ(xi.tetra_volume[c], yi.tetra_volume[c]) << c;
      ASSERT_EQ(xi.tetra_lloyd_sum[c], yi.tetra_lloyd_sum[c]) << c;
    } else {
      ASSERT_NEAR(xi.tetra_volume[c], yi.tetra_volume[c], 1e-12 * std::fabs(yi.tetra_volume[c])) << c;
      ASSERT_NEAR(xi.tetra_lloyd_sum[c], yi.tetra_lloyd_sum[c], 1e-12 * std::fabs(yi.tetra_lloyd_sum[c])) << c;
    }
  }
  expect_same_geometry(x.shape, y.shape);
  ASSERT_EQ(x.shape.parts.size(), y.shape.parts.size());
  for (std::size_t b = 0; b < x.shape.parts.size(); ++b) expect_same_geometry(x.shape.parts[b], y.shape.parts[b]);
  ASSERT_EQ(x.shape.faces.size(), y.shape.faces.size());
  for (std::size_t f = 0; f < x.shape.faces.size(); ++f) {
    const NamedFace &p = x.shape.faces[f], &q = y.shape.faces[f];
    EXPECT_EQ(p.body, q.body);
    EXPECT_EQ(p.name, q.name);
    EXPECT_EQ(p.molecules, q.molecules);
    EXPECT_EQ(p.area, q.area);
    EXPECT_EQ(p.total_area, q.total_area);
    EXPECT_EQ(p.centroid, q.centroid);
    EXPECT_EQ(p.axis, q.axis);
    EXPECT_EQ(p.side, q.side);
    EXPECT_EQ(p.plane, q.plane);
    EXPECT_EQ(p.lattice, q.lattice);
    EXPECT_EQ(p.anchor, q.anchor);
    EXPECT_EQ(p.anchor2, q.anchor2);
    EXPECT_EQ(p.anchor2_component, q.anchor2_component);
  }
}

// Partition-free: each local molecule and connection, found by its global id in the whole body on one rank
// (`whole`: MPI_COMM_SELF, where local index = global id), carries the same numbers; the owned molecules of all
// ranks are every molecule once, with contiguous PETSc blocks; the ghosts are exactly the connections' ends
// owned elsewhere. PT-Scotch's partition differs from one call to the next (run_scripts/compare_binaries.sh), so
// this is what PT-Scotch runs are checked by.
void expect_consistent(const Built& bx, const Built& bw) {
  const LocalModel &x = bx.model, &whole = bw.model;
  const CalibrationInputs &xi = bx.inputs, &wi = bw.inputs;
  long long owned = x.owned, all = 0;
  MPI_Allreduce(&owned, &all, 1, MPI_LONG_LONG, MPI_SUM, x.comm);
  EXPECT_EQ(all, whole.global_molecules);
  EXPECT_EQ(x.global_connections, whole.global_connections);
  std::vector<char> end_here(x.local, 0);
  for (int i = 0; i < x.local; ++i) {
    const std::int64_t g = x.id[i];
    if (i < x.owned) EXPECT_EQ(x.block[i], x.first_block + i);
    if (i > 0 && i != x.owned) EXPECT_LT(x.id[i - 1], g);
    for (int d = 0; d < 3; ++d) ASSERT_EQ(x.rest[3 * i + d], whole.rest[3 * g + d]) << g;
    ASSERT_EQ(x.mass[i], whole.mass[g]) << g;
    ASSERT_EQ(xi.youngs_modulus[i], wi.youngs_modulus[g]) << g;
    ASSERT_EQ(xi.degree[i], wi.degree[g]) << g;
    ASSERT_EQ(x.body[i], whole.body[g]) << g;
    ASSERT_EQ(x.first_connection[i], whole.first_connection[g]) << g;
  }
  std::int64_t previous = -1;
  for (int c = 0; c < x.connections(); ++c) {
    const std::int64_t k = x.connection_id(c);
    ASSERT_GT(k, previous);
    previous = k;
    ASSERT_TRUE(x.end_a[c] < x.owned || x.end_b[c] < x.owned) << c;
    end_here[x.end_a[c]] = end_here[x.end_b[c]] = 1;
    ASSERT_EQ(x.id[x.end_a[c]], whole.id[whole.end_a[k]]) << c;
    ASSERT_EQ(x.id[x.end_b[c]], whole.id[whole.end_b[k]]) << c;
    ASSERT_EQ(x.connection_class[c], whole.connection_class[k]) << c;
    ASSERT_EQ(x.l0(c), whole.l0(k)) << c;
    const double tolerance = x.shape.part(x.id[x.end_a[c]]).unstructured() ? 0.0 : 1e-12;  // Kuhn: expect_same
    ASSERT_NEAR(xi.tetra_volume[c], wi.tetra_volume[k], tolerance * wi.tetra_volume[k]) << c;
    ASSERT_NEAR(xi.tetra_lloyd_sum[c], wi.tetra_lloyd_sum[k], tolerance * wi.tetra_lloyd_sum[k]) << c;
  }
  for (int i = x.owned; i < x.local; ++i) EXPECT_TRUE(end_here[i]) << "ghost " << x.id[i] << " of no connection";
}

std::string mesh_file(const std::string& name) { return std::string(TISSUE_SOURCE_DIR) + "/tests/meshes/" + name; }

const std::string dynamic = "[solver]\nkind = \"dynamic\"\nsteps = 1\n";

const std::string slab = dynamic + "[body]\nshape = \"mesh\"\nfile = \"" + mesh_file("two_layers.msh") + R"("
youngs_modulus = 1.0e5
density = 1000.0
offset = [0.1, -0.2, 0.3]
[[body.region]]
name = "surface"
youngs_modulus = 3.0e5
density = 1500.0
)";

const std::string random_box = dynamic + R"(
[body]
molecules = [6, 5, 5]
size = [1.0, 0.8, 0.8]
topology = "random"
seed = 7
youngs_modulus = 1.0e5
density = 1000.0
)";

const std::string random_in_l = dynamic + "[body]\nshape = \"mesh\"\nfile = \"" + mesh_file("l_shape.msh") +
                                "\"\ntopology = \"random\"\ninterior_molecules = 200\nseed = 3\n"
                                "youngs_modulus = 1.0e5\ndensity = 1000.0\n";

// A box, the slab, a tetrahedral box: explicit and stencil connections in one numbering.
const std::string mixed = dynamic + R"(
[[body]]
molecules = [4, 3, 5]
spacing = [0.1, 0.12, 0.09]
topology = "face-diagonals"
youngs_modulus = 2.0e5
density = 1000.0
[[body]]
shape = "mesh"
file = ")" + mesh_file("two_layers.msh") + R"("
offset = [2.0, 0.0, 0.0]
youngs_modulus = 1.0e5
density = 1000.0
[[body]]
molecules = [3, 4, 3]
spacing = [0.1, 0.1, 0.1]
offset = [4.0, 0.0, 0.0]
topology = "tetrahedral"
youngs_modulus = 1.0e5
density = 1000.0
)";

struct Case {
  const char* name;
  const std::string* text;
};
const Case cases[] = {{"slab", &slab}, {"random_box", &random_box}, {"random_in_l", &random_in_l}, {"mixed", &mixed}};

class EveryExplicitScene : public ::testing::TestWithParam<std::tuple<int, const char*>> {};

TEST_P(EveryExplicitScene, BlocksEqualWholeBody) {
  const Case& c = cases[std::get<0>(GetParam())];
  const Scene scene = parse_scene(*c.text, "explicit.toml", {std::string("partition.method=") + std::get<1>(GetParam())});
  Built built;
  built.model = build_local_model(scene, PETSC_COMM_WORLD, built.inputs, read_mesh);
  EXPECT_GT(built.model.connections(), 0);
  if (std::string(std::get<1>(GetParam())) == "metis") expect_same(built, reference(scene, PETSC_COMM_WORLD));
  const Body body = build_body(scene, read_mesh);
  Built whole;
  whole.model = distribute(body, std::vector<int>(body.molecules(), 0), PartitionStats{}, MPI_COMM_SELF, whole.inputs);
  expect_consistent(built, whole);
}

INSTANTIATE_TEST_SUITE_P(Scenes, EveryExplicitScene,
                         ::testing::Combine(::testing::Values(0, 1, 2, 3), ::testing::Values("metis", "ptscotch")));

// A bad mesh read on rank 0 alone is the same one-line InputError on every rank.
TEST(ExplicitModel, ReaderErrorOnEveryRank) {
  std::string text = slab;
  text.replace(text.find("\"surface\""), 9, "\"nowhere\"");
  const Scene scene = parse_scene(text, "explicit.toml");
  try {
    CalibrationInputs inputs;
    build_local_model(scene, PETSC_COMM_WORLD, inputs, read_mesh);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("body.region[0].name"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("no physical volume \"nowhere\""), std::string::npos) << e.what();
  }
}

}  // namespace
