#include "io/hdf5_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <deque>
#include <cstdint>
#include <thread>
#include <vector>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <utility>

#include "io/file_seal.hpp"
#include "io/isolated_parse.hpp"
#include "partition/agreement.hpp"

namespace tissue {

namespace {

// Closes an HDF5 identifier of any kind when it goes out of scope.
class Handle {
public:
  Handle(hid_t id, herr_t (*closer)(hid_t)) : id_(id), closer_(closer) {}
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  ~Handle() {
    if (id_ >= 0) closer_(id_);
  }
  hid_t get() const { return id_; }
  bool ok() const { return id_ >= 0; }
  hid_t release() { return std::exchange(id_, -1); }
  void reset(hid_t id) {
    if (id_ >= 0) closer_(id_);
    id_ = id;
  }

private:
  hid_t id_;
  herr_t (*closer_)(hid_t);
};

// The innermost (first-failing) message of HDF5's error stack: the most specific reason.
herr_t first_error(unsigned n, const H5E_error2_t* err, void* out) {
  if (n == 0 && err->desc) *static_cast<std::string*>(out) = err->desc;
  return 0;
}

std::string hdf5_reason() {
  std::string reason;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, first_error, &reason);
  H5Eclear2(H5E_DEFAULT);
  return reason;
}

// The system error behind a failed HDF5 or MPI-IO call, when the call left one that says what went wrong on the
// disk (the MPI-IO layer reports "MPI_ERR_OTHER" or similar for a full disk; errno still holds the cause).
// Only the errors a write itself can meet are believed: the MPI-IO layer makes other calls after the failed one
// (ENOENT was seen after an EIO), and a wrong reason is worse than none.
std::string system_error(int err) {
  switch (err) {
    case ENOSPC: case EDQUOT: case EIO: case EROFS: case EFBIG:
      return std::strerror(err);
    default:
      return "";
  }
}

void quiet_hdf5() {
  // One-line exceptions instead of HDF5's multi-line stack dump on stderr.
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
}

void check_mpi(int rc, const std::string& path, const char* what) {
  if (rc != MPI_SUCCESS) {
    char msg[MPI_MAX_ERROR_STRING];
    int len = 0;
    MPI_Error_string(rc, msg, &len);
    throw std::runtime_error(path + ": " + what + " failed: " + std::string(msg, len));
  }
}

hid_t file_access(MPI_Comm comm) {
  hid_t fapl = H5Pcreate(H5P_FILE_ACCESS);
  if (fapl < 0) return fapl;
  if (H5Pset_fapl_mpio(fapl, comm, MPI_INFO_NULL) < 0) {
    H5Pclose(fapl);
    return -1;
  }
  return fapl;
}

// The seal: every file tissue writes starts with a 512-byte HDF5 user block (ignored by HDF5, h5py, ParaView)
// holding "TISSUE-HDF5-SEAL 1 <size> <hash>": the file's size and a hash of all its bytes after the user block.
// Readers check it before HDF5 parses anything, so a truncated, damaged or foreign file is refused with one line
// instead of reaching HDF5's parser (which can crash on corrupt metadata).
constexpr std::size_t kUserBlock = kSealUserBlock;

// Set when a file was abandoned after a failed write (Hdf5File::abandon): see hdf5_files_abandoned().
bool abandoned_files = false;
const char kSealTag[] = "TISSUE-HDF5-SEAL 1 ";

// The seal's hash (io/file_seal.hpp) of the file's blocks, split among the ranks: each rank hashes its share of the
// blocks that no rank hashed while writing (`stream`: this rank's side of a file being written; null for a file
// being read, whose every block is hashed here), and one reduction gives the total.
std::uint64_t seal_hash(const std::string& path, std::uint64_t size, MPI_Comm comm,
                        const SealStream* stream = nullptr) {
  int rank = 0, ranks = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &ranks);
  const std::uint64_t blocks = seal_blocks(size);
  std::vector<std::uint64_t> left;
  std::uint64_t sum = 0;
  if (stream) {
    // Blocks written whole lie inside the file; if not (this rank's bookkeeping is wrong), its blocks are re-read.
    const auto& hashed = stream->hashed();
    const bool inside = std::all_of(hashed.begin(), hashed.end(), [&](std::uint64_t b) { return b < blocks; });
    std::vector<unsigned char> done(blocks, 0);
    if (inside) {
      for (const std::uint64_t b : hashed) done[b] = 1;
      sum = stream->sum();
    }
    MPI_Allreduce(MPI_IN_PLACE, done.data(), static_cast<int>(blocks), MPI_UNSIGNED_CHAR, MPI_MAX, comm);
    for (std::uint64_t b = 0; b < blocks; ++b)
      if (!done[b]) left.push_back(b);
  } else {
    left.resize(blocks);
    for (std::uint64_t b = 0; b < blocks; ++b) left[b] = b;
  }
  const std::size_t first = left.size() * rank / ranks, last = left.size() * (rank + 1) / ranks;
  int failed = 0;
  if (first < last) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    std::vector<unsigned char> buffer;
    std::uint64_t h[16];
    for (std::size_t b = first; b < last && !failed; b += 16) {
      const int n = static_cast<int>(std::min<std::size_t>(16, last - b));
      if (!hash_seal_blocks(fd, size, &left[b], n, h, buffer)) failed = 1;
      for (int i = 0; i < n; ++i) sum += h[i];
    }
    if (fd < 0) failed = 1;
    else ::close(fd);
  }
  std::uint64_t total = 0;
  int any = 0;
  MPI_Allreduce(&sum, &total, 1, MPI_UINT64_T, MPI_SUM, comm);
  MPI_Allreduce(&failed, &any, 1, MPI_INT, MPI_MAX, comm);
  if (any) throw std::runtime_error(path + ": cannot read the file back");
  return total;
}

std::uint64_t file_size(const std::string& path) {
  struct stat st;
  return ::stat(path.c_str(), &st) == 0 ? static_cast<std::uint64_t>(st.st_size) : 0;
}

// Collective: checks the seal of a file before HDF5 opens it. Throws one line saying what is wrong.
void verify_seal(const std::string& path, MPI_Comm comm) {
  char header[kUserBlock + 1] = {0};
  int ok = 0;
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  if (rank == 0) {
    int fd = ::open(path.c_str(), O_RDONLY);
    if (fd >= 0) {
      ok = ::pread(fd, header, kUserBlock, 0) == static_cast<ssize_t>(kUserBlock);
      ::close(fd);
    }
  }
  MPI_Bcast(&ok, 1, MPI_INT, 0, comm);
  MPI_Bcast(header, kUserBlock, MPI_CHAR, 0, comm);
  unsigned long long size = 0, hash = 0;
  if (!ok || std::strncmp(header, kSealTag, sizeof kSealTag - 1) != 0 ||
      std::sscanf(header + sizeof kSealTag - 1, "%llu %llx", &size, &hash) != 2)
    throw std::runtime_error(path + ": not a file written by tissue (no seal in its first 512 bytes)");
  // The hash covers the bytes after the user block only: the block itself must be exactly what the writer puts
  // there (the seal line, then zeros), so that no byte of the file escapes the check.
  char expected[kUserBlock] = {0};
  std::snprintf(expected, sizeof expected, "%s%llu %016llx\n", kSealTag, size, hash);
  if (std::memcmp(header, expected, kUserBlock) != 0)
    throw std::runtime_error(path + ": damaged: its seal block (the first 512 bytes) was altered");
  const std::uint64_t actual = file_size(path);
  if (actual != size)
    throw std::runtime_error(path + ": truncated or extended: " + std::to_string(actual) + " bytes, sealed at " +
                             std::to_string(size));
  if (seal_hash(path, size, comm) != hash) throw std::runtime_error(path + ": damaged: its bytes do not match its seal");
}

}  // namespace

Hdf5File::Hdf5File(std::string path, MPI_Comm comm, bool writable)
    : path_(std::move(path)), comm_(comm), writable_(writable) {}

Hdf5File Hdf5File::create(const std::string& path, MPI_Comm comm, int64_t reserve) {
  quiet_hdf5();
  Hdf5File f(path, comm, true);
  Handle fapl(file_access(comm), H5Pclose);
  if (!fapl.ok()) f.fail("", "cannot set up MPI-IO file access");
  Handle fcpl(H5Pcreate(H5P_FILE_CREATE), H5Pclose);
  if (!fcpl.ok() || H5Pset_userblock(fcpl.get(), kUserBlock) < 0) f.fail("", "cannot reserve the seal's user block");
  // Agreed: a rank that could not create the file must not leave the others writing into it alone.
  try {
    agree(comm, [&] {
      errno = 0;
      f.file_ = H5Fcreate((path + ".tmp").c_str(), H5F_ACC_TRUNC, fcpl.get(), fapl.get());
      if (f.file_ < 0) f.fail_io("", "cannot create " + path + ".tmp", errno);
      // The seal's hashing on a thread of its own when this rank has a core to spare (the ranks fewer than the
      // cores: a rank a node, or fewer, is assumed; more ranks than cores would only take turns).
      int ranks = 1;
      MPI_Comm_size(comm, &ranks);
      f.seal_ = std::make_unique<SealStream>(path + ".tmp", static_cast<unsigned>(ranks) < std::thread::hardware_concurrency());
    });
    if (reserve > 0)
      agree(comm, [&] {
        int rank = 0;
        MPI_Comm_rank(comm, &rank);
        if (rank != 0) return;
        const std::string tmp = path + ".tmp";
        const int fd = ::open(tmp.c_str(), O_WRONLY | O_CLOEXEC);
        if (fd < 0) throw OutputError(path + ": cannot open " + tmp + ": " + std::strerror(errno));
        const int rc = ::fallocate(fd, FALLOC_FL_KEEP_SIZE, 0, static_cast<off_t>(reserve));
        const int err = errno;
        ::close(fd);
        if (rc != 0 && err != EOPNOTSUPP && err != ENOSYS && err != EINVAL)  // not supported: the writes will tell
          throw OutputError(path + ": cannot reserve " + std::to_string((reserve + 999999) / 1000000) + " MB for " +
                            tmp + ": " + std::strerror(err));
      });
  } catch (...) {
    f.abandon();  // a rank may hold the file and another not: no collective close (rank 0 removes the .tmp)
    throw;
  }
  return f;
}

Hdf5File Hdf5File::open(const std::string& path, MPI_Comm comm, const std::string& what, const Walk& walk) {
  quiet_hdf5();
  verify_seal(path, comm);
  parse_isolated(path, what, comm, [&] {
    Hdf5File copy = open_serial(path);
    if (walk) walk(copy);
    copy.close();
  });
  return open_parsed(path, comm, false);
}

Hdf5File Hdf5File::open_walked(const std::string& path, MPI_Comm comm) { return open_parsed(path, comm, true); }

Hdf5File Hdf5File::open_parsed(const std::string& path, MPI_Comm comm, bool check_seal) {
  quiet_hdf5();
  Hdf5File f(path, comm, false);
  if (check_seal) verify_seal(path, comm);
  Handle fapl(file_access(comm), H5Pclose);
  if (!fapl.ok()) f.fail("", "cannot set up MPI-IO file access");
  f.file_ = H5Fopen(path.c_str(), H5F_ACC_RDONLY, fapl.get());
  if (f.file_ < 0) f.fail("", "cannot open");
  return f;
}

Hdf5File Hdf5File::open_serial(const std::string& path) {
  quiet_hdf5();
  Hdf5File f(path, MPI_COMM_NULL, false);
  f.file_ = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);  // the default file access: the sec2 driver
  if (f.file_ < 0) f.fail("", "cannot open");
  return f;
}

Hdf5File::Hdf5File(Hdf5File&& o) noexcept
    : path_(std::move(o.path_)),
      comm_(o.comm_),
      writable_(o.writable_),
      file_(std::exchange(o.file_, -1)),
      seal_(std::move(o.seal_)) {}

Hdf5File& Hdf5File::operator=(Hdf5File&& o) noexcept {
  if (this != &o) {
    release();
    path_ = std::move(o.path_);
    comm_ = o.comm_;
    writable_ = o.writable_;
    file_ = std::exchange(o.file_, -1);
    seal_ = std::move(o.seal_);
  }
  return *this;
}

Hdf5File::~Hdf5File() { release(); }

void Hdf5File::release() noexcept {
  seal_.reset();
  if (file_ < 0) return;
  H5Fclose(file_);
  file_ = -1;
  if (writable_) {
    int rank = 0;
    MPI_Comm_rank(comm_, &rank);
    if (rank == 0) std::remove((path_ + ".tmp").c_str());
  }
}

void Hdf5File::close() {
  if (file_ < 0) return;
  int rank = 0;
  MPI_Comm_rank(comm_, &rank);
  const std::string tmp = path_ + ".tmp";
  if (!writable_) {
    const herr_t rc = H5Fclose(file_);
    file_ = -1;
    if (rc < 0) {
      const std::string reason = hdf5_reason();
      throw std::runtime_error(path_ + ": cannot close" + (reason.empty() ? "" : ": " + reason));
    }
    return;
  }
  // Written files: every step is agreed (io/agreement), so that a rank whose flush, seal or rename fails stops
  // every rank with the same line, and no .tmp stays behind.
  try {
    // The raw data's blocks still waiting for a group are hashed now (io/file_seal.hpp); a page of it that could
    // not be written back fails the file here, as its fsync would have.
    agree(comm_, [&] {
      if (!seal_) return;
      seal_->finish();
      if (seal_->error())
        throw OutputError(path_ + ": cannot write " + tmp + ": " + std::strerror(seal_->error()));
    });
    agree(comm_, [&] {
      errno = 0;
      const herr_t rc = H5Fclose(file_);
      const int err = errno;
      file_ = -1;
      if (rc < 0) {
        const std::string reason = hdf5_reason();
        std::string system = system_error(err);
        if (system.empty()) system = probe_write_error(tmp);  // errno lost inside MPI-IO (see fail_io)
        throw OutputError(path_ + ": cannot write " + tmp + ": " +
                          (system.empty() ? "the file could not be flushed and closed" : system) +
                          (reason.empty() ? "" : " (" + reason + ")"));
      }
    });
    // Every rank's data is on disk before the file appears under its real name.
    agree(comm_, [&] {
      const std::uint64_t size = file_size(tmp);
      const std::uint64_t hash = seal_hash(tmp, size, comm_, seal_.get());  // collective; throws on every rank
      seal_.reset();
      if (rank != 0) return;
      // Seal, then flush to the disk before the name appears: after a power loss a published name holds it all.
      char header[kUserBlock] = {0};
      std::snprintf(header, sizeof header, "%s%llu %016llx\n", kSealTag, static_cast<unsigned long long>(size),
                    static_cast<unsigned long long>(hash));
      const int fd = ::open(tmp.c_str(), O_WRONLY);
      if (fd < 0) throw OutputError(path_ + ": cannot open " + tmp + " to seal it: " + std::strerror(errno));
      const char* step = "write the seal of";
      // Growing by a byte and shrinking back to its size gives back the space reserved beyond the end (create()):
      // only a shrinking truncate frees preallocated blocks on every file system (XFS keeps them otherwise).
      bool ok = ::pwrite(fd, header, kUserBlock, 0) == static_cast<ssize_t>(kUserBlock);
      if (ok)
        step = "truncate", ok = ::ftruncate(fd, static_cast<off_t>(size) + 1) == 0 &&
                                ::ftruncate(fd, static_cast<off_t>(size)) == 0;
      if (ok) step = "fsync", ok = ::fsync(fd) == 0;
      const int err = errno;
      ::close(fd);
      if (!ok) throw OutputError(path_ + ": cannot " + step + " " + tmp + ": " + std::strerror(err ? err : EIO));
      if (std::rename(tmp.c_str(), path_.c_str()) != 0)
        throw OutputError(path_ + ": cannot rename " + tmp + " into place: " + std::strerror(errno));
    });
  } catch (...) {
    abandoned_files = true;  // a failed H5Fclose may leave HDF5 state behind: the process must not finalize HDF5
    if (rank == 0) std::remove(tmp.c_str());
    throw;
  }
}

void Hdf5File::abandon() noexcept {
  seal_.reset();
  if (file_ >= 0) {
    file_ = -1;  // the identifier is leaked on purpose: closing it is a collective that cannot complete
    abandoned_files = true;
  }
  if (writable_ && comm_ != MPI_COMM_NULL) {
    int rank = 0;
    MPI_Comm_rank(comm_, &rank);
    if (rank == 0) std::remove((path_ + ".tmp").c_str());
  }
}

bool hdf5_files_abandoned() { return abandoned_files; }

void Hdf5File::fail_io(const std::string& object, const std::string& what, int err) const {
  const std::string reason = hdf5_reason();
  std::string system = system_error(err);
  // Open MPI's MPI-IO layer reports a failed pwrite or open only as MPI_ERR_OTHER and may leave errno at 0: ask
  // the system what writing this file says now (a full disk, a quota, a failing device tell again).
  if (system.empty() && writable_) system = probe_write_error(path_ + ".tmp");
  std::string msg = path_ + ": ";
  if (!object.empty()) msg += object + ": ";
  msg += what;
  if (!system.empty()) msg += ": " + system;
  if (!reason.empty()) msg += " (" + reason + ")";
  throw OutputError(msg);
}

void Hdf5File::fail(const std::string& object, const std::string& what) const {
  const std::string reason = hdf5_reason();
  std::string msg = path_ + ": ";
  if (!object.empty()) msg += object + ": ";
  msg += what;
  if (!reason.empty()) msg += " (" + reason + ")";
  throw std::runtime_error(msg);
}

bool Hdf5File::exists(const std::string& object) const {
  if (file_ < 0) fail(object, "file is closed");
  if (object.empty() || object[0] != '/') fail(object, "path must be absolute");
  // H5Lexists fails, rather than answering no, when a parent is missing: walk the path one link at a time.
  size_t pos = 1;
  while (pos < object.size()) {
    size_t next = object.find('/', pos);
    if (next == std::string::npos) next = object.size();
    const std::string prefix = object.substr(0, next);
    const htri_t e = H5Lexists(file_, prefix.c_str(), H5P_DEFAULT);
    if (e < 0) fail(object, "cannot look up " + prefix);
    if (e == 0) return false;
    pos = next + 1;
  }
  return true;
}

void Hdf5File::create_group(const std::string& group) {
  if (!writable_) fail(group, "file is open read-only");
  if (exists(group)) return;
  Handle lcpl(H5Pcreate(H5P_LINK_CREATE), H5Pclose);
  if (!lcpl.ok() || H5Pset_create_intermediate_group(lcpl.get(), 1) < 0) fail(group, "cannot set up group creation");
  Handle g(H5Gcreate2(file_, group.c_str(), lcpl.get(), H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
  if (!g.ok()) fail(group, "cannot create group");
}

void Hdf5File::write(const std::string& dataset, int64_t global_rows, int width, int64_t offset, int64_t rows,
                     const double* data) {
  write_block(dataset, global_rows, width, offset, rows, data, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE);
}

void Hdf5File::write(const std::string& dataset, int64_t global_rows, int width, int64_t offset, int64_t rows,
                     const int64_t* data) {
  write_block(dataset, global_rows, width, offset, rows, data, H5T_STD_I64LE, H5T_NATIVE_INT64);
}

void Hdf5File::write_block(const std::string& dataset, int64_t global_rows, int width, int64_t offset, int64_t rows,
                           const void* data, hid_t file_type, hid_t mem_type) {
  // Ranks that disagree on the shape, or a block outside it, would hang or corrupt the collective write:
  // agree first, so that every rank throws the same error.
  const int bad = offset < 0 || rows < 0 || width <= 0 || offset + rows > global_rows || (rows > 0 && !data);
  int any_bad = 0;
  check_mpi(MPI_Allreduce(&bad, &any_bad, 1, MPI_INT, MPI_MAX, comm_), path_, "MPI_Allreduce");
  if (any_bad)
    throw std::runtime_error(path_ + ": " + dataset + ": a rank's row block lies outside [0, " +
                             std::to_string(global_rows) + ") or has no data");
  write_pieces(dataset, global_rows, width, file_type, mem_type, 1, [&](int64_t, int64_t* o, int64_t* r) {
    *o = offset, *r = rows;
    return data;
  });
}

void Hdf5File::write_pieces(const std::string& dataset, int64_t global_rows, int width, bool integer, int64_t pieces,
                            const Piece& piece, bool independent, const Placed& placed) {
  write_pieces(dataset, global_rows, width, integer ? H5T_STD_I64LE : H5T_IEEE_F64LE,
               integer ? H5T_NATIVE_INT64 : H5T_NATIVE_DOUBLE, pieces, piece, independent, placed);
}

void Hdf5File::write_pieces(const std::string& dataset, int64_t global_rows, int width, hid_t file_type,
                            hid_t mem_type, int64_t pieces, const Piece& piece, bool independent,
                            const Placed& placed) {
  write_columns({{dataset, width, file_type, mem_type}}, global_rows, pieces,
                [&](int64_t p, const void** data, int64_t* offset, int64_t* rows) { data[0] = piece(p, offset, rows); },
                independent, placed);
}

void Hdf5File::write_pieces_together(const std::vector<Column>& columns, int64_t global_rows, int64_t pieces,
                                     const Pieces& piece) {
  std::vector<TypedColumn> typed;
  for (const Column& c : columns)
    typed.push_back({c.dataset, c.width, c.integer ? H5T_STD_I64LE : H5T_IEEE_F64LE,
                     c.integer ? H5T_NATIVE_INT64 : H5T_NATIVE_DOUBLE});
  write_columns(typed, global_rows, pieces, piece, true, nullptr);
}

void Hdf5File::write_columns(const std::vector<TypedColumn>& columns, int64_t global_rows, int64_t pieces,
                             const Pieces& piece, bool independent, const Placed& placed) {
  const std::size_t n_columns = columns.size();
  const std::string& first_name = n_columns > 0 ? columns[0].dataset : std::string();
  if (!writable_ || file_ < 0) fail(first_name, "file is not open for writing");
  std::vector<long long> mine, all(3 + 2 * n_columns);
  mine = {global_rows, -global_rows, pieces};
  for (const TypedColumn& c : columns) mine.push_back(c.width), mine.push_back(-c.width);
  check_mpi(MPI_Allreduce(mine.data(), all.data(), static_cast<int>(mine.size()), MPI_LONG_LONG, MPI_MAX, comm_),
            path_, "MPI_Allreduce");
  bool disagree = all[0] != -all[1] || all[2] != pieces;
  for (std::size_t i = 0; i < n_columns; ++i)
    disagree = disagree || all[3 + 2 * i] != -all[4 + 2 * i] || columns[i].width <= 0;
  if (disagree || n_columns == 0)
    throw std::runtime_error(path_ + ": " + first_name + ": ranks disagree on the dataset's shape");

  std::deque<Handle> file_spaces;  // Handle does not move: a deque builds each in place
  for (const TypedColumn& c : columns) {
    const hsize_t dims[2] = {static_cast<hsize_t>(global_rows), static_cast<hsize_t>(c.width)};
    file_spaces.emplace_back(H5Screate_simple(2, dims, nullptr), H5Sclose);
    if (!file_spaces.back().ok()) fail(c.dataset, "cannot create dataspace");
  }
  Handle lcpl(H5Pcreate(H5P_LINK_CREATE), H5Pclose);
  if (!lcpl.ok() || H5Pset_create_intermediate_group(lcpl.get(), 1) < 0) fail(first_name, "cannot set up creation");
  // Every row is written: skip the fill pass that would otherwise write the whole dataset twice.
  Handle dcpl(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
  if (!dcpl.ok() || H5Pset_fill_time(dcpl.get(), H5D_FILL_TIME_NEVER) < 0 ||
      H5Pset_alloc_time(dcpl.get(), H5D_ALLOC_TIME_EARLY) < 0)
    fail(first_name, "cannot set up creation");
  // Each rank writes its rows alone (independent MPI-IO), in writes of at most kWriteBytes: a rank's rows of a
  // piece are one contiguous run of the file, so a collective write would only add the aggregators' copy, and the
  // kernel takes several times the system time for one write of a few MB as for the same bytes in writes of 1 MiB
  // (docs/benchmarks.md, "Snapshot writes at half of dd"; dd writes 1 MiB blocks too).
  constexpr int64_t kWriteBytes = int64_t{1} << 20;
  Handle dxpl(H5Pcreate(H5P_DATASET_XFER), H5Pclose);
  if (!dxpl.ok() || H5Pset_dxpl_mpio(dxpl.get(), H5FD_MPIO_INDEPENDENT) < 0)
    fail(first_name, "cannot set up transfer");
  // From here the work is agreed: a rank whose write fails (a full disk, a quota, an I/O error) stops every rank
  // with its line instead of leaving them in the file's next collective. The file is then abandoned, not closed:
  // after a failed write HDF5's ranks no longer agree on what closing it takes (one flushes its metadata in a
  // collective, another has given up and truncates in another: a hang, seen with the fault tests).
  try {
    std::deque<Handle> dsets;
    for (std::size_t i = 0; i < n_columns; ++i) dsets.emplace_back(-1, H5Dclose);
    agree(comm_, [&] {
      for (std::size_t i = 0; i < n_columns; ++i) {
        errno = 0;
        dsets[i].reset(H5Dcreate2(file_, columns[i].dataset.c_str(), columns[i].file_type, file_spaces[i].get(),
                                  lcpl.get(), dcpl.get(), H5P_DEFAULT));
        if (!dsets[i].ok()) fail_io(columns[i].dataset, "cannot create dataset", errno);
      }
    });
    // Where the rows lie in the file (contiguous, allocated at creation): the seal hashes the blocks this rank
    // writes whole as it goes (io/file_seal.hpp).
    std::vector<haddr_t> bases(n_columns);
    for (std::size_t i = 0; i < n_columns; ++i) bases[i] = H5Dget_offset(dsets[i].get());
    if (placed) placed(bases[0] != HADDR_UNDEF ? static_cast<int64_t>(bases[0]) : -1);
    // Each rank's rows of a piece are one block of the file's rows.
    auto bad_block = [&](int64_t offset, int64_t rows, const void* const* data) {
      bool bad = offset < 0 || rows < 0 || offset + rows > global_rows;
      for (std::size_t i = 0; i < n_columns; ++i) bad = bad || (rows > 0 && !data[i]);
      return bad;
    };
    auto bad_block_error = [&] {
      return std::runtime_error(path_ + ": " + first_name + ": a rank's row block lies outside [0, " +
                                std::to_string(global_rows) + ") or has no data");
    };
    auto write_rows = [&](std::size_t i, int64_t offset, int64_t rows, const void* data) {
      const TypedColumn& c = columns[i];
      const int64_t rows_a_write = std::max<int64_t>(1, kWriteBytes / (8 * static_cast<int64_t>(c.width)));
      SealStream* seal = bases[i] != HADDR_UNDEF ? seal_.get() : nullptr;
      for (int64_t done = 0; done < rows; done += rows_a_write) {
        const int64_t n = std::min(rows_a_write, rows - done);
        Handle space(H5Scopy(file_spaces[i].get()), H5Sclose);
        const hsize_t start[2] = {static_cast<hsize_t>(offset + done), 0};
        const hsize_t count[2] = {static_cast<hsize_t>(n), static_cast<hsize_t>(c.width)};
        Handle mem_space(H5Screate_simple(2, count, nullptr), H5Sclose);
        if (!space.ok() || !mem_space.ok()) fail(c.dataset, "cannot create dataspace");
        if (H5Sselect_hyperslab(space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr) < 0)
          fail(c.dataset, "cannot select rows");
        errno = 0;
        const char* from = static_cast<const char*>(data) + done * c.width * 8;
        if (H5Dwrite(dsets[i].get(), c.mem_type, mem_space.get(), space.get(), dxpl.get(), from) < 0)
          fail_io(c.dataset, "cannot write rows [" + std::to_string(offset + done) + ", " +
                             std::to_string(offset + done + n) + ")", errno);
        if (seal) seal->wrote(bases[i] + static_cast<std::uint64_t>((offset + done) * c.width * 8), n * c.width * 8);
      }
    };
    std::vector<const void*> data(n_columns, nullptr);
    if (independent) {
      // No rank waits for another between its pieces: one agreement after the last.
      agree(comm_, [&] {
        for (int64_t p = 0; p < pieces; ++p) {
          int64_t offset = 0, rows = 0;
          std::fill(data.begin(), data.end(), nullptr);
          piece(p, data.data(), &offset, &rows);
          if (bad_block(offset, rows, data.data())) throw bad_block_error();
          for (std::size_t i = 0; i < n_columns; ++i) write_rows(i, offset, rows, data[i]);
        }
      });
    } else {
      // piece() exchanges rows point to point with the other ranks' piece() calls: every rank calls it for every
      // piece, whatever failed, so that no rank waits for a message that never comes, and the ranks agree once,
      // after the last piece (no collective between pieces: a rank runs up to a piece ahead of another). A rank
      // that failed (what piece() threw, a bad block, a write) writes nothing more and throws, on every rank, the
      // first failing rank's error (agree_on).
      std::exception_ptr failed;
      for (int64_t p = 0; p < pieces; ++p) {
        int64_t offset = 0, rows = 0;
        try {
          std::fill(data.begin(), data.end(), nullptr);
          piece(p, data.data(), &offset, &rows);
          if (!failed && bad_block(offset, rows, data.data())) throw bad_block_error();
          if (!failed)
            for (std::size_t i = 0; i < n_columns; ++i) write_rows(i, offset, rows, data[i]);
        } catch (...) {
          if (!failed) failed = std::current_exception();
        }
      }
      agree_on(comm_, failed);
    }
  } catch (...) {
    abandon();
    throw;
  }
}

std::vector<int64_t> Hdf5File::shape(const std::string& dataset) const {
  if (file_ < 0) fail(dataset, "file is closed");
  Handle dset(H5Dopen2(file_, dataset.c_str(), H5P_DEFAULT), H5Dclose);
  if (!dset.ok()) fail(dataset, "no such dataset");
  Handle space(H5Dget_space(dset.get()), H5Sclose);
  if (!space.ok()) fail(dataset, "cannot get dataspace");
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank < 1 || rank > 2) fail(dataset, "expected a 1-D or 2-D dataset, found rank " + std::to_string(rank));
  hsize_t dims[2] = {0, 1};
  if (H5Sget_simple_extent_dims(space.get(), dims, nullptr) < 0) fail(dataset, "cannot get dimensions");
  return {static_cast<int64_t>(dims[0]), static_cast<int64_t>(rank == 2 ? dims[1] : 1)};
}

void Hdf5File::check_plain(const std::string& dataset, bool integer) const {
  if (file_ < 0) fail(dataset, "file is closed");
  Handle dset(H5Dopen2(file_, dataset.c_str(), H5P_DEFAULT), H5Dclose);
  if (!dset.ok()) fail(dataset, "no such dataset");
  Handle type(H5Dget_type(dset.get()), H5Tclose);
  if (!type.ok()) fail(dataset, "cannot get the datatype");
  if (H5Tget_class(type.get()) != (integer ? H5T_INTEGER : H5T_FLOAT) || H5Tget_size(type.get()) != 8)
    fail(dataset, std::string("is not stored as 8-byte ") + (integer ? "integers" : "floating-point numbers"));
  Handle dcpl(H5Dget_create_plist(dset.get()), H5Pclose);
  if (!dcpl.ok()) fail(dataset, "cannot get the creation properties");
  if (H5Pget_layout(dcpl.get()) != H5D_CONTIGUOUS || H5Pget_nfilters(dcpl.get()) != 0)
    fail(dataset, "is not stored contiguously without filters (as tissue writes it)");
}

std::vector<double> Hdf5File::read_double(const std::string& dataset, int64_t offset, int64_t rows) const {
  const auto s = shape(dataset);
  std::vector<double> out(static_cast<size_t>(rows > 0 ? rows : 0) * s[1]);
  read_block(dataset, offset, rows, out.data(), H5T_NATIVE_DOUBLE);
  return out;
}

std::vector<int64_t> Hdf5File::read_int64(const std::string& dataset, int64_t offset, int64_t rows) const {
  const auto s = shape(dataset);
  std::vector<int64_t> out(static_cast<size_t>(rows > 0 ? rows : 0) * s[1]);
  read_block(dataset, offset, rows, out.data(), H5T_NATIVE_INT64);
  return out;
}

void Hdf5File::read_rows(const std::string& dataset, int64_t offset, int64_t rows, int width, double* data) const {
  read_block(dataset, offset, rows, data, H5T_NATIVE_DOUBLE, true, width);
}

void Hdf5File::read_rows(const std::string& dataset, int64_t offset, int64_t rows, int width, int64_t* data) const {
  read_block(dataset, offset, rows, data, H5T_NATIVE_INT64, true, width);
}

void Hdf5File::read_block(const std::string& dataset, int64_t offset, int64_t rows, void* data, hid_t mem_type,
                          bool collective, int width) const {
  if (comm_ == MPI_COMM_NULL) fail(dataset, "parallel read on a file opened without MPI");
  Handle dset(H5Dopen2(file_, dataset.c_str(), H5P_DEFAULT), H5Dclose);
  if (!dset.ok()) fail(dataset, "no such dataset");
  Handle file_space(H5Dget_space(dset.get()), H5Sclose);
  if (!file_space.ok()) fail(dataset, "cannot get dataspace");
  const int ndims = H5Sget_simple_extent_ndims(file_space.get());
  hsize_t dims[2] = {0, 1};
  if (ndims < 1 || ndims > 2 || H5Sget_simple_extent_dims(file_space.get(), dims, nullptr) < 0)
    fail(dataset, "expected a 1-D or 2-D dataset");
  // read_double/read_int64: each rank reads its block alone (an independent transfer, no collective), so that a
  // rank whose read or check fails leaves no other rank waiting in the read: the caller agrees on the outcome
  // (io/checkpoint.cpp). read_rows: one collective read, after the caller has agreed on the shape.
  if (offset < 0 || rows < 0 || static_cast<hsize_t>(offset + rows) > dims[0])
    throw std::runtime_error(path_ + ": " + dataset + ": rows [" + std::to_string(offset) + ", " +
                             std::to_string(offset + rows) + ") lie outside the dataset's " +
                             std::to_string(dims[0]) + " rows");
  if (width > 0 && static_cast<hsize_t>(width) != (ndims == 2 ? dims[1] : 1)) fail(dataset, "has another width");
  const hsize_t start[2] = {static_cast<hsize_t>(offset), 0};
  const hsize_t count[2] = {static_cast<hsize_t>(rows), ndims == 2 ? dims[1] : 1};
  const hsize_t mem_dims[2] = {rows > 0 ? count[0] : 1, count[1]};
  Handle mem_space(H5Screate_simple(ndims, mem_dims, nullptr), H5Sclose);
  if (!mem_space.ok()) fail(dataset, "cannot create dataspace");
  herr_t sel = rows > 0 ? H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr)
                        : H5Sselect_none(file_space.get());
  if (sel < 0 || (rows == 0 && H5Sselect_none(mem_space.get()) < 0)) fail(dataset, "cannot select rows");
  Handle dxpl(H5Pcreate(H5P_DATASET_XFER), H5Pclose);
  if (!dxpl.ok() || H5Pset_dxpl_mpio(dxpl.get(), collective ? H5FD_MPIO_COLLECTIVE : H5FD_MPIO_INDEPENDENT) < 0)
    fail(dataset, "cannot set up transfer");
  double dummy[1];
  if (H5Dread(dset.get(), mem_type, mem_space.get(), file_space.get(), dxpl.get(), rows > 0 ? data : dummy) < 0)
    fail(dataset, "cannot read rows [" + std::to_string(offset) + ", " + std::to_string(offset + rows) + ")");
}

namespace {

hid_t open_object(hid_t file, const std::string& object) { return H5Oopen(file, object.c_str(), H5P_DEFAULT); }

}  // namespace

void Hdf5File::set_attribute(const std::string& object, const std::string& name, const std::string& value) {
  if (!writable_ || file_ < 0) fail(object, "file is not open for writing");
  Handle obj(open_object(file_, object), H5Oclose);
  if (!obj.ok()) fail(object, "no such group or dataset");
  const htri_t there = H5Aexists(obj.get(), name.c_str());
  if (there < 0 || (there > 0 && H5Adelete(obj.get(), name.c_str()) < 0))
    fail(object, "cannot replace attribute " + name);
  // Fixed-length UTF-8 (null-padded, exactly the bytes of the value; at least 1 byte): a variable-length string
  // lives in the file's global heap, and HDF5 1.10 trusts the lengths it finds there (a crafted file with a valid
  // seal crashed H5Aread inside H5HG_read). h5py reads these as bytes: .decode() gives the str.
  Handle type(H5Tcopy(H5T_C_S1), H5Tclose);
  const size_t size = std::max<size_t>(1, value.size());
  if (!type.ok() || H5Tset_size(type.get(), size) < 0 || H5Tset_cset(type.get(), H5T_CSET_UTF8) < 0 ||
      H5Tset_strpad(type.get(), H5T_STR_NULLPAD) < 0)
    fail(object, "cannot make string type for attribute " + name);
  Handle space(H5Screate(H5S_SCALAR), H5Sclose);
  if (!space.ok()) fail(object, "cannot create dataspace for attribute " + name);
  Handle attr(H5Acreate2(obj.get(), name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  if (!attr.ok()) fail(object, "cannot create attribute " + name);
  std::string padded = value;
  padded.resize(size, '\0');
  if (H5Awrite(attr.get(), type.get(), padded.data()) < 0) fail(object, "cannot write attribute " + name);
}

void Hdf5File::set_attribute(const std::string& object, const std::string& name, double value) {
  write_numeric_attribute(object, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &value);
}

void Hdf5File::set_int64_attribute(const std::string& object, const std::string& name, int64_t value) {
  write_numeric_attribute(object, name, H5T_STD_I64LE, H5T_NATIVE_INT64, &value);
}

void Hdf5File::write_numeric_attribute(const std::string& object, const std::string& name, hid_t file_type,
                                       hid_t mem_type, const void* value) {
  if (!writable_ || file_ < 0) fail(object, "file is not open for writing");
  Handle obj(open_object(file_, object), H5Oclose);
  if (!obj.ok()) fail(object, "no such group or dataset");
  const htri_t there = H5Aexists(obj.get(), name.c_str());
  if (there < 0 || (there > 0 && H5Adelete(obj.get(), name.c_str()) < 0))
    fail(object, "cannot replace attribute " + name);
  Handle space(H5Screate(H5S_SCALAR), H5Sclose);
  if (!space.ok()) fail(object, "cannot create dataspace for attribute " + name);
  Handle attr(H5Acreate2(obj.get(), name.c_str(), file_type, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  if (!attr.ok()) fail(object, "cannot create attribute " + name);
  if (H5Awrite(attr.get(), mem_type, value) < 0) fail(object, "cannot write attribute " + name);
}

bool Hdf5File::has_attribute(const std::string& object, const std::string& name) const {
  if (file_ < 0) fail(object, "file is closed");
  Handle obj(open_object(file_, object), H5Oclose);
  if (!obj.ok()) fail(object, "no such group or dataset");
  const htri_t there = H5Aexists(obj.get(), name.c_str());
  if (there < 0) fail(object, "cannot look up attribute " + name);
  return there > 0;
}

// Opens attribute `name` of `object` and checks, before anything is read, that it is a scalar of class
// `expected` whose size is at most `max_size` bytes and that its stored data is exactly that size (a crafted file
// can declare anything: HDF5 would allocate and copy what the file says).
hid_t Hdf5File::open_checked_attribute(const std::string& object, const std::string& name, int expected,
                                      size_t max_size, size_t* size) const {
  if (file_ < 0) fail(object, "file is closed");
  Handle attr(H5Aopen_by_name(file_, object.c_str(), name.c_str(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  if (!attr.ok()) fail(object, "no attribute " + name);
  Handle space(H5Aget_space(attr.get()), H5Sclose);
  if (!space.ok() || H5Sget_simple_extent_type(space.get()) != H5S_SCALAR)
    fail(object, "attribute " + name + " is not a scalar");
  Handle type(H5Aget_type(attr.get()), H5Tclose);
  if (!type.ok()) fail(object, "cannot get the type of attribute " + name);
  const H5T_class_t cls = H5Tget_class(type.get());
  if (expected == H5T_STRING) {
    if (cls != H5T_STRING) fail(object, "attribute " + name + " is not a string");
    const htri_t variable = H5Tis_variable_str(type.get());
    if (variable < 0) fail(object, "cannot inspect attribute " + name);
    if (variable)
      fail(object, "attribute " + name +
                       " is a variable-length string (tissue writes fixed-length ones; not read: its length lives "
                       "in the global heap, which HDF5 does not check)");
  } else if (cls != H5T_INTEGER && cls != H5T_FLOAT) {
    fail(object, "attribute " + name + " is not a number");
  }
  *size = H5Tget_size(type.get());
  if (*size == 0 || *size > max_size)
    fail(object, "attribute " + name + " has an implausible size of " + std::to_string(*size) + " bytes");
  if (H5Aget_storage_size(attr.get()) != static_cast<hsize_t>(*size))
    fail(object, "attribute " + name + " stores " + std::to_string(H5Aget_storage_size(attr.get())) +
                     " bytes for a " + std::to_string(*size) + "-byte value");
  return attr.release();
}

void Hdf5File::read_attribute(const std::string& object, const std::string& name, hid_t mem_type, void* value) const {
  size_t size = 0;
  Handle attr(open_checked_attribute(object, name, H5T_INTEGER, 16, &size), H5Aclose);
  if (H5Aread(attr.get(), mem_type, value) < 0) fail(object, "cannot read attribute " + name);
}

double Hdf5File::double_attribute(const std::string& object, const std::string& name) const {
  double v = 0.0;
  read_attribute(object, name, H5T_NATIVE_DOUBLE, &v);
  return v;
}

int64_t Hdf5File::int64_attribute(const std::string& object, const std::string& name) const {
  int64_t v = 0;
  read_attribute(object, name, H5T_NATIVE_INT64, &v);
  return v;
}

std::string Hdf5File::string_attribute(const std::string& object, const std::string& name) const {
  // At most the file's own size (and 64 MiB): the value is stored in the file.
  hsize_t file_size = 0;
  if (file_ < 0 || H5Fget_filesize(file_, &file_size) < 0) fail(object, "cannot get the file size");
  size_t size = 0;
  Handle attr(open_checked_attribute(object, name, H5T_STRING, static_cast<size_t>(std::min<hsize_t>(file_size, 64u << 20)), &size),
              H5Aclose);
  Handle type(H5Aget_type(attr.get()), H5Tclose);
  Handle mem(H5Tcopy(H5T_C_S1), H5Tclose);
  if (!type.ok() || !mem.ok() || H5Tset_cset(mem.get(), H5Tget_cset(type.get())) < 0 ||
      H5Tset_size(mem.get(), size) < 0 || H5Tset_strpad(mem.get(), H5T_STR_NULLPAD) < 0)
    fail(object, "cannot read attribute " + name);
  std::string out(size, '\0');
  if (H5Aread(attr.get(), mem.get(), out.data()) < 0) fail(object, "cannot read attribute " + name);
  out.resize(std::strlen(out.c_str()));  // drop the padding (null-padded, or null-terminated by other writers)
  return out;
}

}  // namespace tissue
