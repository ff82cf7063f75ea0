// The personalized all-to-all every distributed stage uses (the lattice directory, the natural order of files,
// the contact halo, the multigrid's coarse numbering and coarse rows): items grouped by destination rank go out,
// items grouped by source rank come in. An ExchangePlan is made once from the send counts (one MPI_Alltoall of
// the counts) and then moves any number of arrays of any width, in either direction (MPI_Alltoallv with one
// derived type per item, so counts stay in items and do not overflow int for wide rows). Collective.
#pragma once
#include <mpi.h>

#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

namespace tissue {

template <typename T>
MPI_Datatype mpi_type() {
  if constexpr (std::is_same_v<T, double>) return MPI_DOUBLE;
  else if constexpr (std::is_same_v<T, float>) return MPI_FLOAT;
  else if constexpr (std::is_same_v<T, std::int64_t>) return MPI_INT64_T;
  else if constexpr (std::is_same_v<T, std::uint64_t>) return MPI_UINT64_T;
  else if constexpr (std::is_same_v<T, int>) return MPI_INT;
  else if constexpr (std::is_same_v<T, std::uint32_t>) return MPI_UINT32_T;
  else if constexpr (std::is_same_v<T, std::uint8_t>) return MPI_UINT8_T;
  else if constexpr (std::is_same_v<T, char>) return MPI_CHAR;
  else static_assert(sizeof(T) == 0, "mpi_type: no MPI type for T");
}

class ExchangePlan {
public:
  ExchangePlan() = default;
  // Collective. send_counts[r]: how many items go to rank r (in the order the arrays hold them, grouped by r).
  ExchangePlan(MPI_Comm comm, std::vector<int> send_counts) : comm_(comm), send_counts_(std::move(send_counts)) {
    const int size = static_cast<int>(send_counts_.size());
    recv_counts_.assign(size, 0);
    check(MPI_Alltoall(send_counts_.data(), 1, MPI_INT, recv_counts_.data(), 1, MPI_INT, comm), "MPI_Alltoall");
    send_displs_ = displacements(send_counts_);
    recv_displs_ = displacements(recv_counts_);
  }
  // Items sent and received in all, and per rank.
  std::size_t sent() const { return total(send_counts_); }
  std::size_t received() const { return total(recv_counts_); }
  const std::vector<int>& send_counts() const { return send_counts_; }
  const std::vector<int>& recv_counts() const { return recv_counts_; }
  const std::vector<int>& send_displs() const { return send_displs_; }
  const std::vector<int>& recv_displs() const { return recv_displs_; }

  // Collective. `width` values an item: in[sent() * width] out, out[received() * width] in (forward), or the
  // reverse of the plan (backward: what came in goes back where it came from).
  template <typename T>
  void forward(const T* in, T* out, int width = 1) const { move(in, out, width, true); }
  template <typename T>
  void backward(const T* in, T* out, int width = 1) const { move(in, out, width, false); }
  template <typename T>
  std::vector<T> forward(const std::vector<T>& in, int width = 1) const {
    std::vector<T> out(received() * static_cast<std::size_t>(width));
    move(in.data(), out.data(), width, true);
    return out;
  }

private:
  static std::vector<int> displacements(const std::vector<int>& counts) {
    std::vector<int> d(counts.size(), 0);
    for (std::size_t r = 1; r < counts.size(); ++r) d[r] = d[r - 1] + counts[r - 1];
    return d;
  }
  static std::size_t total(const std::vector<int>& counts) {
    std::size_t n = 0;
    for (int c : counts) n += static_cast<std::size_t>(c);
    return n;
  }
  static void check(int rc, const char* call) {
    if (rc != MPI_SUCCESS) throw std::runtime_error(std::string("exchange: ") + call + " failed");
  }
  template <typename T>
  void move(const T* in, T* out, int width, bool forward) const {
    if (width <= 0) throw std::invalid_argument("exchange: width must be positive");
    MPI_Datatype item = mpi_type<T>();
    if (width > 1) {
      check(MPI_Type_contiguous(width, mpi_type<T>(), &item), "MPI_Type_contiguous");
      check(MPI_Type_commit(&item), "MPI_Type_commit");
    }
    const int rc = forward ? MPI_Alltoallv(in, send_counts_.data(), send_displs_.data(), item, out,
                                           recv_counts_.data(), recv_displs_.data(), item, comm_)
                           : MPI_Alltoallv(in, recv_counts_.data(), recv_displs_.data(), item, out,
                                           send_counts_.data(), send_displs_.data(), item, comm_);
    if (width > 1) MPI_Type_free(&item);
    check(rc, "MPI_Alltoallv");
  }

  MPI_Comm comm_ = MPI_COMM_NULL;
  std::vector<int> send_counts_, recv_counts_, send_displs_, recv_displs_;
};

namespace detail {
// Lists is const (the caller keeps its lists) or not (each list is freed once it is in the send buffer).
template <typename Lists>
std::vector<typename Lists::value_type::value_type> exchange_lists(MPI_Comm comm, Lists& out,
                                                                    std::vector<int>* received) {
  using T = typename Lists::value_type::value_type;
  std::vector<int> counts(out.size());
  std::size_t n = 0;
  for (std::size_t r = 0; r < out.size(); ++r) {
    if (out[r].size() > static_cast<std::size_t>(std::numeric_limits<int>::max()))
      throw std::runtime_error("a rank sends more than 2^31 values to another: use more ranks");
    counts[r] = static_cast<int>(out[r].size()), n += out[r].size();
  }
  std::vector<T> send;
  send.reserve(n);
  for (auto& o : out) {
    send.insert(send.end(), o.begin(), o.end());
    if constexpr (!std::is_const_v<Lists>) std::vector<T>().swap(o);
  }
  const ExchangePlan plan(comm, std::move(counts));
  if (received) *received = plan.recv_counts();
  return plan.forward(send);
}
}  // namespace detail

// Collective. One exchange of lists grouped by destination rank (out[r] goes to rank r; out.size() = ranks):
// returns what arrives, grouped by source rank; `received` (if given) gets the count per source in values.
template <typename T>
std::vector<T> exchange(MPI_Comm comm, const std::vector<std::vector<T>>& out, std::vector<int>* received = nullptr) {
  return detail::exchange_lists(comm, out, received);
}
// The same, freeing each list as soon as it is in the send buffer (large exchanges: a lower memory peak).
template <typename T>
std::vector<T> exchange(MPI_Comm comm, std::vector<std::vector<T>>&& out, std::vector<int>* received = nullptr) {
  std::vector<T> in = detail::exchange_lists(comm, out, received);
  out.clear();
  return in;
}

}  // namespace tissue
