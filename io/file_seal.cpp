#include "io/file_seal.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <iterator>
#include <cerrno>
#include <cstring>

#include "src/vector_clones.hpp"

namespace tissue {

namespace {

constexpr std::uint64_t kBasis = 1469598103934665603ULL, kPrime = 1099511628211ULL;
constexpr int kLanes = 16;
// Blocks whose pages are being written back, at most: the older half is waited for and dropped when it fills up.
constexpr std::size_t kWritingBlocks = 2 * kLanes;

// FNV-1a of 16 byte streams side by side: h[l] takes the n bytes at lane[l] (n a multiple of 8). FNV-1a is
// one chain of multiplications a byte; with AVX-512 (vpmullq) two vectors of 8 lanes each keep the multiplier busy
// (1.5-2.5x the bytes a second of 8 scalar lanes on a loaded machine: docs/benchmarks.md, "Snapshot writes at half
// of dd").
using Lanes8 = std::uint64_t __attribute__((vector_size(64)));
TISSUE_CLONES_V4 void fnv_16_lanes(std::uint64_t* h, const unsigned char* const* lane, std::size_t n) {
  Lanes8 lo, hi;
  std::memcpy(&lo, h, sizeof lo);
  std::memcpy(&hi, h + 8, sizeof hi);
  for (std::size_t i = 0; i < n; i += 8) {
    Lanes8 wl, wh;
    for (int l = 0; l < 8; ++l) {
      std::uint64_t w;
      std::memcpy(&w, lane[l] + i, 8);
      wl[l] = w;
      std::memcpy(&w, lane[l + 8] + i, 8);
      wh[l] = w;
    }
    for (int b = 0; b < 8; ++b) {  // little-endian: the lowest byte is the first
      lo = (lo ^ (wl & 0xff)) * kPrime;
      hi = (hi ^ (wh & 0xff)) * kPrime;
      wl >>= 8, wh >>= 8;
    }
  }
  std::memcpy(h, &lo, sizeof lo);
  std::memcpy(h + 8, &hi, sizeof hi);
}

std::uint64_t block_offset(std::uint64_t block) { return kSealUserBlock + block * kSealBlock; }

}  // namespace

bool hash_seal_blocks(int fd, std::uint64_t size, const std::uint64_t* blocks, int n, std::uint64_t* h,
                      std::vector<unsigned char>& buffer) {
  bool ok = fd >= 0;
  auto read = [&](std::uint64_t offset, std::size_t bytes, unsigned char* to) {
    if (ok && ::pread(fd, to, bytes, static_cast<off_t>(offset)) != static_cast<ssize_t>(bytes)) ok = false;
  };
  // Whole blocks side by side in the sixteen lanes; a short block (the file's last) alone, byte by byte.
  std::uint64_t lanes[kLanes];
  int whole[kLanes], wholes = 0;
  for (int i = 0; i < n; ++i) {
    const std::uint64_t offset = block_offset(blocks[i]);
    h[i] = kBasis;
    for (int b = 0; b < 8; ++b) h[i] = (h[i] ^ ((offset >> (8 * b)) & 0xff)) * kPrime;
    if (offset + kSealBlock <= size) {
      whole[wholes++] = i;
    } else if (offset < size) {
      const std::size_t bytes = static_cast<std::size_t>(size - offset);
      buffer.resize(kSealBlock);
      read(offset, bytes, buffer.data());
      for (std::size_t k = 0; k < bytes; ++k) h[i] = (h[i] ^ buffer[k]) * kPrime;
    }
  }
  if (wholes == 0 || !ok) return ok;
  for (int l = 0; l < kLanes; ++l) lanes[l] = l < wholes ? h[whole[l]] : kBasis;
  const unsigned char* lane[kLanes];
  // A sixteenth of each block at a time through 1 MiB of buffer (copied there by pread: hashing the page cache in
  // place through a mapping took 3x the time, sixteen streams from memory instead of one buffer in the cache).
  buffer.resize(kSealBlock);
  const std::size_t chunk = kSealBlock / kLanes;
  for (int l = 0; l < kLanes; ++l) lane[l] = &buffer[(l < wholes ? l : 0) * chunk];
  for (std::size_t c = 0; c < kLanes && ok; ++c) {
    for (int l = 0; l < wholes; ++l) read(block_offset(blocks[whole[l]]) + c * chunk, chunk, &buffer[l * chunk]);
    fnv_16_lanes(lanes, lane, chunk);
  }
  for (int l = 0; l < wholes; ++l) h[whole[l]] = lanes[l];
  return ok;
}

SealStream::SealStream(const std::string& path, bool background)
    : fd_(::open(path.c_str(), O_RDONLY | O_CLOEXEC)) {
  if (background && fd_ >= 0)
    worker_ = std::thread([this] {
      std::unique_lock<std::mutex> lock(mutex_);
      for (;;) {
        changed_.wait(lock, [this] { return closing_ || !queue_.empty(); });
        if (queue_.empty()) return;  // closing, nothing left
        std::vector<std::uint64_t> blocks = std::move(queue_.front());
        queue_.pop_front();
        busy_ = true;
        lock.unlock();
        hash(blocks);
        lock.lock();
        busy_ = false;
        changed_.notify_all();
      }
    });
}

SealStream::~SealStream() {
  stop();
  if (fd_ >= 0) ::close(fd_);
}

void SealStream::stop() {
  if (!worker_.joinable()) return;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    closing_ = true;
  }
  changed_.notify_all();
  worker_.join();
}

void SealStream::wrote(std::uint64_t offset, std::uint64_t bytes) {
  if (fd_ < 0 || bytes == 0) return;
  // A block is taken once this rank has written every byte of it in one run (its writes of a dataset follow each
  // other; datasets written a piece of each at a time are as many runs, side by side); a block begun by another
  // rank or by HDF5's metadata is left for the re-read at close. A write that continues no run starts one in
  // place of the one extended longest ago.
  Run* run = nullptr;
  for (Run& r : runs_)
    if (r.end == offset) run = &r;
  if (!run) {
    Run& oldest = *std::min_element(std::begin(runs_), std::end(runs_),
                                    [](const Run& x, const Run& y) { return x.used < y.used; });
    oldest.next_block = offset <= kSealUserBlock ? 0 : (offset - kSealUserBlock + kSealBlock - 1) / kSealBlock;
    run = &oldest;
  }
  run->end = offset + bytes;
  run->used = ++writes_;
  while (block_offset(run->next_block + 1) <= run->end) {
    pending_.push_back(run->next_block++);
    if (pending_.size() == static_cast<std::size_t>(kLanes)) hand_over();
  }
}

void SealStream::finish() {
  if (!pending_.empty()) hand_over();
  stop();
}

void SealStream::hand_over() {
  if (!worker_.joinable()) {
    hash(pending_);
  } else {
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait(lock, [this] { return queue_.size() < 2; });
    queue_.push_back(pending_);
  }
  changed_.notify_all();
  pending_.clear();
}

void SealStream::hash(const std::vector<std::uint64_t>& blocks) {
  std::uint64_t h[kLanes];
  const int n = static_cast<int>(blocks.size());
  const std::uint64_t size = block_offset(*std::max_element(blocks.begin(), blocks.end()) + 1);
  // The blocks are written: their pages go to the disk now, in the background (one call a run of consecutive
  // blocks), while they are hashed from the page cache (a page being written back reads as any other).
  for (int i = 0; i < n;) {
    int j = i + 1;
    while (j < n && blocks[j] == blocks[j - 1] + 1) ++j;
    ::sync_file_range(fd_, static_cast<off_t>(block_offset(blocks[i])),
                      static_cast<off_t>((blocks[j - 1] - blocks[i] + 1) * kSealBlock), SYNC_FILE_RANGE_WRITE);
    i = j;
  }
  if (hash_seal_blocks(fd_, size, blocks.data(), n, h, buffer_)) {
    for (int i = 0; i < n; ++i) {
      sum_ += h[i];
      hashed_.push_back(blocks[i]);
      if (mine_.size() <= blocks[i]) mine_.resize(blocks[i] + 1, 0);
      mine_[blocks[i]] = 1;
      writing_.push_back(blocks[i]);
    }
  }
  // The older half of the blocks on their way to the disk: wait until written (by now, mostly), then drop their
  // pages, which the next writes reuse. A failed write-back is kept for close() to report: the file's later fsync
  // would not see an error this call has already collected.
  if (writing_.size() >= kWritingBlocks) {
    const std::size_t old = writing_.size() - kLanes;
    // Each run of consecutive blocks in one call, from the 2 MiB boundary below it: the kernel drops only the
    // page-cache folios (up to 2 MiB) that lie wholly inside the range, and the blocks start 512 bytes past a page.
    // Below the run's first block lie blocks hashed before it (or a page that is still dirty, which is kept).
    for (std::size_t i = 0; i < old;) {
      std::size_t j = i + 1;
      while (j < old && writing_[j] == writing_[j - 1] + 1) ++j;
      const std::uint64_t begin = block_offset(writing_[i]), end = block_offset(writing_[j - 1] + 1);
      if (::sync_file_range(fd_, static_cast<off_t>(begin), static_cast<off_t>(end - begin),
                            SYNC_FILE_RANGE_WAIT_BEFORE | SYNC_FILE_RANGE_WRITE | SYNC_FILE_RANGE_WAIT_AFTER) != 0) {
        if (!error_) error_ = errno ? errno : EIO;
      } else {
        // Only over blocks this rank hashed: another rank's block below may be written back but not hashed yet
        // (ranks' parts alternate), and dropping it would make that rank read it back from the disk.
        std::uint64_t from = begin / (2 * kSealBlock) * (2 * kSealBlock);
        for (std::uint64_t b = writing_[i]; from < begin && b-- > 0 && block_offset(b + 1) > from;)
          if (b >= mine_.size() || !mine_[b]) from = begin;
        ::posix_fadvise(fd_, static_cast<off_t>(from), static_cast<off_t>(end - from), POSIX_FADV_DONTNEED);
      }
      i = j;
    }
    writing_.erase(writing_.begin(), writing_.begin() + static_cast<std::ptrdiff_t>(old));
  }
}

}  // namespace tissue
