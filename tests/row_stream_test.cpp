// RowStream (io/row_stream.hpp): rows owned in a scrambled pattern, with slots a rank skips, written in pieces
// of 7 rows (many pieces, the last one short) must give the dataset the closed form says, row for row, the same
// as one whole-block write, and the row hash of the closed form; ids that are not an increasing permutation are
// refused on every rank. Run at 1, 2 and 3 ranks.
#include <gtest/gtest.h>
#include <mpi.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <algorithm>
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

namespace {
// FNV-1a, one byte at a time: the reference for the writer's interleaved hashes.
std::uint64_t fnv1a(std::uint64_t h, const void* p, std::size_t n) {
  const unsigned char* b = static_cast<const unsigned char*>(p);
  for (std::size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ULL;
  return h;
}
constexpr std::uint64_t kFnvBasis = 1469598103934665603ULL;

// The seal line a file of these bytes must start with: the sum over 1 MiB blocks after the 512-byte user block of
// FNV-1a(block offset, block bytes), computed here byte by byte (the writer hashes while it writes).
std::string expected_seal(const std::vector<unsigned char>& bytes) {
  const std::size_t user_block = 512, block = std::size_t{1} << 20;
  std::uint64_t sum = 0;
  for (std::size_t offset = user_block; offset < bytes.size(); offset += block) {
    const std::uint64_t at = offset;
    unsigned char le[8];
    for (int i = 0; i < 8; ++i) le[i] = static_cast<unsigned char>((at >> (8 * i)) & 0xff);
    sum += fnv1a(fnv1a(kFnvBasis, le, 8), &bytes[offset], std::min(block, bytes.size() - offset));
  }
  char header[128];
  std::snprintf(header, sizeof header, "TISSUE-HDF5-SEAL 1 %zu %016llx\n", bytes.size(),
                static_cast<unsigned long long>(sum));
  return header;
}

// A file that `stream` (slots `ids`, a negative id: a slot not written) wrote with rows 0..rows-1 of the closed form,
// 3 values a row in /values and (id, -id) in /ids, with the writer's row hashes `hash` and `hash_ids`: the hashes are
// the closed form's, the datasets read back whole equal it, and so do the rows read back through the stream (a
// skipped slot is never read). Every rank checks; rank 0 removes the file.
void expect_closed_form_file(const RowStream& stream, const std::vector<std::int64_t>& ids, const std::string& file,
                             std::int64_t rows, std::uint64_t hash, std::uint64_t hash_ids) {
  std::vector<double> expected;
  std::vector<std::int64_t> expected_ids;
  for (std::int64_t id = 0; id < rows; ++id) {
    for (int c = 0; c < 3; ++c) expected.push_back(value(id, c));
    expected_ids.push_back(id), expected_ids.push_back(-id);
  }
  EXPECT_EQ(hash, row_hash_sum(expected.data(), 3, rows, 0)) << file;
  EXPECT_EQ(hash_ids, row_hash_sum(expected_ids.data(), 2, rows, 0)) << file;
  Hdf5File h = Hdf5File::open(file, MPI_COMM_WORLD, "file", nullptr);
  EXPECT_EQ(h.read_double("/values", 0, rows), expected) << file;
  EXPECT_EQ(h.read_int64("/ids", 0, rows), expected_ids) << file;
  int wrong = 0;
  const RowStream::ReadCheck check = stream.read_double(h, "/values", 3, [&](std::int64_t k, const double* row) {
    for (int c = 0; c < 3; ++c) wrong += ids[k] < 0 || row[c] != value(ids[k], c);
  });
  EXPECT_EQ(wrong, 0) << file;
  EXPECT_EQ(check.hash, hash) << file;
  h.close();
  MPI_Barrier(MPI_COMM_WORLD);
  if (comm_rank() == 0) std::filesystem::remove(file);
}
}  // namespace

// The row hash (hashed four rows side by side) is the sum of each row's FNV-1a(row index, row bytes), for any row
// count (whole groups of four and a remainder) and first row.
TEST(RowStream, RowHashIsEachRowsFnv1a) {
  std::vector<double> values(3 * 11);
  std::vector<std::int64_t> ints(2 * 11);
  for (std::size_t i = 0; i < values.size(); ++i) values[i] = 0.1 * static_cast<double>(i) - 1.0;
  for (std::size_t i = 0; i < ints.size(); ++i) ints[i] = static_cast<std::int64_t>(i * i) - 7;
  for (std::int64_t count = 0; count <= 11; ++count)
    for (std::int64_t first : {std::int64_t{0}, std::int64_t{5}, std::int64_t{1} << 40}) {
      std::uint64_t want = 0, want_ints = 0;
      for (std::int64_t r = 0; r < count; ++r) {
        const std::int64_t row = first + r;
        want += fnv1a(fnv1a(kFnvBasis, &row, sizeof row), &values[3 * r], 3 * sizeof(double));
        want_ints += fnv1a(fnv1a(kFnvBasis, &row, sizeof row), &ints[2 * r], 2 * sizeof(std::int64_t));
      }
      EXPECT_EQ(row_hash_sum(values.data(), 3, count, first), want) << count << " rows from " << first;
      EXPECT_EQ(row_hash_sum(ints.data(), 2, count, first), want_ints) << count << " rows from " << first;
    }
}

// A file of 48 MiB: its seal equals the sum over 1 MiB blocks of FNV-1a(block offset, block bytes), computed here
// from the bytes on disk, in both layouts: each rank's rows one run (every block but those at the ranks' and the
// datasets' boundaries hashed as it is written, io/file_seal.hpp) and rows scrambled among the ranks (each rank
// writes a part of every piece: at several ranks the blocks across parts are hashed by the re-read at close).
// The file's page cache is dropped as it is written: the reader's check and the values read back come from the
// disk. A stream asked for no checksum returns 0.
TEST(RowStream, SealIsTheBlockHashOfEveryByte) {
  const std::int64_t rows = std::int64_t{1} << 21;
  const int size = comm_size(), rank = comm_rank();
  for (const bool runs : {true, false}) {
    std::vector<std::int64_t> ids;
    for (std::int64_t id = 0; id < rows; ++id)
      if ((runs ? NaturalOrder::block_owner(rows, size, id) : rank_of(id, size)) == rank) ids.push_back(id);
    const RowStream stream(MPI_COMM_WORLD, rows, static_cast<std::int64_t>(ids.size()),
                           [&](std::int64_t k) { return ids[static_cast<std::size_t>(k)]; });
    const std::string file = std::string(TISSUE_TEST_OUT_DIR) + "/row_stream_seal_np" + std::to_string(size) +
                             (runs ? "_runs" : "_scrambled") + ".h5";
    Hdf5File f = Hdf5File::create(file, MPI_COMM_WORLD);
    const std::uint64_t hash = stream.write_double(
        f, "/values", 3,
        [&](std::int64_t k, double* row) {
          for (int c = 0; c < 3; ++c) row[c] = std::sqrt(static_cast<double>(3 * ids[static_cast<std::size_t>(k)] + c));
        },
        RowStream::Checksum::skip);
    EXPECT_EQ(hash, 0u);
    // Rows of 8 and 16 bytes too: scrambled, each rank's part of a piece is a MiB or less at 2 and 3 ranks, so
    // most seal blocks lie across two ranks' parts and are hashed at close; in runs, nearly all as written.
    stream.write_int64(f, "/ids", 1, [&](std::int64_t k, std::int64_t* row) { row[0] = ids[static_cast<std::size_t>(k)]; },
                       RowStream::Checksum::skip);
    stream.write_int64(f, "/pairs", 2, [&](std::int64_t k, std::int64_t* row) {
      row[0] = ids[static_cast<std::size_t>(k)], row[1] = -3 * ids[static_cast<std::size_t>(k)];
    }, RowStream::Checksum::skip);
    f.close();
    RowStream::release();
    if (rank == 0) {
      std::ifstream in(file, std::ios::binary);
      const std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      ASSERT_GT(bytes.size(), std::size_t{96} << 20);
      const std::string header = expected_seal(bytes);
      EXPECT_EQ(std::string(bytes.begin(), bytes.begin() + static_cast<long>(header.size())), header)
          << (runs ? "runs" : "scrambled");
    }
    Hdf5File h = Hdf5File::open(file, MPI_COMM_WORLD, "file", nullptr);  // the seal checked by the reader too
    for (const std::int64_t row : {std::int64_t{0}, rows / 3, rows - 1}) {
      const std::vector<double> back = h.read_double("/values", row, 1);
      ASSERT_EQ(back.size(), 3u);
      for (int c = 0; c < 3; ++c) EXPECT_EQ(back[c], std::sqrt(static_cast<double>(3 * row + c))) << row;
    }
    // Every row of every dataset, this rank's share of the file (the parts that wrote them were not the reader's).
    const std::int64_t first = NaturalOrder::block_begin(rows, size, rank), end = NaturalOrder::block_begin(rows, size, rank + 1);
    const std::vector<double> values = h.read_double("/values", first, end - first);
    const std::vector<std::int64_t> own = h.read_int64("/ids", first, end - first), pairs = h.read_int64("/pairs", first, end - first);
    std::int64_t wrong = 0;
    for (std::int64_t i = 0; i < end - first; ++i) {
      const std::int64_t id = first + i;
      for (int c = 0; c < 3; ++c) wrong += values[3 * i + c] != std::sqrt(static_cast<double>(3 * id + c));
      wrong += own[i] != id, wrong += pairs[2 * i] != id || pairs[2 * i + 1] != -3 * id;
    }
    EXPECT_EQ(wrong, 0) << (runs ? "runs" : "scrambled");
    h.close();
    if (rank == 0) std::filesystem::remove(file);
  }
}

// The batched forms (a stream of batched ids, rows a batch at a time) against the closed form and the row hash,
// in the two layouts: ids scrambled among the ranks (the even split, rows exchanged) and each rank's ids one run
// in rank order (parts aligned with the ranks' own rows: nothing exchanged), each with and without skipped slots
// (a batch of consecutive ids goes straight into the piece; a skipped slot's row, NaN here, must be dropped).
// 10,000 rows in pieces of 9,000: batches of kBatch slots cut inside a part. Read back through the same stream.
// Pieces of 1,234 rows too: each rank's own rows in several pieces of its own (runs of uneven length, rank r holding
// a share proportional to r + 1: the ranks with fewer pieces take part in the others' last ones with none).
TEST(RowStream, BatchedRowsInBothLayouts) {
  constexpr std::int64_t rows = 10000;
  const int size = comm_size(), rank = comm_rank();
  auto uneven_owner = [&](std::int64_t id) {
    int r = 0;
    while (r + 1 < size && rows * (r + 1) * (r + 2) / (size * (size + 1)) <= id) ++r;
    return r;
  };
  for (const std::int64_t piece : {std::int64_t{9000}, std::int64_t{1234}})
  for (const bool runs : {false, true})
    for (const bool skips : {false, true}) {
      std::vector<std::int64_t> ids;
      for (std::int64_t id = 0; id < rows; ++id) {
        const int owner = runs ? (piece == 9000 ? NaturalOrder::block_owner(rows, size, id) : uneven_owner(id))
                               : rank_of(id, size);
        if (owner != rank) continue;
        ids.push_back(id);
        if (skips && ids.size() % 5 == 0) ids.push_back(-1);
      }
      int batches = 0;
      RowStream stream(
          MPI_COMM_WORLD, rows, static_cast<std::int64_t>(ids.size()),
          [&](std::int64_t first, std::int64_t end, std::int64_t* out) {
            ASSERT_LE(end - first, RowStream::kBatch);
            ++batches;
            std::copy(ids.begin() + first, ids.begin() + end, out);
          },
          RowStream::Batched{}, piece);
      EXPECT_EQ(stream.own_parts(), runs && size > 1);
      const std::string file =
          path() + (runs ? ".runs" : ".scrambled") + (skips ? ".skips" : "") + ".piece" + std::to_string(piece);
      Hdf5File f = Hdf5File::create(file, MPI_COMM_WORLD);
      const std::uint64_t hash = stream.write_double_rows(
          f, "/values", 3, [&](std::int64_t first, std::int64_t end, const std::int64_t* batch_ids, double* out) {
            for (std::int64_t k = first; k < end; ++k) {
              EXPECT_EQ(batch_ids[k - first], ids[k]);
              for (int c = 0; c < 3; ++c)
                out[3 * (k - first) + c] = ids[k] < 0 ? std::nan("") : value(ids[k], c);
            }
          });
      const std::uint64_t hash_ids = stream.write_int64_rows(
          f, "/ids", 2, [&](std::int64_t first, std::int64_t end, const std::int64_t*, std::int64_t* out) {
            for (std::int64_t k = first; k < end; ++k) out[2 * (k - first)] = ids[k], out[2 * (k - first) + 1] = -ids[k];
          });
      f.close();
      RowStream::release();
      EXPECT_GT(batches, 0);
      expect_closed_form_file(stream, ids, file, rows, hash, hash_ids);
    }
}

// A rank whose slots are consecutive ids, every one written, may say so (RowStream::Consecutive) instead of listing
// them: the file, its row hash and the rows read back are the closed form's, whatever the other ranks do (their
// ids listed, or consecutive too), with the ranks' ranges in rank order (each rank writes its own rows) or not
// (rows exchanged), in pieces of several sizes; a range outside the dataset is refused on every rank.
TEST(RowStream, ConsecutiveIdsWriteAsTheirList) {
  constexpr std::int64_t rows = 10000;
  const int size = comm_size(), rank = comm_rank();
  for (const std::int64_t piece : {std::int64_t{9000}, std::int64_t{1234}, std::int64_t{7}})
    for (const bool reversed : {false, true})
      for (const bool listed_elsewhere : {false, true}) {
        // Rank r holds the balanced block of rank r, or of rank size - 1 - r (the blocks out of rank order).
        const int block = reversed ? size - 1 - rank : rank;
        const std::int64_t first = NaturalOrder::block_begin(rows, size, block),
                           end = NaturalOrder::block_begin(rows, size, block + 1);
        std::vector<std::int64_t> ids;
        for (std::int64_t id = first; id < end; ++id) ids.push_back(id);
        const bool consecutive = !listed_elsewhere || rank == 0;
        const RowStream stream =
            consecutive ? RowStream(MPI_COMM_WORLD, rows, end - first, RowStream::Consecutive{first}, piece)
                        : RowStream(MPI_COMM_WORLD, rows, end - first,
                                    [&](std::int64_t k0, std::int64_t k1, std::int64_t* out) {
                                      std::copy(ids.begin() + k0, ids.begin() + k1, out);
                                    },
                                    RowStream::Batched{}, piece);
        EXPECT_EQ(stream.own_parts(), size > 1 && !reversed);
        const std::string file = path() + ".consecutive" + (reversed ? ".reversed" : "") +
                                 (listed_elsewhere ? ".listed" : "") + ".piece" + std::to_string(piece);
        Hdf5File f = Hdf5File::create(file, MPI_COMM_WORLD);
        const std::uint64_t hash = stream.write_double_rows(
            f, "/values", 3, [&](std::int64_t k0, std::int64_t k1, const std::int64_t* batch_ids, double* out) {
              for (std::int64_t k = k0; k < k1; ++k) {
                EXPECT_EQ(batch_ids[k - k0], ids[k]);
                for (int c = 0; c < 3; ++c) out[3 * (k - k0) + c] = value(ids[k], c);
              }
            });
        const std::uint64_t hash_ids = stream.write_int64_rows(
            f, "/ids", 2, [&](std::int64_t k0, std::int64_t k1, const std::int64_t*, std::int64_t* out) {
              for (std::int64_t k = k0; k < k1; ++k) out[2 * (k - k0)] = ids[k], out[2 * (k - k0) + 1] = -ids[k];
            });
        f.close();
        RowStream::release();
        expect_closed_form_file(stream, ids, file, rows, hash, hash_ids);
      }
  // The last rank's range one past the end (at 1 rank: the only one): every rank throws.
  const std::int64_t first = NaturalOrder::block_begin(rows, size, rank),
                     end = NaturalOrder::block_begin(rows, size, rank + 1) + (rank == size - 1);
  EXPECT_THROW(RowStream(MPI_COMM_WORLD, rows, end - first, RowStream::Consecutive{first}), std::invalid_argument);
}

// Several datasets written together (RowStream::write_columns): three columns of 24, 16 and 8 bytes a row over
// 2^19 + 77 rows (several pieces, each dataset many seal blocks), every row the closed form's, and the seal the
// block hash of every byte (the seal follows a run a dataset when they are written a piece of each at a time). At
// 1 rank and with each rank's ids one run (with skipped slots too) every fill gives all three columns (written
// together); with ids scrambled among the ranks one column a call (one dataset after the other).
TEST(RowStream, ColumnsWrittenTogether) {
  const std::int64_t rows = (std::int64_t{1} << 19) + 77;
  const int size = comm_size(), rank = comm_rank();
  for (const int layout : {0, 1, 2}) {  // runs, runs with skipped slots, scrambled
    std::vector<std::int64_t> ids;
    for (std::int64_t id = 0; id < rows; ++id)
      if ((layout < 2 ? NaturalOrder::block_owner(rows, size, id) : rank_of(id, size)) == rank) {
        ids.push_back(id);
        if (layout == 1 && ids.size() % 1000 == 0) ids.push_back(-1);
      }
    const RowStream stream(
        MPI_COMM_WORLD, rows, static_cast<std::int64_t>(ids.size()),
        [&](std::int64_t k0, std::int64_t k1, std::int64_t* out) { std::copy(ids.begin() + k0, ids.begin() + k1, out); },
        RowStream::Batched{});
    const bool together = size == 1 || layout < 2;
    EXPECT_EQ(stream.own_parts(), size > 1 && layout < 2);
    const std::string file = std::string(TISSUE_TEST_OUT_DIR) + "/row_stream_columns_np" + std::to_string(size) +
                             "_" + std::to_string(layout) + ".h5";
    Hdf5File f = Hdf5File::create(file, MPI_COMM_WORLD);
    long long calls = 0, all_three = 0;
    stream.write_columns(f, {{"/a/values", 3, false}, {"/a/pairs", 2, true}, {"/a/roots", 1, false}},
                         [&](std::int64_t k0, std::int64_t k1, const std::int64_t* batch_ids, void* const* out) {
                           ++calls;
                           all_three += out[0] && out[1] && out[2];
                           for (std::int64_t k = k0; k < k1; ++k) {
                             const std::int64_t id = ids[static_cast<std::size_t>(k)], j = k - k0;
                             EXPECT_EQ(batch_ids[j], id);
                             if (id < 0) continue;  // a skipped slot: its rows are dropped
                             if (out[0])
                               for (int c = 0; c < 3; ++c) static_cast<double*>(out[0])[3 * j + c] = value(id, c);
                             if (out[1])
                               static_cast<std::int64_t*>(out[1])[2 * j] = id,
                                                           static_cast<std::int64_t*>(out[1])[2 * j + 1] = -7 * id;
                             if (out[2]) static_cast<double*>(out[2])[j] = std::sqrt(static_cast<double>(id));
                           }
                         });
    f.close();
    RowStream::release();
    EXPECT_GT(calls, 0);
    EXPECT_EQ(all_three, together ? calls : 0) << layout;
    if (rank == 0) {
      std::ifstream in(file, std::ios::binary);
      const std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      ASSERT_GT(bytes.size(), std::size_t{24} << 20);
      const std::string header = expected_seal(bytes);
      EXPECT_EQ(std::string(bytes.begin(), bytes.begin() + static_cast<long>(header.size())), header) << layout;
    }
    Hdf5File h = Hdf5File::open(file, MPI_COMM_WORLD, "file", nullptr);  // the seal checked by the reader too
    const std::int64_t first = NaturalOrder::block_begin(rows, size, rank), end = NaturalOrder::block_begin(rows, size, rank + 1);
    const std::vector<double> values = h.read_double("/a/values", first, end - first),
                              roots = h.read_double("/a/roots", first, end - first);
    const std::vector<std::int64_t> pairs = h.read_int64("/a/pairs", first, end - first);
    std::int64_t wrong = 0;
    for (std::int64_t i = 0; i < end - first; ++i) {
      const std::int64_t id = first + i;
      for (int c = 0; c < 3; ++c) wrong += values[3 * i + c] != value(id, c);
      wrong += pairs[2 * i] != id || pairs[2 * i + 1] != -7 * id;
      wrong += roots[i] != std::sqrt(static_cast<double>(id));
    }
    EXPECT_EQ(wrong, 0) << layout;
    h.close();
    MPI_Barrier(MPI_COMM_WORLD);
    if (rank == 0) std::filesystem::remove(file);
  }
}

TEST(RowStream, AFillThatThrowsOnOneRankStopsEveryRankAndTheStreamWritesOnAfter) {
  // The pieces' rows go point to point a piece ahead of the write, with no collective between pieces: a fill that
  // throws on the rank holding one id (in the first piece, in a middle one, in the last) must stop every rank with
  // that error, leave no message behind (the same stream then writes a file whose every row is the closed form's),
  // and remove the file.
  const std::vector<std::int64_t> ids = slots();
  const RowStream stream(MPI_COMM_WORLD, N, static_cast<std::int64_t>(ids.size()),
                         [&](std::int64_t k) { return ids[k]; }, 7);
  for (const std::int64_t bad_id : {std::int64_t{3}, N / 2, N - 2}) {
    const std::string file = path() + ".throws" + std::to_string(bad_id);
    std::string what;
    {
      Hdf5File f = Hdf5File::create(file, MPI_COMM_WORLD);  // abandoned by the failed write: nothing to close
      try {
        stream.write_double(f, "/values", 3, [&](std::int64_t k, double* row) {
          if (ids[k] == bad_id) throw std::runtime_error("fill of " + std::to_string(bad_id));
          for (int c = 0; c < 3; ++c) row[c] = value(ids[k], c);
        }, RowStream::Checksum::skip);
      } catch (const std::exception& e) {
        what = e.what();
      }
    }
    EXPECT_NE(what.find("fill of " + std::to_string(bad_id)), std::string::npos) << what;
    MPI_Barrier(MPI_COMM_WORLD);
    EXPECT_FALSE(std::filesystem::exists(file + ".tmp"));
    EXPECT_FALSE(std::filesystem::exists(file));
  }
  const std::string file = path() + ".after";
  Hdf5File f = Hdf5File::create(file, MPI_COMM_WORLD);
  const std::uint64_t hash = stream.write_double(f, "/values", 3, [&](std::int64_t k, double* row) {
    for (int c = 0; c < 3; ++c) row[c] = value(ids[k], c);
  });
  f.close();
  RowStream::release();
  const std::vector<double> expected = closed_form_values();
  EXPECT_EQ(hash, row_hash_sum(expected.data(), 3, N, 0));
  Hdf5File h = Hdf5File::open(file, MPI_COMM_WORLD, "file", nullptr);
  EXPECT_EQ(h.read_double("/values", 0, N), expected);
  h.close();
  MPI_Barrier(MPI_COMM_WORLD);
  if (comm_rank() == 0) std::filesystem::remove(file);
}
