// RowStream (io/row_stream.hpp): rows owned in a scrambled pattern, with slots a rank skips, written in pieces
// of 7 rows (many pieces, the last one short) must give the dataset the closed form says, row for row, the same
// as one whole-block write, and the row hash of the closed form; ids that are not an increasing permutation are
// refused on every rank. Run at 1, 2 and 3 ranks.
#include <gtest/gtest.h>
#include <mpi.h>

#include <cstdint>
#include <filesystem>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "io/hdf5_file.hpp"
#include "io/row_stream.hpp"
#include "partition/natural_order.hpp"

#ifndef TISSUE_TEST_OUT_DIR
#define TISSUE_TEST_OUT_DIR "tests/out"
#endif

using namespace tissue;

namespace {

constexpr std::int64_t N = 1000;
int rank_of(std::int64_t id, int size) { return static_cast<int>((id * 7919 + id / 13) % size); }
double value(std::int64_t id, int c) { return 3.0 * id + c + 0.25; }

int comm_size() {
  int s = 1;
  MPI_Comm_size(MPI_COMM_WORLD, &s);
  return s;
}
int comm_rank() {
  int r = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &r);
  return r;
}

// This rank's slots: its ids in increasing order, with a skipped slot (-1) after every third one.
std::vector<std::int64_t> slots() {
  std::vector<std::int64_t> s;
  for (std::int64_t id = 0; id < N; ++id)
    if (rank_of(id, comm_size()) == comm_rank()) {
      s.push_back(id);
      if (s.size() % 3 == 0) s.push_back(-1);
    }
  return s;
}

// The whole datasets the tests write, from the closed form: 3 values a row, and (id, -id).
std::vector<double> closed_form_values() {
  std::vector<double> v;
  for (std::int64_t id = 0; id < N; ++id)
    for (int c = 0; c < 3; ++c) v.push_back(value(id, c));
  return v;
}
std::vector<std::int64_t> closed_form_ids() {
  std::vector<std::int64_t> v;
  for (std::int64_t id = 0; id < N; ++id) v.push_back(id), v.push_back(-id);
  return v;
}

std::string path() {
  std::filesystem::create_directories(TISSUE_TEST_OUT_DIR);
  return std::string(TISSUE_TEST_OUT_DIR) + "/row_stream_np" + std::to_string(comm_size()) + ".h5";
}

}  // namespace

TEST(RowStream, PiecesGiveTheWholeBlockWrite) {
  const std::vector<std::int64_t> ids = slots();
  RowStream stream(MPI_COMM_WORLD, N, static_cast<std::int64_t>(ids.size()), [&](std::int64_t k) { return ids[k]; }, 7);
  EXPECT_EQ(stream.pieces(), (N + 6) / 7);
  Hdf5File f = Hdf5File::create(path(), MPI_COMM_WORLD);
  const std::uint64_t hash = stream.write_double(f, "/streamed", 3, [&](std::int64_t k, double* row) {
    for (int c = 0; c < 3; ++c) row[c] = value(ids[k], c);
  });
  const std::uint64_t hash_ids = stream.write_int64(f, "/ids", 2, [&](std::int64_t k, std::int64_t* row) {
    row[0] = ids[k], row[1] = -ids[k];
  });
  // The reference: this rank's balanced block from the closed form, one collective write.
  const std::int64_t first = NaturalOrder::block_begin(N, comm_size(), comm_rank()),
                     end = NaturalOrder::block_begin(N, comm_size(), comm_rank() + 1);
  std::vector<double> block;
  for (std::int64_t id = first; id < end; ++id)
    for (int c = 0; c < 3; ++c) block.push_back(value(id, c));
  f.write("/whole", N, 3, first, end - first, block.data());
  f.close();

  const std::vector<double> expected = closed_form_values();
  const std::vector<std::int64_t> expected_ids = closed_form_ids();
  EXPECT_EQ(hash, row_hash_sum(expected.data(), 3, N, 0));
  EXPECT_EQ(hash_ids, row_hash_sum(expected_ids.data(), 2, N, 0));
  Hdf5File h = Hdf5File::open(path(), MPI_COMM_WORLD, "file", nullptr);
  EXPECT_EQ(h.read_double("/streamed", 0, N), expected);
  EXPECT_EQ(h.read_double("/whole", 0, N), expected);
  EXPECT_EQ(h.read_int64("/ids", 0, N), expected_ids);
}

TEST(RowStream, RefusesIdsThatAreNotAnIncreasingPermutation) {
  // Rank 0 repeats its first id (at 1 rank: not increasing; else also a missing row): every rank throws.
  std::vector<std::int64_t> ids = slots();
  if (comm_rank() == 0) ids.insert(ids.begin() + 1, ids[0]);
  EXPECT_THROW(RowStream(MPI_COMM_WORLD, N, static_cast<std::int64_t>(ids.size()), [&](std::int64_t k) { return ids[k]; }),
               std::invalid_argument);
  // One id missing on the last rank: the row counts do not add up.
  ids = slots();
  if (comm_rank() == comm_size() - 1) ids.pop_back(), ids.pop_back();
  EXPECT_THROW(RowStream(MPI_COMM_WORLD, N, static_cast<std::int64_t>(ids.size()), [&](std::int64_t k) { return ids[k]; }),
               std::invalid_argument);
}

TEST(RowStream, ReadsBackInPieces) {
  // Written as the first test does, read back in pieces of 7 rows: every slot gets its row of the closed form,
  // and the row hash is the closed form's.
  const std::vector<std::int64_t> ids = slots();
  const std::string file = std::string(TISSUE_TEST_OUT_DIR) + "/row_stream_read_np" + std::to_string(comm_size()) + ".h5";
  std::filesystem::create_directories(TISSUE_TEST_OUT_DIR);
  RowStream stream(MPI_COMM_WORLD, N, static_cast<std::int64_t>(ids.size()), [&](std::int64_t k) { return ids[k]; }, 7);
  {
    Hdf5File f = Hdf5File::create(file, MPI_COMM_WORLD);
    stream.write_double(f, "/values", 3, [&](std::int64_t k, double* row) {
      for (int c = 0; c < 3; ++c) row[c] = value(ids[k], c);
    });
    stream.write_int64(f, "/ids", 2, [&](std::int64_t k, std::int64_t* row) { row[0] = ids[k], row[1] = -ids[k]; });
    stream.write_double(f, "/one_nan", 1, [&](std::int64_t k, double* row) {
      row[0] = ids[k] == N / 2 ? std::numeric_limits<double>::quiet_NaN() : 1.0;
    });
    f.close();
  }
  const std::vector<double> expected = closed_form_values();
  const std::vector<std::int64_t> expected_ids = closed_form_ids();
  Hdf5File h = Hdf5File::open(file, MPI_COMM_WORLD, "file", nullptr);
  std::int64_t wrong = 0, taken = 0, last = -1;
  RowStream::ReadCheck check = stream.read_double(h, "/values", 3, [&](std::int64_t k, const double* row) {
    wrong += k <= last || ids[k] < 0;
    last = k, ++taken;
    for (int c = 0; c < 3; ++c) wrong += row[c] != value(ids[k], c);
  });
  EXPECT_EQ(wrong, 0);
  std::int64_t mine = 0;
  for (std::int64_t i : ids) mine += i >= 0;
  EXPECT_EQ(taken, mine);
  EXPECT_EQ(check.hash, row_hash_sum(expected.data(), 3, N, 0));
  EXPECT_TRUE(check.finite);
  check = stream.read_int64(h, "/ids", 2, [&](std::int64_t k, const std::int64_t* row) {
    wrong += row[0] != ids[k] || row[1] != -ids[k];
  });
  EXPECT_EQ(wrong, 0);
  EXPECT_EQ(check.hash, row_hash_sum(expected_ids.data(), 2, N, 0));

  // Shared: every rank wants every fifth row and the last one (all ranks the same rows), pieces of 64.
  std::vector<std::int64_t> every_fifth;
  for (std::int64_t id = 0; id < N; id += 5) every_fifth.push_back(id);
  every_fifth.push_back(N - 1);
  const RowStream shared(MPI_COMM_WORLD, N, static_cast<std::int64_t>(every_fifth.size()),
                         [&](std::int64_t k) { return every_fifth[k]; }, RowStream::Shared{}, 64);
  taken = 0;
  check = shared.read_double(h, "/values", 3, [&](std::int64_t k, const double* row) {
    ++taken;
    for (int c = 0; c < 3; ++c) wrong += row[c] != value(every_fifth[k], c);
  });
  EXPECT_EQ(wrong, 0);
  EXPECT_EQ(taken, static_cast<std::int64_t>(every_fifth.size()));
  EXPECT_EQ(check.hash, row_hash_sum(expected.data(), 3, N, 0));
  // A NaN in one row is seen by whichever rank reads it, and reported on every rank.
  check = shared.read_double(h, "/one_nan", 1, [](std::int64_t, const double*) {});
  EXPECT_FALSE(check.finite);
  // A shared stream writes nothing; ids out of range are refused on every rank.
  EXPECT_THROW(RowStream(MPI_COMM_WORLD, N, 1, [&](std::int64_t) { return comm_rank() == 0 ? N : 0; },
                         RowStream::Shared{}),
               std::invalid_argument);
  h.close();
}
