// Explicit (unstructured) topologies: a tetrahedral mesh, handed in by a MeshReader (io/gmsh_mesh) or made by Delaunay
// from a random cloud (src/model/random_cloud), turned into a Body. Nodes become molecules, tetrahedron edges
// connections, named surfaces the faces that fixes and loads name, named volumes the regions materials name.
#pragma once
#include <array>
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

// Every [[fix]] and [[load]] face on an explicit body must be one of its named faces: InputError naming the key.
void check_face_names(const Scene& scene, const Body& body);

}  // namespace tissue
