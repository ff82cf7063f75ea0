// A reader of Gmsh's mesh format 4.1, ASCII (https://gmsh.info/doc/texinfo/gmsh.html#MSH-file-format), written
// against the specification: physical names, entities, nodes and elements. What it keeps: 4-node tetrahedra
// (every 3D element must be one), the triangles of physical surfaces, and the physical volume of each
// tetrahedron. Nodes that no tetrahedron uses are dropped; molecules are the rest, in node-tag order.
#pragma once
#include <string>

#include "src/model/unstructured.hpp"

namespace tissue {

// Throws InputError naming the file (and the line) for anything it cannot use: missing or unreadable file,
// another version or the binary form, a malformed section, an element other than a 4-node tetrahedron in 3D
// (or other than a triangle on a physical surface), an inverted or flat tetrahedron, an unknown node.
TetMesh read_gmsh(const std::string& path);

// A mesh body's tetrahedra (its `file`): the MeshReader the driver hands to the model (src/model/unstructured.hpp).
TetMesh read_mesh(const BodySpec& spec);

}  // namespace tissue
