#include "io/row_stream.hpp"

#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <numeric>
#include <stdexcept>
#include <type_traits>

#include "io/file_seal.hpp"
#include "partition/agreement.hpp"
#include "partition/natural_order.hpp"

namespace tissue {

namespace {

void check_mpi(int rc, const char* what) {
  if (rc != MPI_SUCCESS) throw std::runtime_error(std::string("RowStream: ") + what + " failed");
}

// Waits for every request, polling, with a pause between polls after the first few: a rank waiting for another's
// rows leaves its core to that rank (two ranks on two cores of a busy machine; MPI's own wait spins), at a cost of
// tens of microseconds a piece when the rows are late.
void wait_all(std::vector<MPI_Request>& requests) {
  for (int polls = 0;; ++polls) {
    int done = 0;
    check_mpi(MPI_Testall(static_cast<int>(requests.size()), requests.data(), &done, MPI_STATUSES_IGNORE),
              "MPI_Testall");
    if (done) return;
    if (polls >= 32) {
      const timespec pause{0, 50000};
      nanosleep(&pause, nullptr);
    }
  }
}

}  // namespace

template <typename T>
std::uint64_t row_hash_sum(const T* rows, int width, std::int64_t count, std::int64_t first_row) {
  constexpr std::uint64_t kBasis = 1469598103934665603ULL, kPrime = 1099511628211ULL;
  const std::size_t bytes = sizeof(T) * static_cast<std::size_t>(width);
  std::uint64_t sum = 0;
  std::int64_t r = 0;
  // Four rows side by side: FNV-1a is one chain of multiplications a byte, so independent rows hashed together keep
  // the multiplier busy. Each row's hash is the one-row-at-a-time hash of the loop below.
  constexpr int kLanes = 4;
  for (; r + kLanes <= count; r += kLanes) {
    std::uint64_t h[kLanes];
    unsigned char index[kLanes][sizeof(std::int64_t)];
    const unsigned char* b[kLanes];
    for (int l = 0; l < kLanes; ++l) {
      h[l] = kBasis;
      const std::int64_t row = first_row + r + l;
      std::memcpy(index[l], &row, sizeof row);
      b[l] = reinterpret_cast<const unsigned char*>(rows + (r + l) * width);
    }
    for (std::size_t i = 0; i < sizeof(std::int64_t); ++i)
      for (int l = 0; l < kLanes; ++l) h[l] = (h[l] ^ index[l][i]) * kPrime;
    for (std::size_t i = 0; i < bytes; ++i)
      for (int l = 0; l < kLanes; ++l) h[l] = (h[l] ^ b[l][i]) * kPrime;
    for (int l = 0; l < kLanes; ++l) sum += h[l];
  }
  for (; r < count; ++r) {
    std::uint64_t h = kBasis;
    auto mix = [&](const void* p, std::size_t n) {
      const unsigned char* b = static_cast<const unsigned char*>(p);
      for (std::size_t i = 0; i < n; ++i) h = (h ^ b[i]) * kPrime;
    };
    const std::int64_t row = first_row + r;
    mix(&row, sizeof row);
    mix(rows + r * width, bytes);
    sum += h;
  }
  return sum;
}

template std::uint64_t row_hash_sum<double>(const double*, int, std::int64_t, std::int64_t);
template std::uint64_t row_hash_sum<std::int64_t>(const std::int64_t*, int, std::int64_t, std::int64_t);

std::int64_t RowStream::part_begin(std::int64_t p, int r) const {
  const std::int64_t first = p * piece_rows_, end = std::min(global_rows_, first + piece_rows_);
  return first + NaturalOrder::block_begin(end - first, size_, r);
}

std::pair<std::int64_t, std::int64_t> RowStream::part_rows(std::int64_t p, int r) const {
  if (!own_begin_.empty()) {
    const std::int64_t end = own_begin_[r + 1], first = std::min(end, own_begin_[r] + p * piece_rows_);
    return {first, std::min(end, first + piece_rows_)};
  }
  return {part_begin(p, r), part_begin(p, r + 1)};
}

namespace {

RowStream::Ids one_at_a_time(RowStream::Id id) {
  return [id = std::move(id)](std::int64_t first, std::int64_t end, std::int64_t* out) {
    for (std::int64_t k = first; k < end; ++k) *out++ = id(k);
  };
}

}  // namespace

RowStream::RowStream(MPI_Comm comm, std::int64_t global_rows, std::int64_t slots, Id id, std::int64_t piece_rows)
    : comm_(comm), global_rows_(global_rows), slots_(slots), piece_rows_(piece_rows),
      ids_(one_at_a_time(std::move(id))) {
  plan(false);
}

RowStream::RowStream(MPI_Comm comm, std::int64_t global_rows, std::int64_t slots, Ids ids, Batched,
                     std::int64_t piece_rows)
    : comm_(comm), global_rows_(global_rows), slots_(slots), piece_rows_(piece_rows), ids_(std::move(ids)) {
  plan(false);
}

RowStream::RowStream(MPI_Comm comm, std::int64_t global_rows, std::int64_t slots, Consecutive ids,
                     std::int64_t piece_rows)
    : comm_(comm), global_rows_(global_rows), slots_(slots), piece_rows_(piece_rows),
      ids_([first = ids.first_id](std::int64_t k0, std::int64_t k1, std::int64_t* out) {
        std::iota(out, out + (k1 - k0), first + k0);
      }),
      first_id_(ids.first_id), consecutive_(true) {
  plan(false);
}

RowStream::RowStream(MPI_Comm comm, std::int64_t global_rows, std::int64_t slots, Id id, Shared,
                     std::int64_t piece_rows)
    : comm_(comm), global_rows_(global_rows), slots_(slots), piece_rows_(piece_rows), shared_(true),
      ids_(one_at_a_time(std::move(id))) {
  plan(true);
}

void RowStream::plan(bool shared) {
  check_mpi(MPI_Comm_rank(comm_, &rank_), "MPI_Comm_rank");
  check_mpi(MPI_Comm_size(comm_, &size_), "MPI_Comm_size");
  if (piece_rows_ <= 0) throw std::invalid_argument("RowStream: pieces of no rows");
  pieces_ = std::max<std::int64_t>(1, (global_rows_ + piece_rows_ - 1) / piece_rows_);
  std::int64_t parts = pieces_ * size_;
  int bad = 0;
  std::int64_t count = 0, first_id = -1, last = -1, ids[kBatch];
  count_parts(bad, count, first_id, last);
  // When each rank's ids are one run and the runs follow each other in rank order (a lattice's molecules, and the
  // connections each rank writes, in every partition by slabs of ids), each rank's part of a piece is its own rows
  // there: nothing travels, and each rank writes its rows where they lie (a part then holds up to a piece's rows, at
  // most kPieceRows). The even split above becomes that by moving every item to its own rank's part of its piece.
  // Every slot written, ids consecutive (every item at 1 rank): a write then counts the ids instead of asking
  // for them (decoding a batch of connections' ids cost as much as filling its rows).
  dense_ = !bad && count == slots_ && (count == 0 || last - first_id + 1 == count);
  first_id_ = count > 0 ? first_id : 0;
  if (!shared && size_ > 1) {
    long long mine[3] = {bad, count, count > 0 && last - first_id + 1 == count ? first_id : -1};
    std::vector<long long> all(3 * static_cast<std::size_t>(size_));
    check_mpi(MPI_Allgather(mine, 3, MPI_LONG_LONG, all.data(), 3, MPI_LONG_LONG, comm_), "MPI_Allgather");
    bool runs = true;
    long long at = 0;
    for (int r = 0; r < size_ && runs; ++r) {
      runs = all[3 * r] == 0 && (all[3 * r + 1] == 0 || all[3 * r + 2] == at);
      at += all[3 * r + 1];
    }
    if (runs && at == global_rows_) {
      // Each rank's own rows in pieces of its own, written at the same time as the other ranks' (pieces of the
      // file's rows would leave every rank but the one holding a piece's rows waiting): piece p of rank r is its
      // items [p, p + 1) x piece_rows_, and there are as many pieces as the largest rank needs.
      own_begin_.assign(size_ + 1, 0);
      std::int64_t most = 0;
      for (int r = 0; r < size_; ++r) {
        own_begin_[r + 1] = own_begin_[r] + all[3 * r + 1];
        most = std::max<std::int64_t>(most, all[3 * r + 1]);
      }
      pieces_ = std::max<std::int64_t>(1, (most + piece_rows_ - 1) / piece_rows_);
      parts = pieces_ * size_;
      // The slot of this rank's item p x piece_rows_, for each piece (slots_ past its last item).
      std::vector<std::int64_t> piece_slot(pieces_ + 1, slots_);
      std::int64_t item = 0, p = 0;
      if (consecutive_)  // item i is slot i
        for (; p < pieces_; ++p) piece_slot[p] = std::min(slots_, p * piece_rows_);
      for (std::int64_t k0 = 0; k0 < slots_ && p < pieces_; k0 += kBatch) {
        const std::int64_t k1 = std::min(slots_, k0 + kBatch);
        ids_(k0, k1, ids);
        for (std::int64_t k = k0; k < k1 && p < pieces_; ++k)
          if (ids[k - k0] >= 0 && item++ == p * piece_rows_) piece_slot[p++] = k;
      }
      start_.assign(parts + 1, slots_);
      send_.assign(parts, 0);
      runs_.assign(parts, 0);
      for (std::int64_t q = 0; q < pieces_; ++q)
        for (int r = 0; r < size_; ++r) {
          start_[q * size_ + r] = r <= rank_ ? piece_slot[q] : piece_slot[q + 1];
          if (r == rank_) send_[q * size_ + r] = std::clamp(count - q * piece_rows_, std::int64_t{0}, piece_rows_);
        }
    }
  }
  // What each rank receives in each piece, rows and runs: one all-to-all of every piece's counts.
  exchange_counts(send_, runs_, recv_, recv_runs_);
  // Every part must receive exactly its rows' count (duplicates are caught as each piece is written).
  for (std::int64_t p = 0; p < pieces_ && !bad && !shared; ++p) {
    std::int64_t got = 0;
    for (int r = 0; r < size_; ++r) got += recv_[p * size_ + r];
    const auto [first, end] = part_rows(p, rank_);
    bad = got != end - first;
  }
  int any = 0;
  check_mpi(MPI_Allreduce(&bad, &any, 1, MPI_INT, MPI_MAX, comm_), "MPI_Allreduce");
  if (any)
    throw std::invalid_argument(std::string("RowStream: the ranks' ids are not ") +
                                (shared ? "increasing ids in " : "an increasing permutation of ") + "0.." +
                                std::to_string(global_rows_ - 1));
}

void RowStream::count_parts(int& bad, std::int64_t& count, std::int64_t& first_id, std::int64_t& last) {
  const std::int64_t parts = pieces_ * size_;
  start_.assign(parts + 1, slots_);
  send_.assign(parts, 0);
  runs_.assign(parts, 0);
  bad = global_rows_ < 0;
  count = 0, first_id = -1, last = -1;
  if (consecutive_) {
    // Slots [0, slots) hold ids [first_id_, first_id_ + slots): each part takes the ids of its range, as one run.
    bad = bad || first_id_ < 0 || slots_ < 0 || first_id_ + slots_ > global_rows_;
    if (bad) return;
    for (std::int64_t q = 0; q < parts; ++q) {
      const int r = static_cast<int>(q % size_);
      const std::int64_t begin = part_begin(q / size_, r), end = part_begin(q / size_, r + 1);
      start_[q] = std::clamp(begin - first_id_, std::int64_t{0}, slots_);
      send_[q] = static_cast<int>(std::max<std::int64_t>(0, std::min(end, first_id_ + slots_) - std::max(begin, first_id_)));
      runs_[q] = send_[q] > 0;
    }
    count = slots_;
    if (count > 0) first_id = first_id_, last = first_id_ + slots_ - 1;
    return;
  }
  // One pass over the slots, a batch of ids at a time: the items go to the parts in order, since their ids
  // increase (the part holding an id is found by moving past the parts that end before it: no division an item).
  std::int64_t next_part = 0, part = 0, part_end = parts > 0 ? part_begin(0, 1) : 0, run_part = -1;
  std::int64_t ids[kBatch];
  for (std::int64_t k0 = 0; k0 < slots_ && !bad; k0 += kBatch) {
    const std::int64_t k1 = std::min(slots_, k0 + kBatch);
    ids_(k0, k1, ids);
    for (std::int64_t k = k0; k < k1; ++k) {
      const std::int64_t i = ids[k - k0];
      if (i < 0) continue;
      if (i <= last || i >= global_rows_) {
        bad = 1;
        break;
      }
      if (count++ == 0) first_id = i;
      const bool joins = i == last + 1;
      last = i;
      while (i >= part_end) {
        ++part;
        part_end = part_begin(part / size_, part % size_ + 1);
      }
      while (next_part <= part) start_[next_part++] = k;
      ++send_[part];
      // The runs of consecutive ids this rank sends to each part: they travel instead of the ids (write()).
      if (!joins || part != run_part) ++runs_[part], run_part = part;
    }
  }
}

void RowStream::exchange_counts(const std::vector<int>& send, const std::vector<int>& runs, std::vector<int>& recv,
                                std::vector<int>& recv_runs) const {
  const std::size_t parts = static_cast<std::size_t>(pieces_) * size_;
  std::vector<int> out(2 * parts), in(2 * parts);
  for (int r = 0; r < size_; ++r)
    for (std::int64_t p = 0; p < pieces_; ++p) {
      out[2 * (r * pieces_ + p)] = send[p * size_ + r];
      out[2 * (r * pieces_ + p) + 1] = runs[p * size_ + r];
    }
  check_mpi(MPI_Alltoall(out.data(), static_cast<int>(2 * pieces_), MPI_INT, in.data(), static_cast<int>(2 * pieces_),
                         MPI_INT, comm_),
            "MPI_Alltoall");
  recv.assign(parts, 0);
  recv_runs.assign(parts, 0);
  for (int r = 0; r < size_; ++r)
    for (std::int64_t p = 0; p < pieces_; ++p) {
      recv[p * size_ + r] = in[2 * (r * pieces_ + p)];
      recv_runs[p * size_ + r] = in[2 * (r * pieces_ + p) + 1];
    }
}

RowStream::Split RowStream::aligned_split(std::int64_t base, std::int64_t row_bytes) const {
  Split split;
  if (size_ == 1 || own_parts() || base < 0 || row_bytes <= 0) return split;
  // The rows x that begin a seal block: base + row_bytes x = kSealUserBlock (mod kSealBlock). With g the largest
  // power of two dividing both, they exist iff g divides kSealUserBlock - base, and repeat every T = kSealBlock / g
  // rows; m = row_bytes / g is odd, so x0 = (kSealUserBlock - base) / g times m's inverse, modulo T.
  const std::int64_t block = static_cast<std::int64_t>(kSealBlock);
  const std::int64_t g = std::gcd(row_bytes, block), period = block / g;
  const std::int64_t c = ((static_cast<std::int64_t>(kSealUserBlock) - base) % block + block) % block;
  if (c % g != 0 || period > piece_rows_) return split;
  const std::uint64_t m = static_cast<std::uint64_t>(row_bytes / g);
  std::uint64_t inverse = m;  // Newton's iteration: each step doubles the correct low bits (m m = 1 mod 8)
  for (int i = 0; i < 5; ++i) inverse *= 2 - m * inverse;
  const std::int64_t x0 =
      static_cast<std::int64_t>((static_cast<std::uint64_t>(c / g) * inverse) & static_cast<std::uint64_t>(period - 1));
  const std::int64_t parts = pieces_ * size_;
  split.bounds.assign(parts + 1, global_rows_);
  split.bounds[0] = 0;
  for (std::int64_t q = 1; q < parts; ++q) {
    const std::int64_t even = part_begin(q / size_, static_cast<int>(q % size_)), shift = even - x0 + period / 2;
    const std::int64_t nearest = shift < 0 ? 0 : x0 + shift / period * period;
    split.bounds[q] = std::clamp(nearest, split.bounds[q - 1], global_rows_);
  }
  // The items to the parts, and their runs, as plan() does with the even split (the ids were checked there).
  split.start.assign(parts + 1, slots_);
  split.send.assign(parts, 0);
  split.runs.assign(parts, 0);
  std::int64_t ids[kBatch], next_part = 0, part = 0, last = -1, run_part = -1;
  for (std::int64_t k0 = 0; k0 < slots_; k0 += kBatch) {
    const std::int64_t k1 = std::min(slots_, k0 + kBatch);
    ids_(k0, k1, ids);
    for (std::int64_t k = k0; k < k1; ++k) {
      const std::int64_t i = ids[k - k0];
      if (i < 0) continue;
      const bool joins = i == last + 1;
      last = i;
      while (part < parts - 1 && i >= split.bounds[part + 1]) ++part;
      while (next_part <= part) split.start[next_part++] = k;
      ++split.send[part];
      if (!joins || part != run_part) ++split.runs[part], run_part = part;
    }
  }
  exchange_counts(split.send, split.runs, split.recv, split.recv_runs);
  int bad = 0;
  for (std::int64_t p = 0; p < pieces_ && !bad; ++p) {
    std::int64_t got = 0;
    for (int r = 0; r < size_; ++r) got += split.recv[p * size_ + r];
    bad = got != split.bounds[p * size_ + rank_ + 1] - split.bounds[p * size_ + rank_];
  }
  int any = 0;
  check_mpi(MPI_Allreduce(&bad, &any, 1, MPI_INT, MPI_MAX, comm_), "MPI_Allreduce");
  if (any) throw std::logic_error("RowStream: the parts aligned on the seal's blocks miss rows");
  return split;
}

namespace {

// The piece buffers of writes, left uninitialized (every value is written before it is read): the rows of this
// rank's part, and the messages sent to and received from other ranks, one set for even pieces and one for odd. One
// set a process, of 8-byte values of either type (doubles and int64 datasets take turns in a file, and a buffer
// given back and taken again is page faults again: tens of microseconds a fault on this project's virtual
// machines), kept until RowStream::release().
static_assert(sizeof(double) == sizeof(std::int64_t), "one buffer holds either type's values");
struct Scratch {
  struct Free {
    void operator()(void* p) const { ::operator delete(p); }
  };
  std::unique_ptr<void, Free> data;
  std::size_t size = 0;  // values
  template <typename T>
  T* at_least(std::size_t n) {
    if (n > size) data.reset(), data.reset(::operator new(n * sizeof(T))), size = n;
    return static_cast<T*>(data.get());
  }
  template <typename T>
  const T* get() const {
    return static_cast<const T*>(data.get());
  }
};
struct Buffers {
  Scratch rows, outgoing[2], incoming[2];
  std::vector<Scratch> columns;  // write_columns: a piece's rows of each dataset but the first (that one: rows)
  std::vector<char> seen;
};
Buffers write_buffers;

}  // namespace

void RowStream::release() { write_buffers = {}; }

template <typename T>
std::uint64_t RowStream::write(Hdf5File& file, const std::string& dataset, int width,
                               const std::function<void(std::int64_t, std::int64_t, const std::int64_t*, T*)>& fill,
                               Checksum checksum) const {
  if (shared_) throw std::logic_error("RowStream: a stream whose ids repeat across ranks writes no file");
  Buffers& buffer = write_buffers;
  std::vector<char>& seen = buffer.seen;
  // A batch's ids and, when its rows cannot go straight to their place, its rows (a few hundred kB at most).
  std::int64_t ids[kBatch];
  std::unique_ptr<T[]> batch;
  auto batch_rows = [&] {
    if (!batch) batch.reset(new T[static_cast<std::size_t>(kBatch) * width]);
    return batch.get();
  };
  auto slot_ids = [&](std::int64_t k0, std::int64_t k1, std::int64_t* to) {
    if (dense_) std::iota(to, to + (k1 - k0), first_id_ + k0);
    else ids_(k0, k1, to);
  };
  const bool exchange = size_ > 1 && !own_parts();
  // The parts: the stream's plan, or the same moved onto the dataset's seal blocks once its place in the file is
  // known (write_pieces calls `placed` before the first piece).
  Split aligned;
  const std::vector<std::int64_t>* start = &start_;
  const std::vector<int>*send = &send_, *runs = &runs_, *recv = &recv_, *recv_runs = &recv_runs_;
  auto placed = [&](std::int64_t base) {
    aligned = aligned_split(base, static_cast<std::int64_t>(sizeof(T)) * width);
    if (aligned.bounds.empty()) return;
    start = &aligned.start, send = &aligned.send, runs = &aligned.runs, recv = &aligned.recv,
    recv_runs = &aligned.recv_runs;
  };
  // The exchange, a piece ahead of the write: piece p + 1's rows are filled and sent (point to point, nonblocking)
  // before piece p's are placed and written, so that a rank waits for another only until that rank has filled its
  // rows, never for its write, and no collective stands between the pieces. The message to a rank for a piece:
  // the rows, in id order, then the runs of consecutive ids they hold ({first id, length}: a rank knows which ids
  // it sends; a partition's runs are tens of rows or more, so the ids no longer travel with each row). Two sets
  // of buffers (piece parity), each a part's rows at most.
  struct Exchange {
    std::vector<MPI_Request> sends, receives;
    std::vector<int> from;  // the rank of each receive
  } exchanges[2];
  auto message_size = [&](int rows, int n_runs) { return static_cast<std::size_t>(rows) * width + 2 * n_runs; };
  std::exception_ptr fill_failed;  // a fill that threw while the other ranks' messages were being made
  auto post = [&](std::int64_t q) {
    Exchange& x = exchanges[q & 1];
    // The sends of piece q - 2 used these buffers (and its receives, waited for by piece(q - 2)).
    wait_all(x.sends);
    wait_all(x.receives);
    x.sends.clear();
    x.receives.clear();
    x.from.clear();
    std::size_t out_size = 0, in_size = 0;
    for (int r = 0; r < size_; ++r)
      if (r != rank_) {
        out_size += message_size((*send)[q * size_ + r], (*runs)[q * size_ + r]);
        in_size += message_size((*recv)[q * size_ + r], (*recv_runs)[q * size_ + r]);
      }
    T* outgoing = buffer.outgoing[q & 1].at_least<T>(out_size);
    T* incoming = buffer.incoming[q & 1].at_least<T>(in_size);
    const int tag = 0x7e00 + static_cast<int>(q % 256);
    std::size_t in = 0;
    for (int r = 0; r < size_; ++r) {
      const std::size_t n = r == rank_ ? 0 : message_size((*recv)[q * size_ + r], (*recv_runs)[q * size_ + r]);
      if (n == 0) continue;
      x.receives.emplace_back();
      x.from.push_back(r);
      check_mpi(MPI_Irecv(incoming + in, static_cast<int>(n * sizeof(T)), MPI_BYTE, r, tag, comm_,
                          &x.receives.back()),
                "MPI_Irecv");
      in += n;
    }
    std::size_t at = 0;
    for (int r = 0; r < size_; ++r) {
      const int rows_to_r = r == rank_ ? 0 : (*send)[q * size_ + r];
      if (rows_to_r == 0) continue;
      T* message = outgoing + at;
      T* to = message;
      std::vector<std::int64_t> message_runs;  // {first id, length}, as plan() counted them
      // A failed fill leaves its rows as they are: the message still goes, whole (the other rank waits for it and
      // places it), and this rank throws once its part of the piece is done.
      for (std::int64_t k0 = (*start)[q * size_ + r], end = (*start)[q * size_ + r + 1]; k0 < end; k0 += kBatch) {
        const std::int64_t k1 = std::min(end, k0 + kBatch), n = k1 - k0;
        slot_ids(k0, k1, ids);
        std::int64_t written = 0;
        for (std::int64_t j = 0; j < n; ++j) written += ids[j] >= 0;
        if (!fill_failed) try {
            if (written == n) {  // no slot skipped: the rows go straight into the message
              fill(k0, k1, ids, to);
            } else {
              T* b = batch_rows();
              fill(k0, k1, ids, b);
              T* row = to;
              for (std::int64_t j = 0; j < n; ++j)
                if (ids[j] >= 0) row = std::copy(b + j * width, b + (j + 1) * width, row);
            }
          } catch (...) {
            fill_failed = std::current_exception();
          }
        to += written * width;
        for (std::int64_t j = 0; j < n; ++j)
          if (const std::int64_t i = ids[j]; i >= 0) {
            if (!message_runs.empty() && message_runs[message_runs.size() - 2] + message_runs.back() == i)
              ++message_runs.back();
            else
              message_runs.push_back(i), message_runs.push_back(1);
          }
      }
      // plan() counted the same runs from the same ids; a mismatch is a broken id function, not a size to trust.
      message_runs.resize(2 * static_cast<std::size_t>((*runs)[q * size_ + r]), -1);
      std::memcpy(message + static_cast<std::size_t>(rows_to_r) * width, message_runs.data(),
                  message_runs.size() * sizeof(T));
      const std::size_t n = message_size(rows_to_r, (*runs)[q * size_ + r]);
      x.sends.emplace_back();
      check_mpi(MPI_Isend(message, static_cast<int>(n * sizeof(T)), MPI_BYTE, r, tag, comm_, &x.sends.back()),
                "MPI_Isend");
      at += n;
    }
  };
  // Whatever happens, no request outlives this call (every rank calls piece() for every piece: every message
  // posted is received).
  struct Drain {
    Exchange* x;
    ~Drain() {
      for (int s = 0; s < 2; ++s) {
        MPI_Waitall(static_cast<int>(x[s].receives.size()), x[s].receives.data(), MPI_STATUSES_IGNORE);
        MPI_Waitall(static_cast<int>(x[s].sends.size()), x[s].sends.data(), MPI_STATUSES_IGNORE);
      }
    }
  } drain{exchanges};
  std::uint64_t hash = 0;
  auto piece = [&](std::int64_t p, std::int64_t* offset, std::int64_t* count) -> const void* {
    if (exchange) {
      if (p == 0) post(0);
      if (p + 1 < pieces_) post(p + 1);
    }
    const auto [first, end] = aligned.bounds.empty()
                                  ? part_rows(p, rank_)
                                  : std::pair{aligned.bounds[p * size_ + rank_], aligned.bounds[p * size_ + rank_ + 1]};
    const std::int64_t length = end - first;
    T* rows = buffer.rows.at_least<T>(static_cast<std::size_t>(length) * width);
    if (exchange) seen.assign(static_cast<std::size_t>(length), 0);
    // This rank's own items go straight to their rows (plan() checked their ids: increasing, inside this part).
    // A fill that throws here is thrown below, once this piece's messages are received.
    try {
      for (std::int64_t k0 = (*start)[p * size_ + rank_], end = (*start)[p * size_ + rank_ + 1]; k0 < end; k0 += kBatch) {
        const std::int64_t k1 = std::min(end, k0 + kBatch), n = k1 - k0;
        slot_ids(k0, k1, ids);
        bool consecutive = dense_;  // none skipped, each the one after the last
        for (std::int64_t j = 0; j < n && !dense_; ++j) consecutive &= ids[j] == ids[0] + j;
        if (consecutive && ids[0] >= 0) {
          fill(k0, k1, ids, rows + (ids[0] - first) * width);
          if (exchange) std::memset(seen.data() + (ids[0] - first), 1, static_cast<std::size_t>(n));
          continue;
        }
        T* b = batch_rows();
        fill(k0, k1, ids, b);
        for (std::int64_t j = 0; j < n; ++j)
          if (const std::int64_t i = ids[j]; i >= 0) {
            std::copy(b + j * width, b + (j + 1) * width, rows + (i - first) * width);
            if (exchange) seen[i - first] = 1;
          }
      }
    } catch (...) {
      if (!fill_failed) fill_failed = std::current_exception();
    }
    int bad = 0;
    if (exchange) {
      // The other ranks' rows of this part, each run to its place; a run outside the part, or a row arriving twice,
      // is a bad id set.
      Exchange& x = exchanges[p & 1];
      wait_all(x.receives);
      const T* message = buffer.incoming[p & 1].get<T>();
      for (const int r : x.from) {
        const std::int64_t n = (*recv)[p * size_ + r], n_runs = (*recv_runs)[p * size_ + r];
        const T* from = message;
        const T* run_at = message + n * width;
        std::int64_t placed = 0;
        for (std::int64_t k = 0; k < n_runs && !bad; ++k) {
          std::int64_t run[2];
          std::memcpy(run, run_at + 2 * k, sizeof run);
          const std::int64_t at = run[0] - first;
          bad = at < 0 || run[1] <= 0 || run[1] > length - at || run[1] > n - placed ||
                std::memchr(seen.data() + at, 1, static_cast<std::size_t>(run[1])) != nullptr;
          if (bad) break;
          std::memset(seen.data() + at, 1, static_cast<std::size_t>(run[1]));
          std::copy(from, from + run[1] * width, rows + at * width);
          from += run[1] * width;
          placed += run[1];
        }
        bad |= placed != n;
        message += message_size(static_cast<int>(n), static_cast<int>(n_runs));
      }
    }
    if (fill_failed) std::rethrow_exception(std::exchange(fill_failed, nullptr));
    // Thrown on this rank once its messages for the next piece are posted: Hdf5File::write_pieces goes on calling
    // piece() for every piece (the other ranks' messages are received) and agrees on it after the last.
    if (bad) throw std::invalid_argument(file.path() + ": " + dataset + ": the ranks' rows repeat an id");
    if (checksum == Checksum::compute) hash += row_hash_sum(rows, width, length, first);
    *offset = first, *count = length;
    return rows;
  };
  file.write_pieces(dataset, global_rows_, width, std::is_same_v<T, std::int64_t>, pieces_, piece, own_parts(),
                    placed);
  std::uint64_t total = 0;
  check_mpi(MPI_Allreduce(&hash, &total, 1, MPI_UINT64_T, MPI_SUM, comm_), "MPI_Allreduce");
  return total;
}

void RowStream::write_columns(Hdf5File& file, const std::vector<Column>& columns, const FillColumns& fill) const {
  if (shared_) throw std::logic_error("RowStream: a stream whose ids repeat across ranks writes no file");
  const std::size_t n = columns.size();
  if (size_ > 1 && !own_parts()) {
    // Rows travel between ranks (write()'s exchange): one dataset after the other.
    for (std::size_t i = 0; i < n; ++i) {
      auto one = [&](std::int64_t k0, std::int64_t k1, const std::int64_t* ids, auto* out) {
        std::vector<void*> rows(n, nullptr);
        rows[i] = out;
        fill(k0, k1, ids, rows.data());
      };
      if (columns[i].integer)
        write<std::int64_t>(file, columns[i].dataset, columns[i].width, one, Checksum::skip);
      else
        write<double>(file, columns[i].dataset, columns[i].width, one, Checksum::skip);
    }
    return;
  }
  Buffers& buffer = write_buffers;
  buffer.columns.resize(n);
  std::vector<std::unique_ptr<std::int64_t[]>> batch(n);  // a batch's rows, when they cannot go to their place
  std::vector<void*> at(n);
  std::int64_t ids[kBatch];
  auto piece = [&](std::int64_t p, const void** data, std::int64_t* offset, std::int64_t* count) {
    const auto [first, end] = part_rows(p, rank_);
    std::vector<std::int64_t*> rows(n);
    for (std::size_t i = 0; i < n; ++i)
      rows[i] = (i == 0 ? buffer.rows : buffer.columns[i]).at_least<std::int64_t>(
          static_cast<std::size_t>(end - first) * columns[i].width);
    for (std::int64_t k0 = start_[p * size_ + rank_], k_end = start_[p * size_ + rank_ + 1]; k0 < k_end; k0 += kBatch) {
      const std::int64_t k1 = std::min(k_end, k0 + kBatch), m = k1 - k0;
      if (dense_) std::iota(ids, ids + m, first_id_ + k0);
      else ids_(k0, k1, ids);
      bool consecutive = dense_;  // none skipped, each the one after the last
      for (std::int64_t j = 0; j < m && !dense_; ++j) consecutive &= ids[j] == ids[0] + j;
      if (consecutive && ids[0] >= 0) {
        for (std::size_t i = 0; i < n; ++i) at[i] = rows[i] + (ids[0] - first) * columns[i].width;
        fill(k0, k1, ids, at.data());
        continue;
      }
      for (std::size_t i = 0; i < n; ++i) {
        if (!batch[i]) batch[i].reset(new std::int64_t[static_cast<std::size_t>(kBatch) * columns[i].width]);
        at[i] = batch[i].get();
      }
      fill(k0, k1, ids, at.data());
      for (std::size_t i = 0; i < n; ++i) {
        const int w = columns[i].width;
        for (std::int64_t j = 0; j < m; ++j)
          if (ids[j] >= 0) std::memcpy(rows[i] + (ids[j] - first) * w, batch[i].get() + j * w, 8 * static_cast<std::size_t>(w));
      }
    }
    for (std::size_t i = 0; i < n; ++i) data[i] = rows[i];
    *offset = first, *count = end - first;
  };
  file.write_pieces_together(columns, global_rows_, pieces_, piece);
}

template <typename T>
RowStream::ReadCheck RowStream::read(const Hdf5File& file, const std::string& dataset, int width,
                                     const std::function<void(std::int64_t, const T*)>& take,
                                     const char* fault_stage) const {
  // One row of `width` values is one element of the exchanges: counts stay rows, far below 2^31 in a piece.
  MPI_Datatype row_type;
  check_mpi(MPI_Type_contiguous(width, std::is_same_v<T, double> ? MPI_DOUBLE : MPI_INT64_T, &row_type),
            "MPI_Type_contiguous");
  check_mpi(MPI_Type_commit(&row_type), "MPI_Type_commit");
  struct Free {
    MPI_Datatype* t;
    ~Free() { MPI_Type_free(t); }
  } free_type{&row_type};
  std::vector<T> part, answer, got;
  std::vector<std::int64_t> wanted, asked;
  std::int64_t ids[kBatch];
  std::vector<int> want_n(size_), want_at(size_), ask_n(size_), ask_at(size_);
  std::uint64_t hash = 0;
  int bad = 0;  // a value that is not finite, or a request outside this rank's part (a broken plan)
  for (std::int64_t p = 0; p < pieces_; ++p) {
    const auto [first, end] = part_rows(p, rank_);
    const std::int64_t length = end - first;
    part.resize(static_cast<std::size_t>(length) * width);
    // The injected failure first, agreed on its own: a rank that threw there would never reach the collective read.
    if (fault_stage) agree(comm_, [&] { fault_point(fault_stage, comm_); });
    const std::int64_t from = first;  // a lambda may not capture a structured binding before C++20 (clang)
    agree(comm_, [&] { file.read_rows(dataset, from, length, width, part.data()); });
    hash += row_hash_sum(part.data(), width, length, first);
    if constexpr (std::is_same_v<T, double>)
      for (double v : part) bad |= !std::isfinite(v);
    // The ids this rank wants from each rank's part of the piece, in slot order (they increase).
    wanted.clear();
    for (int r = 0; r < size_; ++r) {
      want_at[r] = static_cast<int>(wanted.size());
      for (std::int64_t k0 = start_[p * size_ + r], end = start_[p * size_ + r + 1]; k0 < end; k0 += kBatch) {
        const std::int64_t k1 = std::min(end, k0 + kBatch);
        ids_(k0, k1, ids);
        for (std::int64_t j = 0; j < k1 - k0; ++j)
          if (ids[j] >= 0) wanted.push_back(ids[j]);
      }
      want_n[r] = static_cast<int>(wanted.size()) - want_at[r];
    }
    int asked_total = 0;
    for (int r = 0; r < size_; ++r) ask_at[r] = asked_total, asked_total += ask_n[r] = recv_[p * size_ + r];
    asked.resize(asked_total);
    check_mpi(MPI_Alltoallv(wanted.data(), want_n.data(), want_at.data(), MPI_INT64_T, asked.data(), ask_n.data(),
                            ask_at.data(), MPI_INT64_T, comm_),
              "MPI_Alltoallv");
    answer.resize(static_cast<std::size_t>(asked_total) * width);
    for (int q = 0; q < asked_total; ++q) {
      const std::int64_t r = asked[q] - first;
      if (r < 0 || r >= length) {
        bad = 1;
        continue;
      }
      std::copy(&part[r * width], &part[r * width] + width, &answer[static_cast<std::size_t>(q) * width]);
    }
    got.resize(wanted.size() * width);
    check_mpi(MPI_Alltoallv(answer.data(), ask_n.data(), ask_at.data(), row_type, got.data(), want_n.data(),
                            want_at.data(), row_type, comm_),
              "MPI_Alltoallv");
    std::size_t q = 0;
    for (std::int64_t k0 = start_[p * size_], end = start_[(p + 1) * size_]; k0 < end; k0 += kBatch) {
      const std::int64_t k1 = std::min(end, k0 + kBatch);
      ids_(k0, k1, ids);
      for (std::int64_t k = k0; k < k1; ++k)
        if (ids[k - k0] >= 0) take(k, &got[q++ * width]);
    }
  }
  ReadCheck check;
  int any = 0;
  check_mpi(MPI_Allreduce(&hash, &check.hash, 1, MPI_UINT64_T, MPI_SUM, comm_), "MPI_Allreduce");
  check_mpi(MPI_Allreduce(&bad, &any, 1, MPI_INT, MPI_MAX, comm_), "MPI_Allreduce");
  check.finite = !any;
  return check;
}

RowStream::ReadCheck RowStream::read_double(const Hdf5File& file, const std::string& dataset, int width,
                                            const TakeDouble& take, const char* fault_stage) const {
  return read<double>(file, dataset, width, take, fault_stage);
}

RowStream::ReadCheck RowStream::read_int64(const Hdf5File& file, const std::string& dataset, int width,
                                           const TakeInt& take, const char* fault_stage) const {
  return read<std::int64_t>(file, dataset, width, take, fault_stage);
}

namespace {

// A row at a time, skipped slots left alone.
template <typename T, typename Fill>
auto each_row(int width, const Fill& fill) {
  return [width, &fill](std::int64_t first, std::int64_t end, const std::int64_t* ids, T* rows) {
    for (std::int64_t k = first; k < end; ++k)
      if (ids[k - first] >= 0) fill(k, rows + (k - first) * width);
  };
}

}  // namespace

std::uint64_t RowStream::write_double(Hdf5File& file, const std::string& dataset, int width, const FillDouble& fill,
                                      Checksum checksum) const {
  return write<double>(file, dataset, width, each_row<double>(width, fill), checksum);
}

std::uint64_t RowStream::write_int64(Hdf5File& file, const std::string& dataset, int width, const FillInt& fill,
                                     Checksum checksum) const {
  return write<std::int64_t>(file, dataset, width, each_row<std::int64_t>(width, fill), checksum);
}

std::uint64_t RowStream::write_double_rows(Hdf5File& file, const std::string& dataset, int width,
                                           const FillDoubles& fill, Checksum checksum) const {
  return write<double>(file, dataset, width, fill, checksum);
}

std::uint64_t RowStream::write_int64_rows(Hdf5File& file, const std::string& dataset, int width,
                                          const FillInts& fill, Checksum checksum) const {
  return write<std::int64_t>(file, dataset, width, fill, checksum);
}

}  // namespace tissue
