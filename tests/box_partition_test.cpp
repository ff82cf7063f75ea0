// partition.method = "blocks" (partition/box_bisection.hpp): the bisection of a box lattice's index box against
// closed forms (every molecule in one part, the balance, the slab cut's connection count), against a count over
// the whole body's connection list, and the runs it partitions against the same runs partitioned by METIS
// (another partition: equal to round-off). At 1, 2 and 3 ranks.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "io/scene.hpp"
#include "partition/box_bisection.hpp"
#include "partition/natural_order.hpp"
#include "tests/pipeline.hpp"
#include "tests/whole_body.hpp"

using namespace tissue;
using tissue::test_pipeline::gather_positions;
using tissue::test_pipeline::run;

namespace {

int world_size() {
  int s;
  MPI_Comm_size(PETSC_COMM_WORLD, &s);
  return s;
}

std::string box_scene(long nx, long ny, long nz, const std::string& topology) {
  return "[solver]\nkind = \"dynamic\"\nsteps = 1\ntime_step = 1e-6\n[body]\nmolecules = [" + std::to_string(nx) + ", " +
         std::to_string(ny) + ", " + std::to_string(nz) + "]\nspacing = [0.1, 0.12, 0.09]\ntopology = \"" + topology +
         "\"\nyoungs_modulus = 1.0e5\n";
}

// The boxes tile the lattice: every index in exactly one; the largest part within the bound the cuts allow.
TEST(BisectBox, TilesTheBoxAndBalances) {
  for (const std::array<long, 3> n : {std::array<long, 3>{100, 100, 100}, {200, 200, 20}, {5, 4, 6}, {40, 40, 40}, {7, 3, 11}})
    for (int parts : {1, 2, 3, 4, 5, 6, 7, 8}) {
      const std::vector<IndexBox> boxes = bisect_box(n, parts);
      ASSERT_EQ(static_cast<int>(boxes.size()), parts);
      std::vector<int> hits(n[0] * n[1] * n[2], 0);
      std::int64_t largest = 0;
      for (const IndexBox& b : boxes) {
        ASSERT_GT(b.molecules(), 0);
        largest = std::max(largest, b.molecules());
        for (long z = b.lo[2]; z < b.hi[2]; ++z)
          for (long y = b.lo[1]; y < b.hi[1]; ++y)
            for (long x = b.lo[0]; x < b.hi[0]; ++x) ++hits[x + n[0] * (y + n[1] * z)];
      }
      for (int h : hits) ASSERT_EQ(h, 1);
      // Each cut rounds its plane count to a whole plane: at most 1/k1 plane per part too many below it, so with
      // P planes along the cut axis a part is at most (1 + k / P) of its share, compounded over the levels.
      // On the large boxes below, 1.3 % (METIS's tolerance is 0.1 %).
      const double mean = static_cast<double>(n[0] * n[1] * n[2]) / parts;
      if (n[0] >= 40 && n[2] >= 20) {
        EXPECT_LE(largest, 1.013 * mean) << n[0] << "x" << n[1] << "x" << n[2] << " / " << parts;
      }
      if (parts == 2 || parts == 4 || parts == 8)
        if (n[0] % 2 == 0 && n[1] % 2 == 0 && n[2] % 4 == 0 && n[0] >= 40) EXPECT_EQ(largest, mean);
    }
}

// Two parts of a cube: two slabs across z, ids [0, N/2) and [N/2, N) (each rank's molecules contiguous).
TEST(BisectBox, TwoPartsOfACubeAreSlabsOfContiguousIds) {
  const std::vector<IndexBox> b = bisect_box({10, 10, 10}, 2);
  EXPECT_EQ(b[0].lo, (std::array<long, 3>{0, 0, 0}));
  EXPECT_EQ(b[0].hi, (std::array<long, 3>{10, 10, 5}));
  EXPECT_EQ(b[1].lo, (std::array<long, 3>{0, 0, 5}));
  EXPECT_EQ(b[1].hi, (std::array<long, 3>{10, 10, 10}));
}

// The parts every rank computes (from its block of the natural order) against the whole vector one rank computes
// alone, and the edge cut against the whole body's connections with both ends' parts compared.
TEST(BoxBisection, EdgeCutAndPartsOnAnyRankCount) {
  const int size = world_size();
  for (const std::string topology : {"rectangular", "face-diagonals", "body-diagonals", "tetrahedral"})
    for (int parts : {2, 3, 4, 8}) {
      const Scene scene = parse_scene(box_scene(9, 8, 10, topology), "box.toml");
      const Body body = build_body(scene);
      PartitionStats alone, here;
      const std::vector<int> all = partition_box_bisection(body, PETSC_COMM_SELF, parts, alone);
      ASSERT_EQ(static_cast<std::int64_t>(all.size()), body.molecules());
      const std::vector<int> mine = partition_box_bisection(body, PETSC_COMM_WORLD, parts, here);
      int rank;
      MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
      const std::int64_t begin = NaturalOrder::block_begin(body.molecules(), size, rank);
      for (std::size_t i = 0; i < mine.size(); ++i) ASSERT_EQ(mine[i], all[begin + i]);
      long cut = 0;
      for (const auto& c : body.connections) cut += all[c.a] != all[c.b];
      EXPECT_EQ(here.edge_cut, cut) << topology << " " << parts;
      EXPECT_EQ(alone.edge_cut, cut) << topology << " " << parts;
      std::vector<long> count(parts, 0);
      for (int p : all) ++count[p];
      EXPECT_DOUBLE_EQ(here.imbalance, static_cast<double>(*std::max_element(count.begin(), count.end())) * parts /
                                           body.molecules());
    }
}

// The slab cut's closed form: a face-diagonals lattice cut between two z planes loses the nx ny axial
// connections, the 2 (nx - 1) ny and 2 nx (ny - 1) diagonal ones of the xz and yz faces.
TEST(BoxBisection, SlabCutClosedForm) {
  for (const std::array<long, 3> n : {std::array<long, 3>{40, 40, 40}, {12, 9, 30}}) {
    const Scene scene = parse_scene(box_scene(n[0], n[1], n[2], "face-diagonals"), "box.toml");
    PartitionStats stats;
    (void)partition_box_bisection(scene_shape(scene), PETSC_COMM_WORLD, 2, stats);
    EXPECT_EQ(stats.edge_cut, n[0] * n[1] + 2 * (n[0] - 1) * n[1] + 2 * n[0] * (n[1] - 1));
    EXPECT_DOUBLE_EQ(stats.imbalance, 1.0);
  }
}

// The model build keeps the bisection: on this lattice (12 planes: even parts at 1, 2 and 3 ranks) every molecule
// sits on the rank of its box. Where the bisection is out of balance (7 planes in 2 parts: 4/3.5), "auto" is METIS.
TEST(BoxBisection, AutoIsBlocksOnOneBoxAndMetisElsewhere) {
  const std::string text = box_scene(6, 5, 12, "face-diagonals");
  auto automatic = run(text, PETSC_COMM_WORLD, {}, /*do_solve=*/false);
  EXPECT_DOUBLE_EQ(automatic->model.partition.imbalance, 1.0);
  const std::vector<IndexBox> boxes = bisect_box({6, 5, 12}, world_size());
  int rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  const IndexBox& b = boxes[rank];
  ASSERT_EQ(automatic->model.owned, b.molecules());
  for (int i = 0; i < automatic->model.owned; ++i) {
    const auto ijk = automatic->model.shape.body(0).index(automatic->model.id[i]);
    for (int d = 0; d < 3; ++d) ASSERT_TRUE(ijk[d] >= b.lo[d] && ijk[d] < b.hi[d]);
  }
  const std::string odd = box_scene(5, 4, 7, "face-diagonals");
  auto odd_auto = run(odd, PETSC_COMM_WORLD, {}, false), odd_metis = run(odd, PETSC_COMM_WORLD, {"partition.method=metis"}, false);
  const Body odd_shape = scene_shape(parse_scene(odd, "odd.toml"));
  EXPECT_EQ(box_bisection_chosen(odd_shape, PartitionSpec::Method::automatic, world_size()), world_size() == 1);
  if (world_size() == 2) EXPECT_DOUBLE_EQ(box_bisection_imbalance(odd_shape, 2), 4.0 / 3.5);
  EXPECT_EQ(odd_auto->model.partition.edge_cut, odd_metis->model.partition.edge_cut);
  EXPECT_EQ(odd_auto->model.owned, odd_metis->model.owned);
  EXPECT_THROW(parse_scene(text + "[[body]]\nmolecules = [2, 2, 2]\n[partition]\nmethod = \"blocks\"\n", "two.toml"),
               InputError);
}

const char* tension = R"(
title = "box lattice, blocks against METIS"
[body]
molecules = [6, 5, 9]
spacing = [0.1, 0.12, 0.09]
topology = "face-diagonals"
youngs_modulus = 1.0e5
[[fix]]
face = "z+"
[[load]]
face = "z-"
force = [0.0, 0.0, -20.0]
)";

// Another partition, the same answer: static (to 1e-12) and dynamic (20 steps) runs, blocks against METIS.
TEST(BoxBisection, SameResultsAsMetis) {
  for (const std::vector<std::string> kind :
       {std::vector<std::string>{"solver.kind=static", "solver.tolerance=1e-12"},
        std::vector<std::string>{"solver.kind=dynamic", "solver.steps=20", "solver.time_step=1e-4"}}) {
    std::vector<std::string> blocks = kind, metis = kind;
    blocks.push_back("partition.method=blocks");
    metis.push_back("partition.method=metis");
    auto a = run(tension, PETSC_COMM_WORLD, blocks), b = run(tension, PETSC_COMM_WORLD, metis);
    ASSERT_TRUE(a->report.converged && b->report.converged) << kind[0];
    const std::vector<double> xa = gather_positions(*a), xb = gather_positions(*b);
    double worst = 0, scale = 0;
    for (std::size_t k = 0; k < xa.size(); ++k) worst = std::max(worst, std::fabs(xa[k] - xb[k])), scale = std::max(scale, std::fabs(xb[k]));
    EXPECT_LT(worst, 1e-12 * scale) << kind[0];
    if (a->measured.youngs_modulus && b->measured.youngs_modulus) {
      EXPECT_NEAR(*a->measured.youngs_modulus, *b->measured.youngs_modulus, 1e-9 * *b->measured.youngs_modulus);
    }
  }
}

}  // namespace
