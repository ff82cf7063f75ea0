// NaturalOrder: items owned in a deliberately scrambled pattern arrive in id order, in balanced contiguous blocks,
// and come back unchanged. Run at 1, 2 and 3 ranks.
#include <gtest/gtest.h>
#include <mpi.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <stdexcept>

#include "partition/natural_order.hpp"

using tissue::NaturalOrder;

namespace {

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

// Ids owned by rank (id * 7) % size, listed in a seeded shuffle: neither contiguous nor sorted.
std::vector<int64_t> scrambled_ids(int64_t n, int rank, int size) {
  std::vector<int64_t> ids;
  for (int64_t id = 0; id < n; ++id)
    if ((id * 7) % size == rank) ids.push_back(id);
  std::mt19937 rng(1234 + rank);
  std::shuffle(ids.begin(), ids.end(), rng);
  return ids;
}

double value(int64_t id, int c) { return 1000.0 * id + c + 0.25 * std::sin(static_cast<double>(id)); }

}  // namespace

TEST(NaturalOrder, BalancedBlocksLikePetscDecide) {
  for (int64_t n : {0, 1, 2, 7, 10, 101}) {
    for (int p = 1; p <= 4; ++p) {
      int64_t expect = 0;
      for (int r = 0; r < p; ++r) {
        EXPECT_EQ(NaturalOrder::block_begin(n, p, r), expect);
        const int64_t len = n / p + (r < n % p ? 1 : 0);
        for (int64_t id = expect; id < expect + len; ++id) EXPECT_EQ(NaturalOrder::block_owner(n, p, id), r);
        expect += len;
      }
      EXPECT_EQ(NaturalOrder::block_begin(n, p, p), n);
    }
  }
}

TEST(NaturalOrder, ScrambledOwnershipArrivesInIdOrder) {
  const int rank = comm_rank(), size = comm_size();
  for (int64_t n : {1, 2, 5, 97}) {  // n < size leaves some ranks with an empty block
    const auto ids = scrambled_ids(n, rank, size);
    NaturalOrder order(MPI_COMM_WORLD, ids, n);
    EXPECT_EQ(order.global_count(), n);
    EXPECT_EQ(order.owned_count(), static_cast<int64_t>(ids.size()));
    EXPECT_EQ(order.begin(), NaturalOrder::block_begin(n, size, rank));
    EXPECT_EQ(order.end(), NaturalOrder::block_begin(n, size, rank + 1));

    // The blocks tile 0..n-1.
    long long count = order.count(), total = 0;
    MPI_Allreduce(&count, &total, 1, MPI_LONG_LONG, MPI_SUM, MPI_COMM_WORLD);
    EXPECT_EQ(total, n);

    const int w = 3;
    std::vector<double> mine(ids.size() * w);
    for (size_t i = 0; i < ids.size(); ++i)
      for (int c = 0; c < w; ++c) mine[i * w + c] = value(ids[i], c);
    const auto natural = order.to_natural(mine.data(), w);
    ASSERT_EQ(natural.size(), static_cast<size_t>(order.count() * w));
    for (int64_t row = 0; row < order.count(); ++row)
      for (int c = 0; c < w; ++c) EXPECT_EQ(natural[row * w + c], value(order.begin() + row, c)) << "row " << row;

    // And back: the caller's own order, bit for bit.
    const auto back = order.from_natural(natural.data(), w);
    EXPECT_EQ(back, mine);
  }
}

TEST(NaturalOrder, Int64EndpointsAndWidthOne) {
  const int rank = comm_rank(), size = comm_size();
  const int64_t n = 40;
  // Connections this time: owned by (id * 5 + 1) % size, in reverse order.
  std::vector<int64_t> ids;
  for (int64_t id = n - 1; id >= 0; --id)
    if ((id * 5 + 1) % size == rank) ids.push_back(id);
  NaturalOrder order(MPI_COMM_WORLD, ids, n);

  std::vector<int64_t> ends(ids.size() * 2);
  for (size_t i = 0; i < ids.size(); ++i) {
    ends[2 * i] = 3 * ids[i];
    ends[2 * i + 1] = 3 * ids[i] + 1 + (int64_t{1} << 40);  // beyond 32 bits on purpose
  }
  const auto natural = order.to_natural_ids(ends.data(), 2);
  ASSERT_EQ(natural.size(), static_cast<size_t>(order.count() * 2));
  for (int64_t row = 0; row < order.count(); ++row) {
    EXPECT_EQ(natural[2 * row], 3 * (order.begin() + row));
    EXPECT_EQ(natural[2 * row + 1], 3 * (order.begin() + row) + 1 + (int64_t{1} << 40));
  }
  EXPECT_EQ(order.from_natural_ids(natural.data(), 2), ends);

  std::vector<double> scalar(ids.size());
  for (size_t i = 0; i < ids.size(); ++i) scalar[i] = 0.5 * ids[i];
  const auto nat1 = order.to_natural(scalar.data(), 1);
  for (int64_t row = 0; row < order.count(); ++row) EXPECT_EQ(nat1[row], 0.5 * (order.begin() + row));
  EXPECT_EQ(order.from_natural(nat1.data(), 1), scalar);
}

TEST(NaturalOrder, RejectsIdsThatAreNotAPermutation) {
  const int rank = comm_rank(), size = comm_size();
  const int64_t n = 10;
  // Every rank claims id 0 as well as its own: at more than one rank, 0 is owned twice; at one, 0 is twice.
  auto ids = scrambled_ids(n, rank, size);
  ids.push_back(0);
  EXPECT_THROW(NaturalOrder(MPI_COMM_WORLD, ids, n), std::invalid_argument);
  // An id out of range.
  auto out = scrambled_ids(n, rank, size);
  if (rank == size - 1) out.push_back(n);
  EXPECT_THROW(NaturalOrder(MPI_COMM_WORLD, out, n), std::invalid_argument);
  // A missing id.
  auto missing = scrambled_ids(n, rank, size);
  missing.erase(std::remove(missing.begin(), missing.end(), int64_t{3}), missing.end());
  EXPECT_THROW(NaturalOrder(MPI_COMM_WORLD, missing, n), std::invalid_argument);
}
