// A thin RAII layer over parallel HDF5 for the files tissue writes (snapshots, checkpoints).
//
// Every call here is collective over the file's communicator unless it says otherwise: all ranks call it, in the
// same order, with the same names and global shapes. Data are 2-D datasets [global_rows x width] of double or
// int64, each rank writing one contiguous block of rows (possibly none) with independent MPI-IO writes of at most
// 1 MiB (the dataset's creation and each piece's step are collective and agreed), or reading one with an
// independent transfer (not collective: the caller agrees on the outcome).
// Every HDF5 failure throws std::runtime_error naming the file and the dataset, in one line (HDF5's own error
// stack printing is switched off; its innermost message is kept in the exception).
//
// Written files appear atomically: create() writes "<path>.tmp", and close() renames it to <path> once every
// rank has closed it. While a file is written, each rank hashes the seal's blocks it wrote whole and has their
// pages written to the disk and dropped from the page cache (io/file_seal.hpp): close() re-reads only the rest. A created file that is destroyed without close() (an exception unwound past it) is
// removed, so a failed write leaves no partial output.
#pragma once
#include <hdf5.h>
#include <mpi.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

namespace tissue {

class SealStream;

// Whether a written file was abandoned after a failed write (a full disk, a quota, an I/O error): HDF5 still holds
// it open, and finalizing HDF5 (MPI_Finalize) would try to close it in collectives that cannot complete. The
// program then ends without finalizing (src/main.cpp). Not collective.
bool hdf5_files_abandoned();

class Hdf5File {
public:
  // Collective. Create (truncating) <path>.tmp for writing; close() moves it to <path>. `reserve` > 0: the disk
  // space for a file of about that many bytes is reserved first (fallocate, beyond the end of the file; the rest
  // is given back at close), so that a full disk or an exhausted quota fails here, agreed on every rank, with
  // its system error, and not in the middle of HDF5's collective writes (which cannot fail cleanly on one rank).
  static Hdf5File create(const std::string& path, MPI_Comm comm, int64_t reserve = 0);
  // Collective. Open an existing file read-only: check its seal, then let `walk` read, on a serially opened copy
  // (open_serial) in a child process of rank 0, the metadata that the caller will read (io/isolated_parse.hpp), and
  // only then parse the file here. A file that crashes HDF5 in the child is refused with one InputError line
  // ("... corrupt or crafted WHAT"); a problem the walk throws is thrown here, on every rank. A null walk opens the
  // file only (superblock and root group).
  using Walk = std::function<void(const Hdf5File&)>;
  static Hdf5File open(const std::string& path, MPI_Comm comm, const std::string& what, const Walk& walk);
  // Collective. Open read-only after checking the seal, without the isolated parse: only for a file whose metadata
  // the same walk has passed in a child process, unchanged since (the caller checks that it is the same file).
  static Hdf5File open_walked(const std::string& path, MPI_Comm comm);
  // Not collective, no MPI at all: open read-only with HDF5's default serial (sec2) driver, without the seal check.
  // For the metadata walk of open() in its child process; parallel reads (read_double, read_int64) are refused.
  static Hdf5File open_serial(const std::string& path);

  Hdf5File(Hdf5File&& other) noexcept;
  Hdf5File& operator=(Hdf5File&& other) noexcept;
  Hdf5File(const Hdf5File&) = delete;
  Hdf5File& operator=(const Hdf5File&) = delete;
  ~Hdf5File();

  // Collective. Close the file; for a created file, publish it under its final name (barrier, rank 0
  // renames, barrier). Throws if HDF5 could not flush the file or the rename failed.
  void close();

  const std::string& path() const { return path_; }
  MPI_Comm comm() const { return comm_; }
  bool writable() const { return writable_; }

  // Groups. Paths are absolute ("/molecules"); missing parents are created too. Existing groups are kept.
  void create_group(const std::string& group);
  // Whether a group or dataset exists at this absolute path (not collective: metadata only).
  bool exists(const std::string& object) const;

  // Collective write of a new dataset [global_rows x width]: this rank's rows [offset, offset + rows), row-major,
  // rows * width values (data may be null when rows == 0). Parent groups are created as needed.
  void write(const std::string& dataset, int64_t global_rows, int width, int64_t offset, int64_t rows,
             const double* data);
  void write(const std::string& dataset, int64_t global_rows, int width, int64_t offset, int64_t rows,
             const int64_t* data);

  // Collective write of a new dataset [global_rows x width] in `pieces` agreed steps (the same count on every rank;
  // each rank writes its rows of a piece independently, in writes of at most 1 MiB), so that no rank ever holds
  // more than a piece: piece(p, &offset, &rows) returns this rank's rows
  // [offset, offset + rows) of piece p (rows * width values, valid until the next call; null when rows == 0).
  // `integer`: int64 values, otherwise double. `independent`: piece() makes no MPI call (each rank's rows its own:
  // io/row_stream.hpp), so each rank writes all its pieces on its own and the ranks agree once, after the last.
  // Without `independent`, piece() may exchange rows point to point with the other ranks' piece() calls (no
  // collective): every rank calls it for every piece, even after a failure on its rank (which then writes nothing
  // more), and the ranks agree once, after the last piece.
  // `placed`, if given, is called on every rank once the dataset exists, before the first piece, with the file
  // offset of its first row (the same on every rank; -1 if HDF5 does not say): a caller may then choose its pieces'
  // rows so that they cover whole seal blocks (io/row_stream.cpp). It may make collective calls.
  using Piece = std::function<const void*(int64_t piece, int64_t* offset, int64_t* rows)>;
  using Placed = std::function<void(int64_t base)>;
  void write_pieces(const std::string& dataset, int64_t global_rows, int width, bool integer, int64_t pieces,
                    const Piece& piece, bool independent = false, const Placed& placed = nullptr);

  // Collective, as write_pieces with `independent`, for several new datasets of the same rows (each its own
  // width and type), created in the given order and written a piece of each at a time: piece p of every dataset,
  // then piece p + 1, so that one pass over a piece's items fills the rows of all (a lattice's connections: their
  // ends decoded once for the endpoints, strains and forces). piece(p, data, &offset, &rows) sets data[i] to this
  // rank's rows [offset, offset + rows) of dataset i (valid until the next call) and makes no MPI call.
  struct Column {
    std::string dataset;
    int width;
    bool integer;
  };
  using Pieces = std::function<void(int64_t piece, const void** data, int64_t* offset, int64_t* rows)>;
  void write_pieces_together(const std::vector<Column>& columns, int64_t global_rows, int64_t pieces,
                             const Pieces& piece);

  // The shape {rows, width} of a 2-D dataset (a 1-D dataset reads as width 1).
  std::vector<int64_t> shape(const std::string& dataset) const;
  // Throws unless the dataset is stored as tissue writes it: contiguous, unfiltered, of 8-byte floats (or 8-byte
  // integers), so that reading its rows decodes no further metadata (no chunk index, no filter, no heap).
  void check_plain(const std::string& dataset, bool integer) const;
  // Rows [offset, offset + rows) of a dataset: rows * width values. Not collective (an independent MPI-IO read,
  // so that one rank's failure leaves no rank waiting): a caller whose ranks go on to a collective agrees first.
  std::vector<double> read_double(const std::string& dataset, int64_t offset, int64_t rows) const;
  std::vector<int64_t> read_int64(const std::string& dataset, int64_t offset, int64_t rows) const;
  // Collective: rows [offset, offset + rows) of a dataset `width` values wide into data (rows * width values), in
  // one collective MPI-IO read (io/row_stream.hpp reads a restart's pieces so). Every rank calls it, with rows
  // 0 if it has none; the dataset's shape must be agreed first (a rank that throws here leaves the others waiting).
  void read_rows(const std::string& dataset, int64_t offset, int64_t rows, int width, double* data) const;
  void read_rows(const std::string& dataset, int64_t offset, int64_t rows, int width, int64_t* data) const;

  // Attributes on a group or dataset ("/" is the file root). Writing replaces an existing attribute.
  void set_attribute(const std::string& object, const std::string& name, const std::string& value);
  void set_attribute(const std::string& object, const std::string& name, const char* value) {
    set_attribute(object, name, std::string(value));
  }
  void set_attribute(const std::string& object, const std::string& name, double value);
  template <typename I, std::enable_if_t<std::is_integral_v<I>, int> = 0>
  void set_attribute(const std::string& object, const std::string& name, I value) {
    set_int64_attribute(object, name, static_cast<int64_t>(value));
  }
  bool has_attribute(const std::string& object, const std::string& name) const;
  std::string string_attribute(const std::string& object, const std::string& name) const;
  double double_attribute(const std::string& object, const std::string& name) const;
  int64_t int64_attribute(const std::string& object, const std::string& name) const;

private:
  Hdf5File(std::string path, MPI_Comm comm, bool writable);
  static Hdf5File open_parsed(const std::string& path, MPI_Comm comm, bool check_seal);
  void set_int64_attribute(const std::string& object, const std::string& name, int64_t value);
  void write_block(const std::string& dataset, int64_t global_rows, int width, int64_t offset, int64_t rows,
                   const void* data, hid_t file_type, hid_t mem_type);
  void write_pieces(const std::string& dataset, int64_t global_rows, int width, hid_t file_type, hid_t mem_type,
                    int64_t pieces, const Piece& piece, bool independent = false,
                    const Placed& placed = nullptr);
  struct TypedColumn {
    std::string dataset;
    int width;
    hid_t file_type, mem_type;
  };
  // write_pieces and write_pieces_together: `placed` sees the first column's offset.
  void write_columns(const std::vector<TypedColumn>& columns, int64_t global_rows, int64_t pieces,
                     const Pieces& piece, bool independent, const Placed& placed);
  void write_numeric_attribute(const std::string& object, const std::string& name, hid_t file_type,
                               hid_t mem_type, const void* value);
  void read_block(const std::string& dataset, int64_t offset, int64_t rows, void* data, hid_t mem_type,
                  bool collective = false, int width = 0) const;
  void read_attribute(const std::string& object, const std::string& name, hid_t mem_type, void* value) const;
  // The open attribute (caller closes), after checking its class (H5T_STRING: fixed-length only; otherwise a
  // number), that it is a scalar, its size (1 .. max_size bytes) and that the file stores exactly that many bytes.
  hid_t open_checked_attribute(const std::string& object, const std::string& name, int expected, size_t max_size,
                               size_t* size) const;
  [[noreturn]] void fail(const std::string& object, const std::string& what) const;
  // As fail(), for a failed write: an OutputError naming the file and the system error `err` (errno) if it says why.
  [[noreturn]] void fail_io(const std::string& object, const std::string& what, int err) const;
  void release() noexcept;  // close without publishing; removes an unpublished tmp file
  // After an agreed write failure: forget the file without closing it (HDF5's close is a collective that the
  // ranks can no longer complete together); rank 0 removes the tmp file.
  void abandon() noexcept;

  std::string path_;
  MPI_Comm comm_ = MPI_COMM_NULL;
  bool writable_ = false;
  hid_t file_ = -1;
  std::unique_ptr<SealStream> seal_;  // a created file: this rank's side of the seal (io/file_seal.hpp)
};

}  // namespace tissue
