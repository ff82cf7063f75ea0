// libtissue_gmsh.so: the only code that calls Gmsh (io/gmsh_library.hpp says why it is a module of its own).
#include "io/gmsh_library.hpp"

#include <gmsh.h>

#include <algorithm>
#include <cstdio>
#include <exception>

namespace {

using tissue::gmsh_module::Block;
using tissue::gmsh_module::Model;

// Gmsh's state lives from here to the end of the scope, whatever happens. Started without argv (the command line
// is PETSc's and ours) or configuration files; it installs no signal handler. Verbosity 1 and Terminal 0: errors
// are recorded but nothing is printed (at verbosity 0 Gmsh drops errors altogether, and then does not throw on
// them: a file cut short would read as an empty mesh). General.AbortOnError is 2 under the API (throw, not exit).
// One thread: every rank reads (and meshes) the file itself, and the same way.
class Session {
public:
  Session() {
    gmsh::initialize(0, nullptr, false);
    gmsh::option::setNumber("General.Terminal", 0);
    gmsh::option::setNumber("General.Verbosity", 1);
    gmsh::option::setNumber("General.NumThreads", 1);
    gmsh::option::setNumber("General.AbortOnError", 2);
  }
  ~Session() {
    try {
      gmsh::finalize();  // frees the model; also resets Gmsh's "busy" flag, which an exception mid-read leaves set
    } catch (...) {
    }
  }
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;
};

// One line for a message.
std::string one_line(std::string s) {
  std::replace(s.begin(), s.end(), '\n', ' ');
  std::replace(s.begin(), s.end(), '\r', ' ');
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s.empty() ? std::string("an error without a message") : s;
}

void read(const std::string& path, double mesh_size, bool geometry, Model& out, const char*& stage) {
  Session session;
  gmsh::open(path);
  if (geometry) {
    stage = "Gmsh cannot mesh it";
    if (mesh_size > 0) gmsh::option::setNumber("Mesh.MeshSizeMax", mesh_size);  // over the .geo's own
    // A size that would give more molecules than the program takes is refused before meshing, which would take
    // hours: about one node per h^3 of the geometry's bounding box (an overestimate for all but boxes).
    double h = 0, x0, y0, z0, x1, y1, z1;
    gmsh::option::getNumber("Mesh.MeshSizeMax", h);
    gmsh::model::getBoundingBox(-1, -1, x0, y0, z0, x1, y1, z1);
    const double nodes = (x1 - x0) * (y1 - y0) * (z1 - z0) / (h * h * h);
    if (h > 0 && nodes > 2e9) {
      char why[256];
      std::snprintf(why, sizeof why,
                    "an element size of %g m would mesh its %g x %g x %g m bounding box into about %.3g molecules, "
                    "more than the 2e9 supported (mesh_size)", h, x1 - x0, y1 - y0, z1 - z0, nodes);
      throw std::string(why);
    }
    gmsh::model::mesh::generate(3);
    stage = "Gmsh cannot read it";
  }
  std::vector<std::pair<int, int>> groups;
  gmsh::model::getPhysicalGroups(groups);
  for (const auto& [dim, tag] : groups) gmsh::model::getPhysicalName(dim, tag, out.physical_names[{dim, tag}]);
  std::vector<double> parametric;
  gmsh::model::mesh::getNodes(out.node_tags, out.coords, parametric, -1, -1, false, false);
  std::vector<int> types, physical, partitions;
  std::vector<std::vector<std::size_t>> tags, nodes;
  for (int dim : {3, 2}) {
    std::vector<std::pair<int, int>> entities;
    gmsh::model::getEntities(entities, dim);
    for (const auto& entity : entities) {
      gmsh::model::getPartitions(dim, entity.second, partitions);
      out.partitioned = out.partitioned || !partitions.empty();
      gmsh::model::getPhysicalGroupsForEntity(dim, entity.second, physical);
      if (dim == 2 && physical.empty()) continue;
      gmsh::model::mesh::getElements(types, tags, nodes, dim, entity.second);
      for (std::size_t k = 0; k < types.size(); ++k) {
        if (tags[k].empty()) continue;
        Block b;
        b.dim = dim;
        b.entity = entity.second;
        b.type = types[k];
        b.physical = physical;
        b.nodes_per_element = static_cast<int>(nodes[k].size() / tags[k].size());
        b.tags = std::move(tags[k]);
        b.nodes = std::move(nodes[k]);
        out.blocks.push_back(std::move(b));
      }
    }
  }
}

}  // namespace

extern "C" {

__attribute__((visibility("default"))) void tissue_gmsh_read(const std::string& path, double mesh_size,
                                                             bool geometry, Model& out, std::string& error) {
  error.clear();
  const char* stage = "Gmsh cannot read it";
  try {
    read(path, mesh_size, geometry, out, stage);
    return;
  } catch (const std::string& e) {  // Gmsh 4.7-4.8 throws its last error message
    error = one_line(e);
  } catch (const char* e) {
    error = one_line(e ? e : "");
  } catch (const std::exception& e) {  // later versions throw std::runtime_error (and std::bad_alloc anywhere)
    error = one_line(e.what());
  } catch (int e) {  // before 4.7: an error code
    error = "error code " + std::to_string(e);
  } catch (...) {
    error = "an unknown error";
  }
  error = std::string(stage) + ": " + error;
}

__attribute__((visibility("default"))) void tissue_gmsh_version(std::string& version) {
  try {
    Session session;
    gmsh::option::getString("General.Version", version);
  } catch (...) {
    version = GMSH_API_VERSION " (API)";
  }
}

}  // extern "C"
