#include "src/model/scene.hpp"

namespace tissue {

bool parse_face(const std::string& face, int& axis, int& side) {
  if (face.size() != 2 || face[0] < 'x' || face[0] > 'z' || (face[1] != '-' && face[1] != '+')) return false;
  axis = face[0] - 'x';
  side = face[1] == '+' ? 1 : 0;
  return true;
}

}  // namespace tissue

namespace tissue {

double history_factor(const TimeHistory& h, double t) {
  if (h.empty()) return 1.0;
  if (t <= h.front()[0]) return h.front()[1];
  if (t >= h.back()[0]) return h.back()[1];
  std::size_t i = 1;
  while (h[i][0] < t) ++i;  // h[i - 1][0] < t <= h[i][0]
  if (t == h[i][0]) return h[i][1];  // a breakpoint: its own value, exactly
  const double w = (t - h[i - 1][0]) / (h[i][0] - h[i - 1][0]);
  return h[i - 1][1] + w * (h[i][1] - h[i - 1][1]);
}

}  // namespace tissue
