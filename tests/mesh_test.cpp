// Explicit topologies end to end (shape = "mesh", topology = "random"), in process at 1, 2 and 3 ranks: the same
// answer as one rank (MPI_COMM_SELF, computed on every rank as the reference) to 1e-10; mass, volume and face
// areas against the closed forms of the slab the mesh fills; loads balanced by the reactions.
#include <gtest/gtest.h>
#include <petscsys.h>

#include <cmath>
#include <cstdio>
#include <fstream>

#include "io/gmsh_mesh.hpp"
#include "src/model/mesh_cloud.hpp"
#include "tests/pipeline.hpp"
#include "tests/whole_body.hpp"

using namespace tissue;
using tissue::test_pipeline::run;

namespace {

// tests/meshes/two_layers.geo: 1 x 1 x 0.5 m, "deep" below z = 0.25, "surface" above.
const std::string mesh_scene = std::string(R"(
title = "two-layer slab"
[body]
shape = "mesh"
file = ")") + TISSUE_SOURCE_DIR + R"(/tests/meshes/two_layers.msh"
youngs_modulus = 1.0e5
density = 1000.0
[[body.region]]
name = "surface"
youngs_modulus = 3.0e5
density = 1500.0
[calibration]
method = "tetrahedral"
[[fix]]
face = "bottom"
mode = "roller"
[[load]]
face = "top"
force = [0.0, 0.0, 20.0]
)";

const char* random_scene = R"(
title = "random box"
[body]
molecules = [6, 5, 5]
size = [1.0, 0.8, 0.8]
topology = "random"
seed = 7
youngs_modulus = 1.0e5
density = 1000.0
[calibration]
method = "tetrahedral"
[[fix]]
face = "x-"
mode = "roller"
[[load]]
face = "x+"
force = [10.0, 0.0, 0.0]
)";

// shape = "mesh", topology = "random": `count` molecules at random inside tests/meshes/`mesh`, rolled on `fixed`,
// pulled on `loaded`. No region, so mass = density * volume exactly (RandomInMesh.RegionsByCentroid adds one).
std::string cloud_scene(const std::string& mesh, long count, long seed, const std::string& fixed,
                        const std::string& loaded, const std::string& force) {
  return "[body]\nshape = \"mesh\"\nfile = \"" + std::string(TISSUE_SOURCE_DIR) + "/tests/meshes/" + mesh +
         "\"\ntopology = \"random\"\ninterior_molecules = " + std::to_string(count) + "\nseed = " +
         std::to_string(seed) + "\nyoungs_modulus = 1.0e5\ndensity = 1000.0\n[calibration]\nmethod = \"tetrahedral\"\n" +
         "[[fix]]\nface = \"" + fixed + "\"\nmode = \"roller\"\n[[load]]\nface = \"" + loaded + "\"\nforce = " + force + "\n";
}

// The slab's boundary nodes and 150 molecules inside.
const std::string slab_cloud_scene = cloud_scene("two_layers.msh", 150, 5, "bottom", "top", "[0.0, 0.0, 20.0]");
// The L (tests/meshes/l_shape.geo): non-convex, its Delaunay hull would fill the notch x > 0.5, y > 0.5.
const std::string l_cloud_scene = cloud_scene("l_shape.msh", 200, 3, "x-", "x+", "[10.0, 0.0, 0.0]");

// A box lattice (built rank by rank from its stencil) partitioned by PT-Scotch.
const char* lattice_scene = R"(
title = "box lattice, PT-Scotch"
[body]
molecules = [5, 4, 6]
spacing = [0.1, 0.12, 0.09]
topology = "face-diagonals"
youngs_modulus = 1.0e5
[[fix]]
face = "z+"
[[load]]
face = "z-"
force = [0.0, 0.0, -20.0]
[partition]
method = "ptscotch"
)";

double global_sum(double x) {
  double s = 0;
  MPI_Allreduce(&x, &s, 1, MPI_DOUBLE, MPI_SUM, PETSC_COMM_WORLD);
  return s;
}

// Parallel and one-rank runs of a scene: positions to 1e-10, E to 1e-9.
void same_on_any_rank_count(const std::string& scene, const std::string& kind, const std::string& method = "metis",
                            std::vector<std::string> set = {}) {
  set.insert(set.end(), {"solver.kind=" + kind, "partition.method=" + method,
                         kind == "static" ? "solver.tolerance=1e-12" : "solver.tolerance=1e-11"});
  auto parallel = run(scene, PETSC_COMM_WORLD, set);
  auto serial = run(scene, MPI_COMM_SELF, set);
  ASSERT_TRUE(parallel->report.converged && serial->report.converged) << kind;
  const double* xp = parallel->state->x.array();
  const double* xs = serial->state->x.array();  // one rank: local index == original id
  double worst = 0;
  for (int i = 0; i < parallel->model.owned; ++i) {
    const std::int64_t g = parallel->model.id[i];
    for (int d = 0; d < 3; ++d) worst = std::max(worst, std::fabs(xp[3 * i + d] - xs[3 * g + d]));
  }
  double all = 0;
  MPI_Allreduce(&worst, &all, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  EXPECT_LT(all, 1e-10) << kind;
  ASSERT_TRUE(parallel->measured.youngs_modulus && serial->measured.youngs_modulus);
  EXPECT_NEAR(*parallel->measured.youngs_modulus, *serial->measured.youngs_modulus,
              1e-9 * *serial->measured.youngs_modulus);
}

TEST(Mesh, SameAnswerOnAnyRankCount) {
  same_on_any_rank_count(mesh_scene, "static");
  same_on_any_rank_count(mesh_scene, "relaxation");
  same_on_any_rank_count(mesh_scene, "static", "ptscotch");  // PT-Scotch through PETSc's MatPartitioning
}

// PT-Scotch gives every rank molecules, and the edge cut it reports is the count of connections between ranks.
TEST(Mesh, PtscotchPartitionQuality) {
  auto r = run(mesh_scene, PETSC_COMM_WORLD, {"partition.method=ptscotch"}, /*do_solve=*/false);
  EXPECT_GT(r->model.owned, 0);
  long cut = 0;  // connections this rank holds whose ends are owned on different ranks, each counted by end a
  for (int c : r->model.written_here()) cut += r->model.end_b[c] >= r->model.owned;
  long total = 0;
  MPI_Allreduce(&cut, &total, 1, MPI_LONG, MPI_SUM, PETSC_COMM_WORLD);
  EXPECT_EQ(total, r->model.partition.edge_cut);
  EXPECT_LT(r->model.partition.imbalance, 1.2);
}

TEST(Lattice, PtscotchSameAnswerOnAnyRankCount) {
  same_on_any_rank_count(lattice_scene, "static", "ptscotch");
  auto r = run(lattice_scene, PETSC_COMM_WORLD, {}, /*do_solve=*/false);
  long cut = 0;  // the edge cut build_local_model counts for PT-Scotch on the lattice path: check it independently
  for (int c = 0; c < r->model.connections(); ++c)
    if (r->model.end_a[c] < r->model.owned && r->model.end_b[c] >= r->model.owned) ++cut;
  long total = 0;
  MPI_Allreduce(&cut, &total, 1, MPI_LONG, MPI_SUM, PETSC_COMM_WORLD);
  EXPECT_EQ(total, r->model.partition.edge_cut);
}

TEST(Random, SameAnswerOnAnyRankCount) { same_on_any_rank_count(random_scene, "static"); }

// Meshes through the Gmsh library (io/gmsh_mesh.cpp): the slab as binary MSH 4.1 and binary MSH 2.2 (made from
// two_layers.msh by the gmsh program, docs/mesh.md) gives the very TetMesh of the ASCII file: the same node order,
// positions, tetrahedra, regions and faces. Its .geo, meshed here, gives the same tetrahedra, regions and faces and
// the positions to 1e-15 m (the ASCII file rounds them to 16 digits).
bool same_topology(const TetMesh& a, const TetMesh& b) {
  if (a.tets != b.tets || a.tet_region != b.tet_region || a.region_names != b.region_names ||
      a.surfaces.size() != b.surfaces.size() || a.nodes.size() != b.nodes.size())
    return false;
  for (std::size_t i = 0; i < a.surfaces.size(); ++i)
    if (a.surfaces[i].name != b.surfaces[i].name || a.surfaces[i].triangles != b.surfaces[i].triangles) return false;
  return true;
}

TEST(Mesh, EveryGmshFormatGivesTheSameMesh) {
  const std::string dir = std::string(TISSUE_SOURCE_DIR) + "/tests/meshes/";
  const TetMesh ascii = read_gmsh(dir + "two_layers.msh");
  ASSERT_EQ(ascii.nodes.size(), 320u);
  ASSERT_EQ(ascii.tets.size(), 1081u);
  ASSERT_EQ(ascii.region_names, (std::vector<std::string>{"deep", "surface"}));
  ASSERT_EQ(ascii.surfaces.size(), 3u);  // bottom, top, west
  for (const char* binary : {"two_layers_bin41.msh", "two_layers_bin22.msh"}) {
    const TetMesh b = read_gmsh(dir + binary);
    EXPECT_TRUE(same_topology(ascii, b)) << binary;
    EXPECT_TRUE(ascii.nodes == b.nodes) << binary;  // bit for bit
  }
  const TetMesh geo = read_gmsh(dir + "two_layers.geo");  // meshed at run time, Mesh.MeshSizeMax from the .geo
  EXPECT_TRUE(same_topology(ascii, geo));
  double worst = 0;
  for (std::size_t i = 0; i < std::min(ascii.nodes.size(), geo.nodes.size()); ++i)
    for (int d = 0; d < 3; ++d) worst = std::max(worst, std::fabs(ascii.nodes[i][d] - geo.nodes[i][d]));
  EXPECT_LT(worst, 1e-15);
  // mesh_size caps the element size over the .geo's own (0.2 m): a finer mesh of the same slab.
  const TetMesh fine = read_gmsh(dir + "two_layers.geo", 0.1);
  EXPECT_GT(fine.tets.size(), 2 * ascii.tets.size());
  double volume = 0;
  for (const auto& t : fine.tets)
    volume += signed_volume(fine.nodes[t[0]], fine.nodes[t[1]], fine.nodes[t[2]], fine.nodes[t[3]]);
  EXPECT_NEAR(volume, 0.5, 1e-12);
}

// Gmsh's errors become one InputError naming the file, and leave nothing behind: the next read works.
TEST(Mesh, GmshErrorsBecomeInputErrors) {
  int rank = 0;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  const std::string bad = "gmsh_errors_test_" + std::to_string(rank) + ".geo";
  {
    std::ofstream out(bad);
    out << "Box(1) = {0, 0, 0, 1, 1;\n";  // a syntax error
  }
  try {
    read_gmsh(bad);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_EQ(what.rfind(bad + ": Gmsh cannot read it: ", 0), 0u) << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
  }
  std::remove(bad.c_str());
  EXPECT_EQ(read_gmsh(std::string(TISSUE_SOURCE_DIR) + "/tests/meshes/two_layers_bin41.msh").tets.size(), 1081u);
}

// The slab's closed forms: volume 0.5 m^3, mass 0.25 (1000 + 1500) kg, Eq. 3's l0 = 0.5 m and A = 1 m^2, the
// top's area 1 m^2 (a quarter of each tetrahedron per molecule and a third of each triangle cover them exactly).
TEST(Mesh, GeometryAgainstClosedForms) {
  auto r = run(mesh_scene, PETSC_COMM_WORLD, {}, /*do_solve=*/false);
  double m = 0;
  for (int i = 0; i < r->model.owned; ++i) m += r->model.mass[i];
  EXPECT_NEAR(global_sum(m), 0.25 * 1000.0 + 0.25 * 1500.0, 1e-10);
  EXPECT_NEAR(r->model.shape.total_volume, 0.5, 1e-12);
  ASSERT_TRUE(r->test.valid);
  EXPECT_NEAR(r->test.rest_length, 0.5, 1e-12);
  EXPECT_NEAR(r->test.cross_section, 1.0, 1e-12);
  const NamedFace* top = r->model.shape.named_face(0, "top");
  ASSERT_NE(top, nullptr);
  EXPECT_NEAR(top->total_area, 1.0, 1e-12);
  EXPECT_EQ(top->axis, 2);
  // Moduli: molecules strictly above the interface are "surface" (3e5), strictly below "deep" (1e5).
  for (int i = 0; i < r->model.local; ++i) {
    const double z = r->model.rest[3 * i + 2];
    if (z > 0.25 + 1e-9) EXPECT_EQ(r->inputs.youngs_modulus[i], 3.0e5);
    if (z < 0.25 - 1e-9) EXPECT_EQ(r->inputs.youngs_modulus[i], 1.0e5);
  }
}

// The applied loads sum to the scene's force, and at equilibrium the springs pass all of it to the held
// components: their connection forces sum to the load (the support's reaction is minus that).
TEST(Mesh, ReactionsBalanceTheLoad) {
  auto r = run(mesh_scene, PETSC_COMM_WORLD, {"solver.tolerance=1e-12"});
  ASSERT_TRUE(r->report.converged);
  std::vector<double> f(3 * r->model.local, 0.0);
  r->forces->connection_forces(r->state->x.array(), f.data());
  double applied[3] = {0, 0, 0}, reaction[3] = {0, 0, 0};
  const auto& held = r->forces->held();
  for (const auto& a : r->forces->applied()) applied[a.component % 3] += a.value;  // sparse: loaded only
  for (int i = 0; i < r->model.owned; ++i)
    for (int d = 0; d < 3; ++d)
      if (held[3 * i + d]) reaction[d] += f[3 * i + d];
  for (int d = 0; d < 3; ++d) {
    const double F = d == 2 ? 20.0 : 0.0;
    EXPECT_NEAR(global_sum(applied[d]), F, 1e-12);
    EXPECT_NEAR(global_sum(reaction[d]), F, 1e-8);
  }
}

// A box's six faces are lattice planes made with the box (lattice_faces: nothing per molecule); holds, loads and
// Eq. 3 read them as they read a mesh's faces. Reference: the same box handed in as a mesh (its Kuhn tetrahedra,
// each cell face split into two triangles), whose faces make_face builds from their triangles: the same molecules,
// the same total area, centroid, plane, axis, side and first roller anchor, and each molecule inside a face the
// same tributary area (six triangles of h_u h_v / 2, a third each).
TEST(Box, LatticeFacesAreTheFacesOfTheBoxAsAMesh) {
  BodySpec spec;
  spec.molecules = {4, 3, 5};
  spec.spacing = {0.5, 0.25, 0.2};
  spec.offset = {1.0, -2.0, 0.5};
  spec.topology = "tetrahedral";
  spec.youngs_modulus = 1.0e5;
  Scene scene;
  scene.file = "test";
  scene.body = spec;
  scene.bodies = {spec};
  const Body box = build_body(scene);
  ASSERT_FALSE(box.tetrahedra.empty());
  TetMesh mesh;
  for (std::int64_t id = 0; id < box.molecules(); ++id) {  // the mesh's own frame: build_unstructured adds the offset
    Vec3 x = box.rest_position(id);
    for (int d = 0; d < 3; ++d) x[d] -= spec.offset[d];
    mesh.nodes.push_back(x);
  }
  for (auto t : box.tetrahedra) {
    if (signed_volume(mesh.nodes[t[0]], mesh.nodes[t[1]], mesh.nodes[t[2]], mesh.nodes[t[3]]) < 0) std::swap(t[0], t[1]);
    mesh.tets.push_back(t);
  }
  const auto& n = spec.molecules;
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      TetMesh::Surface s;
      s.name = std::string(1, static_cast<char>('x' + axis)) + (side ? "+" : "-");
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      for (long a = 0; a + 1 < n[u]; ++a)
        for (long b = 0; b + 1 < n[v]; ++b) {
          std::array<std::int64_t, 4> q;
          for (int c = 0; c < 4; ++c) {
            std::array<long, 3> ijk{};
            ijk[axis] = side ? n[axis] - 1 : 0, ijk[u] = a + (c == 1 || c == 2), ijk[v] = b + (c >= 2);
            q[c] = box.id(ijk[0], ijk[1], ijk[2]);
          }
          s.triangles.push_back({q[0], q[1], q[2]});
          s.triangles.push_back({q[0], q[2], q[3]});
        }
      mesh.surfaces.push_back(s);
    }
  const Body as_mesh = build_unstructured(spec, mesh, 0, "test", "body");
  const std::vector<NamedFace> lattice = lattice_faces(body_geometry(spec, 0), 0);
  ASSERT_EQ(lattice.size(), 6u);
  for (const NamedFace& f : lattice) {
    const NamedFace* ref = as_mesh.named_face(0, f.name);
    ASSERT_NE(ref, nullptr) << f.name;
    EXPECT_TRUE(f.lattice);
    EXPECT_EQ(f.axis, ref->axis) << f.name;
    EXPECT_EQ(f.side, ref->side) << f.name;
    EXPECT_EQ(f.count(), ref->count()) << f.name;
    EXPECT_EQ(f.anchor, ref->anchor) << f.name;
    EXPECT_NEAR(f.total_area, ref->total_area, 1e-12) << f.name;
    EXPECT_NEAR(f.plane + spec.offset[f.axis], ref->plane, 1e-12) << f.name;  // a box's plane: in its own frame
    for (int d = 0; d < 3; ++d) EXPECT_NEAR(f.centroid[d], ref->centroid[d], 1e-12) << f.name;
    double sum = 0;
    for (std::int64_t id = 0; id < box.molecules(); ++id) {
      ASSERT_EQ(f.contains(id), ref->contains(id)) << f.name << " molecule " << id;
      if (!f.contains(id)) continue;
      sum += f.area_of(id);
      const auto ijk = box.index(id);
      const int u = (f.axis + 1) % 3, v = (f.axis + 2) % 3;
      if (ijk[u] > 0 && ijk[u] < n[u] - 1 && ijk[v] > 0 && ijk[v] < n[v] - 1)
        EXPECT_NEAR(f.area_of(id), ref->area_of(id), 1e-14) << f.name << " molecule " << id;
    }
    EXPECT_NEAR(sum, f.total_area, 1e-14) << f.name;
  }
}

// The random box fills its box: volume, faces as planes of the box's area, mass = density * volume, Eq. 3's l0
// and A the box's length and cross-section.
TEST(Random, FillsTheBox) {
  auto r = run(random_scene, PETSC_COMM_WORLD, {}, /*do_solve=*/false);
  EXPECT_NEAR(r->model.shape.total_volume, 0.64, 1e-12);
  double m = 0;
  for (int i = 0; i < r->model.owned; ++i) m += r->model.mass[i];
  EXPECT_NEAR(global_sum(m), 640.0, 1e-9);
  const double area[3] = {0.64, 0.8, 0.8};
  for (const char* name : {"x-", "x+", "y-", "y+", "z-", "z+"}) {
    const NamedFace* f = r->model.shape.named_face(0, name);
    ASSERT_NE(f, nullptr) << name;
    EXPECT_EQ(f->axis, name[0] - 'x') << name;
    EXPECT_NEAR(f->total_area, area[name[0] - 'x'], 1e-12) << name;
  }
  ASSERT_TRUE(r->test.valid);
  EXPECT_NEAR(r->test.rest_length, 1.0, 1e-12);
  EXPECT_NEAR(r->test.cross_section, 0.64, 1e-12);
  // The cloud has the lattice's count: boundary molecules plus (n - 2)^3 interior ones.
  EXPECT_EQ(r->model.global_molecules, 6 * 5 * 5);
}

// Random clouds in a mesh volume: every rank count ends a static tension solve at the one-rank positions.
TEST(RandomInMesh, SameAnswerOnAnyRankCount) {
  same_on_any_rank_count(slab_cloud_scene, "static");
  same_on_any_rank_count(l_cloud_scene, "static");
}

// Above 1000 molecules the static solver's default preconditioner would be the lattice multigrid, which an
// explicit topology (no lattice, a nominal 11^3 here) must not get: it falls back to GAMG, the same answer.
TEST(RandomInMesh, StaticSolveOfAThousandMolecules) {
  same_on_any_rank_count(slab_cloud_scene, "static", "metis", {"body.interior_molecules=1200"});
}

double tet_volume(const Body& b, const Tetrahedron& t) {
  return signed_volume(b.points[t[0]], b.points[t[1]], b.points[t[2]], b.points[t[3]]);
}

// The slab is convex: the carved Delaunay tetrahedra fill it exactly (0.5 m^3), the molecules are the slab's
// boundary nodes (counted here by position: on one of its six planes) plus the 150 asked for, and the mass is
// density * volume.
TEST(RandomInMesh, FillsTheSlab) {
  const Scene scene = parse_scene(slab_cloud_scene, "test.toml");
  const Body b = build_body(scene, read_mesh);
  const TetMesh slab = read_gmsh(scene.body.file);
  std::int64_t on_boundary = 0;
  for (const auto& x : slab.nodes)
    on_boundary += x[0] == 0 || x[0] == 1 || x[1] == 0 || x[1] == 1 || x[2] == 0 || x[2] == 0.5;
  EXPECT_EQ(b.molecules(), on_boundary + 150);
  double volume = 0, mass = 0;
  for (const auto& t : b.tetrahedra) volume += tet_volume(b, t);
  for (double m : b.mass) mass += m;
  EXPECT_NEAR(volume, 0.5, 1e-12);
  EXPECT_NEAR(b.total_volume, 0.5, 1e-12);
  EXPECT_NEAR(mass, 1000.0 * volume, 1e-9);
  // The interior molecules lie inside the slab, clear of its faces.
  for (std::int64_t i = on_boundary; i < b.molecules(); ++i) {
    const Vec3& x = b.points[i];
    EXPECT_TRUE(x[0] > 0 && x[0] < 1 && x[1] > 0 && x[1] < 1 && x[2] > 0 && x[2] < 0.5) << i;
  }
  // The named faces keep the mesh's molecules and areas: the top is 1 m^2, Eq. 3's l0 and A the slab's.
  const NamedFace* top = b.named_face(0, "top");
  ASSERT_NE(top, nullptr);
  EXPECT_NEAR(top->total_area, 1.0, 1e-12);
  for (auto id : top->molecules) EXPECT_EQ(b.points[id][2], 0.5);
  auto r = run(slab_cloud_scene, PETSC_COMM_WORLD, {}, /*do_solve=*/false);
  ASSERT_TRUE(r->test.valid);
  EXPECT_NEAR(r->test.rest_length, 0.5, 1e-12);
  EXPECT_NEAR(r->test.cross_section, 1.0, 1e-12);
}

// Each tetrahedron takes the physical volume holding its centroid ("surface" above z = 0.25): the mass is
// 1000 kg/m^3 times the volume below plus 1500 times the volume above, counted here from the centroids.
TEST(RandomInMesh, RegionsByCentroid) {
  const Scene scene = parse_scene(slab_cloud_scene + R"(
[[body.region]]
name = "surface"
youngs_modulus = 3.0e5
density = 1500.0
)", "test.toml");
  const Body b = build_body(scene, read_mesh);
  double below = 0, above = 0, mass = 0, longest = 0;
  for (const auto& t : b.tetrahedra) {
    double z = 0;
    for (auto v : t) z += 0.25 * b.points[v][2];
    (z > 0.25 ? above : below) += tet_volume(b, t);
  }
  for (double m : b.mass) mass += m;
  EXPECT_NEAR(mass, 1000.0 * below + 1500.0 * above, 1e-9);
  EXPECT_NEAR(above, 0.25, 0.03);  // tetrahedra straddle the interface: the split is the carving's, not exact
  // A molecule farther from the interface than the longest connection has all its tetrahedra on its side.
  for (const auto& c : b.connections) longest = std::max(longest, b.rest_distance(c.a, c.b));
  for (std::int64_t i = 0; i < b.molecules(); ++i) {
    const double z = b.points[i][2];
    if (z > 0.25 + longest) EXPECT_EQ(b.youngs_modulus[i], 3.0e5) << i;
    if (z < 0.25 - longest) EXPECT_EQ(b.youngs_modulus[i], 1.0e5) << i;
  }
}

// The L is not convex: no connection crosses the notch (its midpoint outside the L), the volume is the L's
// 0.3 m^3 (the hull's would be 0.35), and the mass density * volume.
TEST(RandomInMesh, NoConnectionAcrossTheNotch) {
  const Body b = build_body(parse_scene(l_cloud_scene, "test.toml"), read_mesh);
  std::int64_t outside = 0;
  for (const auto& c : b.connections) {
    Vec3 m;
    for (int d = 0; d < 3; ++d) m[d] = 0.5 * (b.points[c.a][d] + b.points[c.b][d]);
    outside += m[0] > 0.5 + 1e-12 && m[1] > 0.5 + 1e-12;
  }
  EXPECT_EQ(outside, 0);
  double volume = 0, mass = 0;
  for (const auto& t : b.tetrahedra) volume += tet_volume(b, t);
  for (double m : b.mass) mass += m;
  EXPECT_NEAR(volume, 0.3, 0.003);  // within 1 %: the carving's error along the notch
  EXPECT_NEAR(mass, 1000.0 * volume, 1e-9);
}

// The seed fixes the cloud: the same seed gives the same positions bit for bit, another seed other ones.
TEST(RandomInMesh, Seeded) {
  const Body a = build_body(parse_scene(l_cloud_scene, "test.toml"), read_mesh);
  const Body same = build_body(parse_scene(l_cloud_scene, "test.toml"), read_mesh);
  const Body other = build_body(parse_scene(l_cloud_scene, "test.toml", {"body.seed=4"}), read_mesh);
  ASSERT_EQ(a.points.size(), same.points.size());
  EXPECT_TRUE(a.points == same.points);
  EXPECT_TRUE(a.connections.size() == same.connections.size());
  EXPECT_FALSE(a.points == other.points);
}

// Two cubes apart: the Delaunay tetrahedra that join them have centroids in the gap, so the carved body falls in
// two pieces, which is refused (exit 2 in main), naming the key.
TEST(RandomInMesh, RefusesABodyInPieces) {
  TetMesh two;
  two.file = "two_cubes";
  for (int cube = 0; cube < 2; ++cube) {
    const std::int64_t first = static_cast<std::int64_t>(two.nodes.size());
    for (int k = 0; k < 2; ++k)
      for (int j = 0; j < 2; ++j)
        for (int i = 0; i < 2; ++i) two.nodes.push_back({i + 3.0 * cube, 1.0 * j, 1.0 * k});
    // The cube's 6 tetrahedra around its diagonal 0-7 (Kuhn), oriented positively.
    const int paths[6][2] = {{1, 3}, {1, 5}, {2, 3}, {2, 6}, {4, 5}, {4, 6}};
    for (const auto& p : paths) {
      std::array<std::int64_t, 4> t{first, first + p[0], first + p[1], first + 7};
      if (signed_volume(two.nodes[t[0]], two.nodes[t[1]], two.nodes[t[2]], two.nodes[t[3]]) < 0) std::swap(t[2], t[3]);
      two.tets.push_back(t);
    }
  }
  BodySpec spec;
  spec.shape = BodySpec::Shape::mesh;
  spec.topology = "random";
  spec.random = true;
  spec.interior_molecules = 16;
  try {
    random_in_mesh(two, spec, "scene.toml", "body");
    ADD_FAILURE() << "two cubes apart were accepted as one body";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("body.interior_molecules"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("2 pieces"), std::string::npos) << e.what();
  }
}

}  // namespace
