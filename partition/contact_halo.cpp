#include "partition/contact_halo.hpp"

#include <algorithm>
#include <array>
#include <limits>

namespace tissue {

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
  std::vector<int> send_count(P, 0);
  for (int q = 0; q < P; ++q) {
    const int first = static_cast<int>(send_.size());
    if (q == m_.rank) continue;
    const double* b = &boxes[6 * q];
    for (int i = 0; i < m_.owned; ++i) {
      const double* p = x + 3 * i;
      if (p[0] >= b[0] && p[0] <= b[3] && p[1] >= b[1] && p[1] <= b[4] && p[2] >= b[2] && p[2] <= b[5])
        send_.push_back(i);
    }
    send_count[q] = static_cast<int>(send_.size()) - first;
  }
  plan_ = ExchangePlan(m_.comm, std::move(send_count));

  std::vector<std::int64_t> send_id(send_.size());
  std::vector<int> send_body(send_.size());
  for (std::size_t s = 0; s < send_.size(); ++s) send_id[s] = m_.id[send_[s]], send_body[s] = m_.body[send_[s]];
  id_ = plan_.forward(send_id);
  body_ = plan_.forward(send_body);
  update(x);
}

void ContactHalo::update(const double* x) {
  buffer_.resize(3 * send_.size());
  for (std::size_t s = 0; s < send_.size(); ++s)
    for (int d = 0; d < 3; ++d) buffer_[3 * s + d] = x[3 * send_[s] + d];
  x_.resize(3 * id_.size());
  if (m_.size == 1) return;
  plan_.forward(buffer_.data(), x_.data(), 3);
}

}  // namespace tissue
