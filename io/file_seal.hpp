// The seal's hash of the files tissue writes (io/hdf5_file.hpp): the sum (mod 2^64), over the 1 MiB blocks that
// follow the 512-byte user block, of FNV-1a(the block's file offset as 8 little-endian bytes, the block's bytes).
// Order-independent: any split of the blocks among ranks, and any order of hashing them, gives the same sum.
//
// SealStream hashes a written file's blocks while the file is written, so that closing it re-reads only the few
// blocks no rank wrote whole (HDF5's metadata, the boundaries between datasets and between ranks' rows), and it
// recycles the file's page cache: each hashed block's pages are written to the disk in the background and dropped
// once written, so the file occupies a few tens of MB of page cache, reused, instead of the whole file in pages
// taken fresh from the system (on this project's virtual machines a fresh page's first touch cost more than
// writing it: docs/benchmarks.md, "Snapshot writes at the disk's pace").
#pragma once
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace tissue {

constexpr std::uint64_t kSealUserBlock = 512;
constexpr std::uint64_t kSealBlock = std::uint64_t{1} << 20;

// The number of seal blocks of a file of `size` bytes.
inline std::uint64_t seal_blocks(std::uint64_t size) {
  return size > kSealUserBlock ? (size - kSealUserBlock + kSealBlock - 1) / kSealBlock : 0;
}

// The hashes h[0..n) of the seal blocks blocks[0..n) (n <= 16, any blocks, the last one possibly short) of the
// open file fd of `size` bytes, read with pread through `buffer` (resized to kSealBlock). False if a read failed.
bool hash_seal_blocks(int fd, std::uint64_t size, const std::uint64_t* blocks, int n, std::uint64_t* h,
                      std::vector<unsigned char>& buffer);

// One rank's side of a file being written. Not collective; every call is a hint that may fail silently (the block
// is then hashed when the file is closed), except a failed write-back, which error() reports (errno).
// `background`: the blocks are hashed, written back and dropped by a thread of this stream's own (no MPI call), while
// the caller goes on filling and writing rows; for a rank with a core to spare (Hdf5File::create: fewer ranks than
// cores). At most two groups of sixteen blocks wait for it: a writer faster than the hashing waits.
class SealStream {
public:
  explicit SealStream(const std::string& path, bool background = false);  // the file being written (opened here)
  ~SealStream();
  SealStream(const SealStream&) = delete;
  SealStream& operator=(const SealStream&) = delete;

  // This rank has written the file's bytes [offset, offset + bytes) (raw data: HDF5 writes nothing else there).
  void wrote(std::uint64_t offset, std::uint64_t bytes);
  // Hashes the blocks still waiting for a group of sixteen (and waits for the thread); call before the file's
  // metadata is written. hashed(), sum() and error() are this rank's whole part after it.
  void finish();
  // The blocks hashed here (each written whole by this rank) and the sum of their hashes.
  const std::vector<std::uint64_t>& hashed() const { return hashed_; }
  std::uint64_t sum() const { return sum_; }
  int error() const { return error_; }

private:
  void hand_over();  // pending_ to the thread, or hashed here
  void hash(const std::vector<std::uint64_t>& blocks);
  void stop();

  std::thread worker_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<std::vector<std::uint64_t>> queue_;  // groups handed to the thread
  bool busy_ = false, closing_ = false;

  int fd_ = -1;
  // Runs of bytes this rank wrote without a gap: where each ends, its first block not yet taken, and when it was
  // last extended (a count of writes). A run per dataset being written (Hdf5File::write_pieces_together: three).
  struct Run {
    std::uint64_t end = ~std::uint64_t{0}, next_block = 0, used = 0;
  };
  Run runs_[4] = {{0, 0, 0}};
  std::uint64_t writes_ = 0;
  std::vector<std::uint64_t> pending_, hashed_;
  std::vector<std::uint64_t> writing_;  // hashed blocks whose pages are being written back, oldest first
  std::vector<char> mine_;              // by block: hashed here
  std::vector<unsigned char> buffer_;
  std::uint64_t sum_ = 0;
  int error_ = 0;
};

}  // namespace tissue
