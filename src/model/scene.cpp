#include "src/model/scene.hpp"

namespace tissue {

bool parse_face(const std::string& face, int& axis, int& side) {
  if (face.size() != 2 || face[0] < 'x' || face[0] > 'z' || (face[1] != '-' && face[1] != '+')) return false;
  axis = face[0] - 'x';
  side = face[1] == '+' ? 1 : 0;
  return true;
}

}  // namespace tissue
