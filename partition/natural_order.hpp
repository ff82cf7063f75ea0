// The natural (original, global-id) order of items that are owned by ranks in an arbitrary pattern.
//
// After partitioning, rank r owns some scattered subset of the ids 0..N-1. Everything written to disk is in id
// order, and parallel HDF5 wants each rank to write one contiguous block of rows. NaturalOrder moves each owned
// item's values to the rank whose block of the balanced split (the PETSC_DECIDE layout: the first N % P ranks
// hold one more) contains its id, and back again. The exchange plan is computed once, collectively, in the
// constructor; every transfer is then one MPI_Alltoallv. No rank ever holds more than its own block.
#pragma once
#include <mpi.h>

#include <cstdint>
#include <vector>

#include "partition/exchange.hpp"

namespace tissue {

class NaturalOrder {
public:
  // Collective. owned_ids: the global ids this rank owns, in the order its local arrays hold them. Across all
  // ranks the ids must be a permutation of 0..global_count-1 (each written by exactly one rank); otherwise
  // every rank throws std::invalid_argument. comm must outlive this object.
  NaturalOrder(MPI_Comm comm, const std::vector<int64_t>& owned_ids, int64_t global_count);

  // This rank's block of the natural layout: ids [begin(), end()).
  int64_t begin() const { return begin_; }
  int64_t end() const { return begin_ + count_; }
  int64_t count() const { return count_; }
  int64_t global_count() const { return global_count_; }
  // How many ids this rank owns (the length, in items, of the arrays given to to_natural).
  int64_t owned_count() const { return static_cast<int64_t>(send_order_.size()); }
  MPI_Comm comm() const { return comm_; }

  // Collective. values: owned_count() items of `width` values each, in the order of owned_ids. Returns this
  // rank's natural block, count() * width values, row i holding id begin() + i.
  template <typename T>
  std::vector<T> to_natural(const T* values, int width) const;
  std::vector<double> to_natural(const double* values, int width) const { return to_natural<double>(values, width); }
  std::vector<int64_t> to_natural_ids(const int64_t* values, int width) const {
    return to_natural<int64_t>(values, width);
  }

  // Collective; the reverse: natural: count() * width values (this rank's block, e.g. read from a checkpoint).
  // Returns owned_count() * width values in the order of owned_ids.
  template <typename T>
  std::vector<T> from_natural(const T* natural, int width) const;
  std::vector<double> from_natural(const double* natural, int width) const {
    return from_natural<double>(natural, width);
  }
  std::vector<int64_t> from_natural_ids(const int64_t* natural, int width) const {
    return from_natural<int64_t>(natural, width);
  }

  // The balanced split, without building a plan: [block_begin(r), block_begin(r + 1)) belongs to rank r.
  static int64_t block_begin(int64_t global_count, int ranks, int rank);
  static int block_owner(int64_t global_count, int ranks, int64_t id);

private:
  MPI_Comm comm_;
  int64_t global_count_ = 0, begin_ = 0, count_ = 0;
  // Items are sent grouped by destination rank: send slot k carries owned item send_order_[k].
  std::vector<int64_t> send_order_;
  // Receive slot k (grouped by source rank) is natural row recv_rows_[k] of this rank's block.
  std::vector<int64_t> recv_rows_;
  ExchangePlan plan_;  // items per rank, both ways
};

// Instantiated in natural_order.cpp for the two types the files hold.
extern template std::vector<double> NaturalOrder::to_natural<double>(const double*, int) const;
extern template std::vector<int64_t> NaturalOrder::to_natural<int64_t>(const int64_t*, int) const;
extern template std::vector<double> NaturalOrder::from_natural<double>(const double*, int) const;
extern template std::vector<int64_t> NaturalOrder::from_natural<int64_t>(const int64_t*, int) const;

}  // namespace tissue
