// Explicit (unstructured) topologies: a tetrahedral mesh, handed in by a MeshReader (io/gmsh_mesh) or made by Delaunay
// from a random cloud (src/model/random_cloud), turned into a Body. Nodes become molecules, tetrahedron edges
// connections, named surfaces the faces that fixes and loads name, named volumes the regions materials name.
#pragma once
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "src/model/body.hpp"

namespace tissue {

struct TetMesh {
  std::string file;                                  // where it came from, for messages
  std::vector<Vec3> nodes;                           // positions, m; molecule i is node i
  std::vector<std::array<std::int64_t, 4>> tets;     // node indices, positively oriented
  std::vector<int> tet_region;                       // per tetrahedron: index into region_names, -1 = none
  std::vector<std::string> region_names;
  struct Surface {
    std::string name;
    std::vector<std::array<std::int64_t, 3>> triangles;  // node indices
  };
  std::vector<Surface> surfaces;
};

// Where a mesh body's tetrahedra come from. The model knows no file format: the driver hands in io's reader
// (read_mesh, io/gmsh_mesh.hpp); a test may hand in a mesh of its own.
using MeshReader = std::function<TetMesh(const BodySpec&)>;

// Signed volume of a tetrahedron (positive when p3 lies on the side of (p1 - p0) x (p2 - p0)).
double signed_volume(const Vec3& p0, const Vec3& p1, const Vec3& p2, const Vec3& p3);

// The body of `spec` from a mesh, numbered from `first`: connections are the tetrahedra's edges (class edge), a
// molecule's volume is a quarter of each tetrahedron it belongs to and its mass the sum of density(T) vol(T) / 4;
// its modulus is that of the last of spec.regions (scene order) among the regions of its tetrahedra, the body's
// own where none. Every surface becomes a NamedFace. Throws InputError naming `scene_file` and the key of a
// region whose name the mesh lacks.
Body build_unstructured(const BodySpec& spec, const TetMesh& mesh, std::int64_t first, const std::string& scene_file,
                        const std::string& key);

// What both construction paths take from a mesh apart from its connections: each molecule's rest position (the
// spec's offset added), mass and modulus, the volume of the tetrahedra and the named faces, with the same checks
// and messages as build_unstructured (which is this plus the edges).
struct MeshMolecules {
  std::vector<Vec3> points;
  std::vector<double> mass, youngs_modulus;
  double total_volume = 0.0;
  std::vector<NamedFace> faces;  // body index left 0
};
MeshMolecules mesh_molecules(const BodySpec& spec, const TetMesh& mesh, std::int64_t first,
                             const std::string& scene_file, const std::string& key);

// The volume of a tetrahedron as Van Gelder's Eq. 5 sums it per connection (|det| / 6), and Lloyd's equivalent
// edge (6 sqrt2 V)^(1/3): one formula for every path that sums them.
double tetrahedron_volume(const Vec3& p0, const Vec3& p1, const Vec3& p2, const Vec3& p3);
// The nominal size of an explicit body (b.count set): the mean connection length (length_sum over `connections`,
// each summed in the global connection order from edge_length) stands for the spacing h and the default contact
// radius (half of it), and n for a cube of the same count (what iteration caps scale with).
double edge_length(const Vec3& a, const Vec3& b);
void set_nominal_size(BoxGeometry& b, const BodySpec& spec, double length_sum, std::int64_t connections);
inline double lloyd_edge(double volume) { return std::cbrt(6.0 * std::sqrt(2.0) * volume); }

// Every [[fix]] and [[load]] face on an explicit body must be one of its named faces: InputError naming the key.
void check_face_names(const Scene& scene, const Body& body);

}  // namespace tissue
