// The body: molecules (spherical mass regions) and the connections between them, in the original (global)
// numbering that every file on disk uses. A box molecule (i,j,k) has id i + n_x (j + n_y k) and sits at
// offset + (i h_x, j h_y, k h_z).
#pragma once
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "src/model/scene.hpp"

namespace tissue {

struct TetMesh;
using MeshReader = std::function<TetMesh(const BodySpec&)>;  // src/model/unstructured.hpp

// Connection classes, by the part of a cell a connection spans (manual stiffness is given per class).
enum class ConnectionClass : std::int8_t { edge = 0, face = 1, body = 2 };
const char* class_name(ConnectionClass c);

struct Connection {
  std::int64_t a, b;  // molecule ids, a < b
  ConnectionClass cls;
};

using Tetrahedron = std::array<std::int64_t, 4>;

// The geometry of one box body: molecule (i,j,k) has the global id first + i + n_x (j + n_y k).
struct BoxGeometry {
  std::array<long, 3> n{};  // molecules along x, y, z
  Vec3 h{};                 // spacing, m
  Vec3 offset{};            // position of molecule (0,0,0)
  std::string topology;
  std::int64_t first = 0;   // global id of molecule (0,0,0): bodies are numbered one after another
  double radius = 0.0;      // m, each molecule's contact sphere
  // Explicit topologies (shape = "mesh", topology = "random"; src/model/unstructured.hpp): `count` molecules with
  // their rest positions in Body::points and their faces in Body::faces; n, h are then only a nominal size.
  std::int64_t count = 0;
  double total_volume = 0.0;  // m^3: explicit topologies the sum of the tetrahedra, a box its hull (body_geometry)
  bool unstructured() const { return count > 0; }

  std::int64_t molecules() const { return count > 0 ? count : static_cast<std::int64_t>(n[0]) * n[1] * n[2]; }
  std::int64_t id(long i, long j, long k) const {
    return first + i + n[0] * (j + static_cast<std::int64_t>(n[1]) * k);
  }
  std::array<long, 3> index(std::int64_t id) const {
    id -= first;
    return {static_cast<long>(id % n[0]), static_cast<long>((id / n[0]) % n[1]),
            static_cast<long>(id / (static_cast<std::int64_t>(n[0]) * n[1]))};
  }
  Vec3 rest_position(std::int64_t id) const {
    auto ijk = index(id);
    return {offset[0] + ijk[0] * h[0], offset[1] + ijk[1] * h[1], offset[2] + ijk[2] * h[2]};
  }
  // The rest distance between two molecules of this box, from their lattice offset ((i' - i) h_x, ...): the same
  // double for every connection of the same offset, wherever it lies (positions would add round-off that
  // differs from place to place), so equal connections get bit-equal k and share a connection type.
  double rest_distance(std::int64_t a, std::int64_t b) const {
    const auto ia = index(a), ib = index(b);
    double sum = 0;
    for (int d = 0; d < 3; ++d) {
      const double x = static_cast<double>(ib[d] - ia[d]) * h[d];
      sum += x * x;
    }
    return std::sqrt(sum);
  }
  // The tributary width of a molecule along an axis: h inside, h/2 on the boundary.
  double width(long i, int axis) const { return (i == 0 || i == n[axis] - 1) ? 0.5 * h[axis] : h[axis]; }
  double volume(std::int64_t id) const {
    auto ijk = index(id);
    return width(ijk[0], 0) * width(ijk[1], 1) * width(ijk[2], 2);
  }
  bool on_face(std::int64_t id, int axis, int side) const {
    long i = index(id)[axis];
    return side == 0 ? i == 0 : i == n[axis] - 1;
  }
  // The area of the face (axis, side) that this molecule stands for.
  double face_area(std::int64_t id, int axis) const {
    auto ijk = index(id);
    int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
    return width(ijk[a1], a1) * width(ijk[a2], a2);
  }
  double length(int axis) const { return (n[axis] - 1) * h[axis]; }  // the body's extent along an axis
};

// A named face: the molecules a [[fix]] or [[load]] names and the area each stands for. Holds, loads, Eq. 3 and
// the measurements read faces only through this. A box's six faces x- .. z+ are lattice planes, made with the
// box (lattice_faces): their molecules are implicit, nothing per molecule. An explicit topology's faces (a mesh's
// physical surfaces, x- .. z+ of a random box) list their molecules, each with a third of every surface triangle
// it is a corner of.
struct NamedFace {
  int body = 0;
  std::string name;
  std::vector<std::int64_t> molecules;  // explicit faces: global ids, sorted
  std::vector<double> area;             // explicit faces: m^2, per molecule
  double total_area = 0.0;
  Vec3 centroid{};                      // area-weighted centroid of the triangles
  int axis = -1;  // the axis the face is normal to, when it is a plane normal to an axis (rollers need one)
  // A plane named x- .. z+ (a box's face, a random box's): 0 at the low end of `axis`, 1 at the high end; -1
  // otherwise. Eq. 3 pairs such a face with the one opposite only.
  int side = -1;
  // The plane's coordinate along `axis`, in the body's own frame (a box's: 0 or (n - 1) h exactly, so that the
  // distance of two faces is the box's length to the bit).
  double plane = 0.0;
  // Roller holds beyond the normal component: both in-plane components of `anchor`, and component
  // `anchor2_component` of `anchor2` (stops the rotation about the normal); -1 when not a plane.
  std::int64_t anchor = -1, anchor2 = -1;
  int anchor2_component = -1;
  bool lattice = false;  // a box's face: its molecules are the lattice plane of `box` (whole layers of molecules)
  BoxGeometry box;       // lattice faces only

  std::ptrdiff_t find(std::int64_t id) const;  // explicit faces: index in molecules, or -1
  // Whether molecule `id` of this face's body lies on the face, and the area it stands for there.
  bool contains(std::int64_t id) const {
    return lattice ? box.on_face(id, axis, side) : find(id) >= 0;
  }
  double area_of(std::int64_t id) const { return lattice ? box.face_area(id, axis) : area[find(id)]; }
  double count() const {  // molecules on the face
    return lattice ? static_cast<double>(box.n[(axis + 1) % 3]) * box.n[(axis + 2) % 3]
                   : static_cast<double>(molecules.size());
  }
};

// The six faces x- .. z+ of box body `b` (lattice planes, O(1) each).
std::vector<NamedFace> lattice_faces(const BoxGeometry& box, int b);

// All the bodies of a scene in one global numbering (body 0's molecules, then body 1's, ...). The inherited
// geometry is body 0's, so single-body code reads it as before; the per-molecule queries below look up the body
// that holds the molecule. A Body built by hand with no parts is one body.
struct Body : BoxGeometry {
  std::vector<BoxGeometry> parts;       // one per body, by first id
  std::vector<Connection> connections;  // sorted by (a, b): the global connection order; never between bodies
  std::vector<Tetrahedron> tetrahedra;  // filled by the tetrahedral topology only (Van Gelder's Eq. 5)
  std::vector<double> youngs_modulus;   // per molecule, Pa
  std::vector<double> mass;             // per molecule, kg
  // Explicit topologies: rest positions of every molecule (global ids; box bodies' entries filled too), empty
  // when all bodies are boxes. Not copied into LocalModel::shape (O(N)); `faces` are (O(surface)), ordered by body.
  std::vector<Vec3> points;
  std::vector<NamedFace> faces;

  int bodies() const { return parts.empty() ? 1 : static_cast<int>(parts.size()); }
  std::int64_t molecules() const {
    return parts.size() <= 1 ? BoxGeometry::molecules() : parts.back().first + parts.back().molecules();
  }
  int body_of(std::int64_t id) const {
    int b = 0;
    while (b + 1 < static_cast<int>(parts.size()) && parts[b + 1].first <= id) ++b;
    return b;
  }
  const BoxGeometry& part(std::int64_t id) const { return parts.size() <= 1 ? *this : parts[body_of(id)]; }
  const BoxGeometry& body(int b) const { return parts.empty() ? *this : parts[b]; }
  std::array<long, 3> index(std::int64_t id) const { return part(id).index(id); }
  Vec3 rest_position(std::int64_t id) const {
    return points.empty() ? part(id).rest_position(id) : points[static_cast<std::size_t>(id)];
  }
  // The rest distance of two molecules of one body: a box's from the lattice indices (BoxGeometry's), an explicit
  // topology's from the positions.
  double rest_distance(std::int64_t a, std::int64_t b) const {
    if (!part(a).unstructured()) return part(a).rest_distance(a, b);
    return point_distance(rest_position(a), rest_position(b));
  }
  static double point_distance(const Vec3& x, const Vec3& y) {
    return std::sqrt((y[0] - x[0]) * (y[0] - x[0]) + (y[1] - x[1]) * (y[1] - x[1]) + (y[2] - x[2]) * (y[2] - x[2]));
  }
  // The face `name` of body b (a box's x- .. z+, an explicit topology's named faces), or nullptr.
  const NamedFace* named_face(int b, const std::string& name) const {
    for (const auto& f : faces)
      if (f.body == b && f.name == name) return &f;
    return nullptr;
  }
  double volume(std::int64_t id) const { return part(id).volume(id); }
  bool on_face(std::int64_t id, int axis, int side) const { return part(id).on_face(id, axis, side); }
  double face_area(std::int64_t id, int axis) const { return part(id).face_area(id, axis); }
};

// The geometry of one box body of the scene (its spec's n, h, offset, topology, radius), numbered from `first`.
BoxGeometry body_geometry(const BodySpec& spec, std::int64_t first);

// The bodies' geometry only (parts, no per-molecule or per-connection array): what every rank keeps.
Body scene_shape(const Scene& scene);

// A molecule's material: its body's, or that of the last region holding it. `id` is the global id.
struct MoleculeMaterial {
  double youngs_modulus, density;  // Pa, kg/m^3
  double poisson_ratio;            // NaN: absent (1/4 on lattices, nothing built for it)
  const FibreSpec* fibres = nullptr;  // the molecule's fibre family (its region's, else its body's), or none
};
MoleculeMaterial molecule_material(const BodySpec& spec, const BoxGeometry& box, std::int64_t id);

}  // namespace tissue
