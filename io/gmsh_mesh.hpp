// Meshes through the Gmsh library (its C++ API, gmsh.h): every format and version Gmsh reads (.msh 4.1 and 2.2,
// ASCII or binary), and a .geo geometry, meshed in 3D at run time. What it keeps: 4-node tetrahedra (every 3D
// element must be one), the triangles of physical surfaces, and the physical volume of each tetrahedron. Nodes
// that no tetrahedron uses are dropped; molecules are the rest, in node-tag order.
#pragma once
#include <string>

#include "src/model/unstructured.hpp"

namespace tissue {

// `path`: a Gmsh mesh (its first line is $MeshFormat, whatever the extension) or a .geo file, which is meshed
// here (gmsh -3); `mesh_size` > 0 (m) then caps the element size (Gmsh's Mesh.MeshSizeMax, over the .geo's own).
// Gmsh runs in a child process (forked here; no MPI in it), started without the command line or configuration
// files, printing nothing; the model comes back through a pipe. So Gmsh's state, memory and libraries stay out
// of this process, and a crash, an exit or a runaway of Gmsh (a corrupt binary file) is one more InputError.
// Throws InputError naming the file for anything it cannot use: a missing or unreadable file, a file Gmsh
// cannot read (its message) or that makes Gmsh crash, exit or run past its time limit, one cut short, a
// partitioned mesh, an element other than a 4-node tetrahedron in 3D (or other than a triangle on a physical
// surface), an inverted or flat tetrahedron, an unknown node, no tetrahedra.
TetMesh read_gmsh(const std::string& path, double mesh_size = 0.0);

// The Gmsh library's version ("4.8.4"), for tissue --version.
std::string gmsh_library_version();

// A mesh body's tetrahedra (its `file`): the MeshReader the driver hands to the model (src/model/unstructured.hpp).
TetMesh read_mesh(const BodySpec& spec);

}  // namespace tissue
