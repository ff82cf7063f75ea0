#include "partition/natural_order.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace tissue {

namespace {

void check_mpi(int rc, const char* what) {
  if (rc != MPI_SUCCESS) {
    char msg[MPI_MAX_ERROR_STRING];
    int len = 0;
    MPI_Error_string(rc, msg, &len);
    throw std::runtime_error(std::string("NaturalOrder: ") + what + " failed: " + std::string(msg, len));
  }
}

}  // namespace

int64_t NaturalOrder::block_begin(int64_t n, int ranks, int rank) {
  const int64_t q = n / ranks, rem = n % ranks;
  return rank * q + std::min<int64_t>(rank, rem);
}

int NaturalOrder::block_owner(int64_t n, int ranks, int64_t id) {
  const int64_t q = n / ranks, rem = n % ranks;
  const int64_t big = rem * (q + 1);  // ids held by the ranks that have one extra
  if (id < big) return static_cast<int>(id / (q + 1));
  return static_cast<int>(rem + (id - big) / q);  // q > 0 here, since id < n
}

NaturalOrder::NaturalOrder(MPI_Comm comm, const std::vector<int64_t>& owned_ids, int64_t global_count)
    : comm_(comm), global_count_(global_count) {
  int size = 1, rank = 0;
  check_mpi(MPI_Comm_size(comm, &size), "MPI_Comm_size");
  check_mpi(MPI_Comm_rank(comm, &rank), "MPI_Comm_rank");
  if (global_count < 0) throw std::invalid_argument("NaturalOrder: negative global count");
  begin_ = block_begin(global_count, size, rank);
  count_ = block_begin(global_count, size, rank + 1) - begin_;

  // Out-of-range ids would index outside every block; agree on it before any exchange so all ranks throw.
  int bad = 0;
  for (int64_t id : owned_ids) bad |= (id < 0 || id >= global_count);
  int any_bad = 0;
  check_mpi(MPI_Allreduce(&bad, &any_bad, 1, MPI_INT, MPI_MAX, comm), "MPI_Allreduce");
  if (any_bad)
    throw std::invalid_argument("NaturalOrder: an owned id lies outside 0.." + std::to_string(global_count - 1));

  const size_t n_owned = owned_ids.size();
  std::vector<int> dest(n_owned);
  std::vector<int> send_counts(size, 0);
  for (size_t i = 0; i < n_owned; ++i) {
    dest[i] = block_owner(global_count, size, owned_ids[i]);
    ++send_counts[dest[i]];
  }
  plan_ = ExchangePlan(comm, std::move(send_counts));
  // Counting sort by destination keeps each destination's items in the caller's order.
  send_order_.resize(n_owned);
  std::vector<int> fill = plan_.send_displs();
  std::vector<int64_t> send_ids(n_owned);
  for (size_t i = 0; i < n_owned; ++i) {
    const int k = fill[dest[i]]++;
    send_order_[k] = static_cast<int64_t>(i);
    send_ids[k] = owned_ids[i];
  }

  const int64_t n_recv = static_cast<int64_t>(plan_.received());
  recv_rows_ = plan_.forward(send_ids);

  // Every row of my block must arrive exactly once; with all ids in range that makes the ids a permutation.
  bad = (n_recv != count_);
  std::vector<char> seen(count_, 0);
  for (int64_t& row : recv_rows_) {
    row -= begin_;
    if (bad || row < 0 || row >= count_ || seen[row]) { bad = 1; break; }
    seen[row] = 1;
  }
  check_mpi(MPI_Allreduce(&bad, &any_bad, 1, MPI_INT, MPI_MAX, comm), "MPI_Allreduce");
  if (any_bad)
    throw std::invalid_argument("NaturalOrder: the owned ids are not a permutation of 0.." +
                                std::to_string(global_count - 1) + " (an id is missing or owned twice)");
}

template <typename T>
std::vector<T> NaturalOrder::to_natural(const T* values, int width) const {
  const size_t w = static_cast<size_t>(width);
  std::vector<T> send(send_order_.size() * w);
  for (size_t k = 0; k < send_order_.size(); ++k)
    std::copy_n(values + send_order_[k] * w, w, send.data() + k * w);
  std::vector<T> recv(recv_rows_.size() * w);
  plan_.forward(send.data(), recv.data(), width);
  std::vector<T> natural(static_cast<size_t>(count_) * w);
  for (size_t k = 0; k < recv_rows_.size(); ++k)
    std::copy_n(recv.data() + k * w, w, natural.data() + recv_rows_[k] * w);
  return natural;
}

template <typename T>
std::vector<T> NaturalOrder::from_natural(const T* natural, int width) const {
  const size_t w = static_cast<size_t>(width);
  std::vector<T> send(recv_rows_.size() * w);
  for (size_t k = 0; k < recv_rows_.size(); ++k)
    std::copy_n(natural + recv_rows_[k] * w, w, send.data() + k * w);
  std::vector<T> recv(send_order_.size() * w);
  plan_.backward(send.data(), recv.data(), width);
  std::vector<T> owned(send_order_.size() * w);
  for (size_t k = 0; k < send_order_.size(); ++k)
    std::copy_n(recv.data() + k * w, w, owned.data() + send_order_[k] * w);
  return owned;
}

template std::vector<double> NaturalOrder::to_natural<double>(const double*, int) const;
template std::vector<int64_t> NaturalOrder::to_natural<int64_t>(const int64_t*, int) const;
template std::vector<double> NaturalOrder::from_natural<double>(const double*, int) const;
template std::vector<int64_t> NaturalOrder::from_natural<int64_t>(const int64_t*, int) const;

}  // namespace tissue
