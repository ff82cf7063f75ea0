// Topologies: which molecules of a box a connection joins. A new topology is one function plus one line in the
// registry (topology.cpp).
#pragma once
#include <string>
#include <vector>

#include "src/model/body.hpp"

namespace tissue {

// Fills body.connections (any order; build_body sorts them) and, for tetrahedral meshes, body.tetrahedra.
using TopologyBuilder = void (*)(Body& body);

struct TopologyStyle {
  const char* name;
  TopologyBuilder build;
  const char* description;
};

const std::vector<TopologyStyle>& topology_styles();
const TopologyStyle* find_topology(const std::string& name);
std::vector<std::string> topology_names();

}  // namespace tissue
