#include "io/xdmf.hpp"

#include "io/atomic_file.hpp"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <stdexcept>

namespace tissue {

namespace {

std::string xml_escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

// DataType (XDMF 3) only: meshio rejects an item that has both DataType and NumberType.
void data_item(std::ostream& os, const std::string& h5, const std::string& dataset, int64_t rows, int width,
               bool integer) {
  os << "          <DataItem Dimensions=\"" << rows << ' ' << width << "\" DataType=\"" << (integer ? "Int" : "Float")
     << "\" Precision=\"8\" Format=\"HDF\">" << xml_escape(h5) << ':' << dataset << "</DataItem>\n";
}

void attribute(std::ostream& os, const char* name, bool vector, bool node, const std::string& h5,
               const std::string& dataset, int64_t rows) {
  os << "        <Attribute Name=\"" << name << "\" AttributeType=\"" << (vector ? "Vector" : "Scalar")
     << "\" Center=\"" << (node ? "Node" : "Cell") << "\">\n";
  data_item(os, h5, dataset, rows, vector ? 3 : 1, false);
  os << "        </Attribute>\n";
}

// Bodies with fibres: the deformed fibre direction (glyphs) and stretch (colour) per molecule (node attributes
// of both grids).
void write_fibre_attributes(std::ostream& os, const XdmfEntry& f) {
  if (f.fibre_direction)
    attribute(os, "fibre_direction", true, true, f.h5_file, "/molecules/fibre_direction", f.molecules);
  if (f.fibre_stretch) attribute(os, "fibre_stretch", false, true, f.h5_file, "/molecules/fibre_stretch", f.molecules);
}

// The positions and the node attributes: the same in both grids (they share /molecules).
void geometry_and_nodes(std::ostream& os, const XdmfEntry& f) {
  os << "        <Geometry GeometryType=\"XYZ\">\n";
  data_item(os, f.h5_file, "/molecules/positions", f.molecules, 3, false);
  os << "        </Geometry>\n";
  if (f.displacements) attribute(os, "displacement", true, true, f.h5_file, "/molecules/displacements", f.molecules);
  if (f.velocities) attribute(os, "velocity", true, true, f.h5_file, "/molecules/velocities", f.molecules);
  if (f.forces) attribute(os, "force", true, true, f.h5_file, "/molecules/forces", f.molecules);
  write_fibre_attributes(os, f);
}

}  // namespace

void write_xdmf(const std::string& path, const std::vector<XdmfEntry>& frames) {
  std::ostringstream os;
  os << std::setprecision(17);
  os << "<?xml version=\"1.0\" ?>\n"
     << "<Xdmf Version=\"3.0\">\n"
     << "  <Domain>\n";
  bool any_cells = false;
  for (const XdmfEntry& f : frames) any_cells = any_cells || f.cells > 0;
  if (any_cells) {
    os << "    <Grid Name=\"cells\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
    for (const XdmfEntry& f : frames) {
      if (f.cells <= 0) continue;
      if (f.cell_nodes != 8 && f.cell_nodes != 4)
        throw std::invalid_argument(path + ": " + f.h5_file + ": cells of " + std::to_string(f.cell_nodes) + " corners");
      os << "      <Grid Name=\"cells_" << f.step << "\" GridType=\"Uniform\">\n"
         << "        <Time Value=\"" << f.time << "\"/>\n"
         << "        <Topology TopologyType=\"" << (f.cell_nodes == 8 ? "Hexahedron" : "Tetrahedron")
         << "\" NumberOfElements=\"" << f.cells << "\">\n";
      data_item(os, f.h5_file, "/cells/corners", f.cells, f.cell_nodes, true);
      os << "        </Topology>\n";
      geometry_and_nodes(os, f);
      if (f.volume_ratio) attribute(os, "volume_ratio", false, false, f.h5_file, "/cells/volume_ratio", f.cells);
      if (f.cell_fibre_stretch)
        attribute(os, "fibre_stretch", false, false, f.h5_file, "/cells/fibre_stretch", f.cells);
      os << "      </Grid>\n";
    }
    os << "    </Grid>\n";
  }
  os << "    <Grid Name=\"tissue\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
  for (const XdmfEntry& f : frames) {
    if (f.h5_file.empty() || f.h5_file.find(':') != std::string::npos)
      throw std::invalid_argument(path + ": snapshot file name '" + f.h5_file + "' is empty or holds ':'");
    if (f.molecules <= 0 || f.connections <= 0 || !f.positions || !f.endpoints)
      throw std::invalid_argument(path + ": " + f.h5_file +
                                  ": a frame needs its mesh: /molecules/positions and /connections/endpoints");
    // GridType="Uniform" is spelled out: meshio looks for it to find the mesh.
    os << "      <Grid Name=\"step_" << f.step << "\" GridType=\"Uniform\">\n"
       << "        <Time Value=\"" << f.time << "\"/>\n"
       << "        <Topology TopologyType=\"Polyline\" NodesPerElement=\"2\" NumberOfElements=\"" << f.connections
       << "\">\n";
    data_item(os, f.h5_file, "/connections/endpoints", f.connections, 2, true);
    os << "        </Topology>\n";
    geometry_and_nodes(os, f);
    if (f.connection_strain) attribute(os, "strain", false, false, f.h5_file, "/connections/strain", f.connections);
    if (f.connection_force)
      attribute(os, "connection_force", false, false, f.h5_file, "/connections/force", f.connections);
    os << "      </Grid>\n";
  }
  os << "    </Grid>\n"
     << "  </Domain>\n"
     << "</Xdmf>\n";

  write_file_atomically(path, os.str());
}

void write_lattice_xdmf(const std::string& path, const std::vector<XdmfEntry>& frames) {
  std::ostringstream os;
  os << std::setprecision(17);
  os << "<?xml version=\"1.0\" ?>\n"
     << "<Xdmf Version=\"3.0\">\n"
     << "  <Domain>\n"
     << "    <Grid Name=\"lattice\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
  for (const XdmfEntry& f : frames) {
    if (f.h5_file.empty() || f.h5_file.find(':') != std::string::npos)
      throw std::invalid_argument(path + ": snapshot file name '" + f.h5_file + "' is empty or holds ':'");
    if (!f.positions || f.lattice[0] <= 0 || f.lattice[1] <= 0 || f.lattice[2] <= 0 ||
        f.lattice[0] * f.lattice[1] * f.lattice[2] != f.molecules)
      throw std::invalid_argument(path + ": " + f.h5_file + ": not a single box lattice with its positions");
    // Dimensions slowest first: z, y, x (x runs fastest in the molecule ids, as in the positions' rows).
    os << "      <Grid Name=\"step_" << f.step << "\" GridType=\"Uniform\">\n"
       << "        <Time Value=\"" << f.time << "\"/>\n"
       << "        <Topology TopologyType=\"3DSMesh\" Dimensions=\"" << f.lattice[2] << ' ' << f.lattice[1] << ' '
       << f.lattice[0] << "\"/>\n";
    geometry_and_nodes(os, f);
    os << "      </Grid>\n";
  }
  os << "    </Grid>\n"
     << "  </Domain>\n"
     << "</Xdmf>\n";
  write_file_atomically(path, os.str());
}

}  // namespace tissue
