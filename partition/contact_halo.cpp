#include "partition/contact_halo.hpp"

#include <algorithm>
#include <array>
#include <limits>

namespace tissue {

namespace {
std::vector<int> times(const std::vector<int>& v, int k) {
  std::vector<int> out(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) out[i] = k * v[i];
  return out;
}
}  // namespace

void ContactHalo::rebuild(const double* x) {
  const int P = m_.size;
  ++rebuilds_;
  // This rank's owned bounding box, grown by the reach; every rank's, gathered.
  std::array<double, 6> box;
  for (int d = 0; d < 3; ++d)
    box[d] = std::numeric_limits<double>::max(), box[3 + d] = -std::numeric_limits<double>::max();
  for (int i = 0; i < m_.owned; ++i)
    for (int d = 0; d < 3; ++d)
      box[d] = std::min(box[d], x[3 * i + d]), box[3 + d] = std::max(box[3 + d], x[3 * i + d]);
  for (int d = 0; d < 3; ++d) box[d] -= reach_, box[3 + d] += reach_;
  std::vector<double> boxes(6 * P);
  MPI_Allgather(box.data(), 6, MPI_DOUBLE, boxes.data(), 6, MPI_DOUBLE, m_.comm);

  // What goes where: the owned molecules inside another rank's grown box.
  send_.clear();
  send_count_.assign(P, 0), send_offset_.assign(P, 0);
  for (int q = 0; q < P; ++q) {
    send_offset_[q] = static_cast<int>(send_.size());
    if (q == m_.rank) continue;
    const double* b = &boxes[6 * q];
    for (int i = 0; i < m_.owned; ++i) {
      const double* p = x + 3 * i;
      if (p[0] >= b[0] && p[0] <= b[3] && p[1] >= b[1] && p[1] <= b[4] && p[2] >= b[2] && p[2] <= b[5])
        send_.push_back(i);
    }
    send_count_[q] = static_cast<int>(send_.size()) - send_offset_[q];
  }
  recv_count_.assign(P, 0), recv_offset_.assign(P, 0);
  MPI_Alltoall(send_count_.data(), 1, MPI_INT, recv_count_.data(), 1, MPI_INT, m_.comm);
  int total = 0;
  for (int q = 0; q < P; ++q) recv_offset_[q] = total, total += recv_count_[q];

  std::vector<std::int64_t> send_id(send_.size());
  std::vector<int> send_body(send_.size());
  for (std::size_t s = 0; s < send_.size(); ++s) send_id[s] = m_.id[send_[s]], send_body[s] = m_.body[send_[s]];
  id_.resize(total), body_.resize(total);
  MPI_Alltoallv(send_id.data(), send_count_.data(), send_offset_.data(), MPI_INT64_T, id_.data(),
                recv_count_.data(), recv_offset_.data(), MPI_INT64_T, m_.comm);
  MPI_Alltoallv(send_body.data(), send_count_.data(), send_offset_.data(), MPI_INT, body_.data(),
                recv_count_.data(), recv_offset_.data(), MPI_INT, m_.comm);
  update(x);
}

void ContactHalo::update(const double* x) {
  buffer_.resize(3 * send_.size());
  for (std::size_t s = 0; s < send_.size(); ++s)
    for (int d = 0; d < 3; ++d) buffer_[3 * s + d] = x[3 * send_[s] + d];
  x_.resize(3 * id_.size());
  if (m_.size == 1) return;
  const auto sc = times(send_count_, 3), so = times(send_offset_, 3);
  const auto rc = times(recv_count_, 3), ro = times(recv_offset_, 3);
  MPI_Alltoallv(buffer_.data(), sc.data(), so.data(), MPI_DOUBLE, x_.data(), rc.data(), ro.data(), MPI_DOUBLE,
                m_.comm);
}

}  // namespace tissue
