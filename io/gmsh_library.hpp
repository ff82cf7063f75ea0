// The Gmsh library behind io/gmsh_mesh.cpp, in a shared module of its own (libtissue_gmsh.so, built from
// io/gmsh_library.cpp) that read_gmsh's child process loads with dlopen: libgmsh brings OpenCASCADE, FLTK and
// OpenGL with it (about 70 more libraries, 0.25 s and 44 MB resident per process to load), which tissue itself
// should not carry. This is what crosses between the two: Gmsh's model, as read (and meshed), unjudged.
#pragma once
#include <cstddef>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace tissue::gmsh_module {

// The elements of one type on one entity, in Gmsh's order.
struct Block {
  int dim = 0, entity = 0, type = 0;
  int nodes_per_element = 0;
  std::vector<int> physical;  // the entity's physical groups
  std::vector<std::size_t> tags, nodes;  // element tags; nodes_per_element node tags each
};

struct Model {
  std::vector<std::size_t> node_tags;
  std::vector<double> coords;  // 3 per node
  std::map<std::pair<int, int>, std::string> physical_names;  // (dim, tag) of every group -> name ("": none)
  bool partitioned = false;
  // Every 3D entity's elements, then those of the 2D entities in a physical group; entities in Gmsh's order.
  std::vector<Block> blocks;
};

// Opens `path` (geometry: meshes it in 3D, mesh_size > 0 as Mesh.MeshSizeMax) and fills `out`; or sets `error` to
// "Gmsh cannot read it: MESSAGE" ("cannot mesh it" while meshing). Gmsh is initialized without argv or
// configuration files, silent, and finalized before returning.
using ReadFunction = void (*)(const std::string& path, double mesh_size, bool geometry, Model& out,
                              std::string& error);
// The library's version ("4.8.4").
using VersionFunction = void (*)(std::string& version);

}  // namespace tissue::gmsh_module
