// Writing a block of rows (molecules, connections) into an HDF5 dataset in the file's natural (original id) order,
// a bounded piece at a time, so that writing a field never needs the whole field in natural order on any rank.
//
// Each rank's items are already in increasing id order (owned molecules come first in original-id order, and
// connections are sorted by their ends, which is their id order: partition/local_model.hpp). The file's rows are
// cut into pieces of at most kPieceRows rows (in all, not a rank: at more ranks each rank's part, and its buffers,
// shrink with its share of the sample; pieces of kPieceRows rows a rank were tried and gained no speed, 2 ranks
// under load, but cost 1.116x instead of 1.080x the memory without output); each piece is split evenly among
// the ranks (each part's ends moved onto the dataset's seal blocks, so that the seal hashes them as written);
// every rank sends the items of the piece that another rank's part holds to that rank, as rows and the runs of
// consecutive ids they cover (point to point, a piece ahead of the write: no collective between pieces), and each
// rank writes its part (independently, in writes of at most 1 MiB: Hdf5File::write_pieces). When each rank's ids are one run and
// the runs follow each other in rank order (a lattice's molecules and written connections), each rank writes its
// own rows instead, in pieces of its own of at most kPieceRows rows, every rank at once, and nothing is exchanged.
// Per rank and piece that is at most kPieceRows rows in and out, whatever
// the sample's size or the rank count: a 10^6-molecule snapshot costs a few MB on top of the run, not a copy of
// every field (docs/benchmarks.md, "Snapshots without the memory spike").
//
// Reading (a restart) runs the same pieces backwards: each rank reads its part of a piece in one collective
// hyperslab read, the ranks send it the ids they want from that part, and it answers with the rows (two
// MPI_Alltoallv a piece). A stream for reading may let several ranks want the same row (a connection cut by the
// partition is held on both sides), or none.
#pragma once
#include <mpi.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "io/hdf5_file.hpp"

namespace tissue {

// This rank's part of the row hash checkpoints carry: the sum (mod 2^64) over rows of FNV-1a(row index, row
// bytes), for `count` rows of `width` values starting at row `first_row`. Order-independent: any split of the rows
// among ranks and pieces sums to the same total.
template <typename T>
std::uint64_t row_hash_sum(const T* rows, int width, std::int64_t count, std::int64_t first_row);

class RowStream {
public:
  static constexpr std::int64_t kPieceRows = std::int64_t{1} << 18;

  // Collective. This rank's item slots are [0, slots): id(k) is slot k's global id in [0, global_rows), or -1 for a
  // slot this rank does not write (a connection whose end a another rank owns); the ids increase with k. Across
  // ranks the ids must be a permutation of 0 .. global_rows - 1: otherwise every rank throws std::invalid_argument.
  // Keeps O(pieces x ranks) numbers, nothing per item.
  using Id = std::function<std::int64_t(std::int64_t slot)>;
  RowStream(MPI_Comm comm, std::int64_t global_rows, std::int64_t slots, Id id, std::int64_t piece_rows = kPieceRows);
  // The same, with the ids given a batch at a time: ids(first, end, out) writes the ids of slots [first, end), at
  // most kBatch of them, in order (-1: not written here). Writers whose items are costly to decode one by one (a
  // lattice's connections stored as runs) decode each batch once instead of once a slot.
  static constexpr std::int64_t kBatch = 4096;
  using Ids = std::function<void(std::int64_t first_slot, std::int64_t end_slot, std::int64_t* ids)>;
  struct Batched {};
  RowStream(MPI_Comm comm, std::int64_t global_rows, std::int64_t slots, Ids ids, Batched,
            std::int64_t piece_rows = kPieceRows);
  // The same when this rank's slots hold the ids first_id, first_id + 1, ... in order, every slot written (every
  // item at 1 rank; a rank of a partition by slabs of ids): the plan is counted from the range, and no id is asked
  // for (decoding a lattice's 9 million connection ids to plan took a tenth of a 1-rank write's CPU).
  struct Consecutive {
    std::int64_t first_id;
  };
  RowStream(MPI_Comm comm, std::int64_t global_rows, std::int64_t slots, Consecutive ids,
            std::int64_t piece_rows = kPieceRows);
  // Collective; for reading only: as above, but any rank may want any id (increasing in its slots), once, several
  // times across the ranks, or not at all. Ids outside [0, global_rows) throw std::invalid_argument on every rank.
  struct Shared {};
  RowStream(MPI_Comm comm, std::int64_t global_rows, std::int64_t slots, Id id, Shared,
            std::int64_t piece_rows = kPieceRows);

  // Collective: writes the new dataset [global_rows x width] of `file`; fill(k, row) gives slot k's `width` values.
  // Returns the row hash of the whole dataset (row_hash_sum, summed over the ranks), the same on every rank, or 0
  // with Checksum::skip (snapshots carry no row hash).
  // The piece buffers (one set a process, shared by every stream) stay allocated from one dataset to the next (a
  // fresh allocation's first touch cost more than the rest of the write): release() gives them back once the file
  // is written.
  enum class Checksum { compute, skip };
  using FillDouble = std::function<void(std::int64_t slot, double* row)>;
  using FillInt = std::function<void(std::int64_t slot, std::int64_t* row)>;
  std::uint64_t write_double(Hdf5File& file, const std::string& dataset, int width, const FillDouble& fill,
                             Checksum checksum = Checksum::compute) const;
  std::uint64_t write_int64(Hdf5File& file, const std::string& dataset, int width, const FillInt& fill,
                            Checksum checksum = Checksum::compute) const;
  // The same a batch of slots at a time: fill(first, end, ids, rows) writes the rows of slots [first, end) (at most
  // kBatch) one after another into rows, `width` values each; ids are the slots' ids, and a slot whose id is -1 may
  // be left unwritten (its row is dropped). Rows arrive in the piece's buffer directly when a batch's ids are
  // consecutive (every slot at 1 rank): no copy, no call a row.
  using FillDoubles = std::function<void(std::int64_t first_slot, std::int64_t end_slot, const std::int64_t* ids,
                                         double* rows)>;
  using FillInts = std::function<void(std::int64_t first_slot, std::int64_t end_slot, const std::int64_t* ids,
                                      std::int64_t* rows)>;
  std::uint64_t write_double_rows(Hdf5File& file, const std::string& dataset, int width, const FillDoubles& fill,
                                  Checksum checksum = Checksum::compute) const;
  std::uint64_t write_int64_rows(Hdf5File& file, const std::string& dataset, int width, const FillInts& fill,
                                 Checksum checksum = Checksum::compute) const;
  // Several datasets of the same rows at once: fill(first, end, ids, rows) writes the rows of slots [first, end)
  // (at most kBatch, ids as above) of each column i into rows[i], columns[i].width values a row, 8-byte integers or
  // doubles as the column says; rows[i] null: that column is not wanted in this call. Where no rows travel (1
  // rank, or each rank's ids one run: own_parts()) the datasets are written a piece of each at a time
  // (Hdf5File::write_pieces_together) and one fill a batch gives every column (a connection's ends decoded once
  // for its endpoints, strain and force); otherwise one dataset after the other, one column asked for at a time.
  // No row hash (snapshots carry none).
  using Column = Hdf5File::Column;
  using FillColumns = std::function<void(std::int64_t first_slot, std::int64_t end_slot, const std::int64_t* ids,
                                         void* const* rows)>;
  void write_columns(Hdf5File& file, const std::vector<Column>& columns, const FillColumns& fill) const;
  static void release();

  // Collective: reads the dataset [global_rows x width] of `file` (its shape checked by the caller) and calls
  // take(k, row) with each slot's row, in slot order. `fault_stage`: a fault_point (partition/agreement.hpp) before
  // each piece's read, agreed, for the fault tests. Returns the dataset's row hash (row_hash_sum, summed over the
  // ranks) and whether every value is finite, the same on every rank: the caller refuses a damaged file.
  struct ReadCheck {
    std::uint64_t hash = 0;
    bool finite = true;
  };
  using TakeDouble = std::function<void(std::int64_t slot, const double* row)>;
  using TakeInt = std::function<void(std::int64_t slot, const std::int64_t* row)>;
  ReadCheck read_double(const Hdf5File& file, const std::string& dataset, int width, const TakeDouble& take,
                        const char* fault_stage = nullptr) const;
  ReadCheck read_int64(const Hdf5File& file, const std::string& dataset, int width, const TakeInt& take,
                       const char* fault_stage = nullptr) const;

  std::int64_t pieces() const { return pieces_; }  // ceil(global_rows / piece_rows), at least 1
  bool own_parts() const { return !own_begin_.empty(); }  // each rank's part its own rows: no rows exchanged

private:
  template <typename T>
  std::uint64_t write(Hdf5File& file, const std::string& dataset, int width,
                      const std::function<void(std::int64_t, std::int64_t, const std::int64_t*, T*)>& fill,
                      Checksum checksum) const;
  template <typename T>
  ReadCheck read(const Hdf5File& file, const std::string& dataset, int width,
                 const std::function<void(std::int64_t, const T*)>& take, const char* fault_stage) const;
  void plan(bool shared);
  // plan()'s pass over the slots: start_, send_ and runs_ of the even split, and this rank's id count and range.
  void count_parts(int& bad, std::int64_t& count, std::int64_t& first_id, std::int64_t& last);
  // A write's split of the pieces among the ranks (the even split's parts moved): each part's first row, and what
  // goes where (as start_, send_, runs_, recv_, recv_runs_); empty bounds: the stream's own plan.
  struct Split {
    std::vector<std::int64_t> bounds, start;
    std::vector<int> send, runs, recv, recv_runs;
  };
  // Collective. For a dataset whose first row lies at file offset `base`, rows of `row_bytes` bytes: the even split
  // with every part boundary moved to the nearest row that begins a seal block (io/file_seal.hpp), so that each
  // rank's part of a piece is whole seal blocks, which the seal hashes (and the page cache recycles) as they are
  // written instead of re-reading them at close. Empty (the stream's own plan) at 1 rank, for own parts, and when
  // no row begins a block or the blocks' rows are farther apart than a piece.
  Split aligned_split(std::int64_t base, std::int64_t row_bytes) const;
  // recv and recv_runs[p * size + r] from send and runs[p * size + r] over the ranks (one MPI_Alltoall).
  void exchange_counts(const std::vector<int>& send, const std::vector<int>& runs, std::vector<int>& recv,
                       std::vector<int>& recv_runs) const;
  // The first row of rank r's part of piece p in the even split (the file's rows of piece p shared evenly).
  std::int64_t part_begin(std::int64_t p, int r) const;
  // Rows [first, end) of piece p that rank r writes (or reads).
  std::pair<std::int64_t, std::int64_t> part_rows(std::int64_t p, int r) const;

  MPI_Comm comm_;
  int rank_ = 0, size_ = 1;
  std::int64_t global_rows_ = 0, slots_ = 0, piece_rows_ = 0, pieces_ = 1;
  bool shared_ = false;  // for reading only
  Ids ids_;
  // Indexed by piece * size + rank: the first slot whose item goes to that (piece, rank) part (one more entry at
  // the end: slots), how many items this rank sends there, and how many it receives from that rank for the piece.
  std::vector<std::int64_t> start_;
  std::vector<int> send_, recv_;
  // The same for the runs of consecutive ids among those items (sent instead of each item's id).
  std::vector<int> runs_, recv_runs_;
  // Parts aligned with the ranks' own rows (plan()): rank r's rows are [own_begin_[r], own_begin_[r + 1]); empty
  // for the even split.
  std::vector<std::int64_t> own_begin_;
  // Every slot of this rank written, slot k's id first_id_ + k (plan()): writes need not ask ids_.
  bool dense_ = false;
  std::int64_t first_id_ = 0;
  bool consecutive_ = false;  // known so by the constructor: plan() counts instead of asking

};

}  // namespace tissue
