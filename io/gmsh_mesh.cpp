#include "io/gmsh_mesh.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <unordered_map>

namespace tissue {
namespace {

// Whitespace-separated tokens with their line numbers; a double-quoted token may hold spaces (physical names).
class Lexer {
public:
  Lexer(const std::string& text, const std::string& file) : s_(text), file_(file) {}

  bool at_end() {
    skip();
    return pos_ >= s_.size();
  }
  long line() const { return line_; }
  std::string word(const char* what) {
    skip();
    if (pos_ >= s_.size()) fail(fmt::format("unexpected end of file, expected {}", what));
    token_line_ = line_;
    std::size_t start = pos_;
    if (s_[pos_] == '"') {
      std::size_t end = s_.find('"', pos_ + 1);
      if (end == std::string::npos || s_.find('\n', pos_) < end) fail("unterminated quoted name");
      pos_ = end + 1;
      return s_.substr(start + 1, end - start - 1);
    }
    while (pos_ < s_.size() && !std::isspace(static_cast<unsigned char>(s_[pos_]))) ++pos_;
    return s_.substr(start, pos_ - start);
  }
  long long integer(const char* what) {
    std::string w = word(what);
    char* end = nullptr;
    errno = 0;
    long long v = std::strtoll(w.c_str(), &end, 10);
    if (w.empty() || *end || errno) fail(fmt::format("expected {} (an integer), got \"{}\"", what, w));
    return v;
  }
  long long count(const char* what) {
    long long v = integer(what);
    if (v < 0) fail(fmt::format("{} is negative ({})", what, v));
    return v;
  }
  double number(const char* what) {
    std::string w = word(what);
    char* end = nullptr;
    errno = 0;
    double v = std::strtod(w.c_str(), &end);
    if (w.empty() || *end || errno == ERANGE || !std::isfinite(v))
      fail(fmt::format("expected {} (a finite number), got \"{}\"", what, w));
    return v;
  }
  void expect(const std::string& tag) {
    std::string w = word(tag.c_str());
    if (w != tag) fail(fmt::format("expected {}, got \"{}\"", tag, w));
  }
  [[noreturn]] void fail(const std::string& problem) const {
    throw InputError(file_, "", fmt::format("line {}: {}", token_line_, problem));
  }

private:
  void skip() {
    while (pos_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[pos_]))) {
      if (s_[pos_] == '\n') ++line_;
      ++pos_;
    }
  }
  const std::string& s_;
  const std::string& file_;
  std::size_t pos_ = 0;
  long line_ = 1, token_line_ = 1;
};

// Nodes per element type (the specification's table, types 1-31) and names for messages.
int nodes_of(int type) {
  static const int n[] = {0, 2, 3, 4, 4, 8, 6, 5, 3, 6, 9, 10, 27, 18, 14, 1, 8, 20, 15, 13,
                          9, 10, 12, 15, 15, 21, 4, 5, 6, 20, 35, 56};
  return type >= 1 && type <= 31 ? n[type] : -1;
}
std::string type_name(int type) {
  switch (type) {
    case 1: return "2-node line";
    case 2: return "3-node triangle";
    case 3: return "4-node quadrangle";
    case 4: return "4-node tetrahedron";
    case 5: return "8-node hexahedron";
    case 6: return "6-node prism";
    case 7: return "5-node pyramid";
    case 9: return "6-node triangle";
    case 11: return "10-node tetrahedron";
    case 15: return "point";
    default: return fmt::format("{}-node element", nodes_of(type));
  }
}

struct Entity {
  std::vector<int> physical;  // physical tags
};

}  // namespace

TetMesh read_gmsh(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "", std::string("cannot open the mesh: ") + std::strerror(errno));
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string text = buffer.str();
  if (in.bad()) throw InputError(path, "", std::string("cannot read the mesh: ") + std::strerror(errno));
  Lexer lex(text, path);

  std::map<std::pair<int, int>, std::string> physical_name;  // (dim, tag) -> name
  std::map<std::pair<int, int>, Entity> entities;            // (dim, tag)
  std::unordered_map<long long, Vec3> node;                  // tag -> position
  struct Tet {
    std::array<long long, 4> tags;
    int physical;  // -1: none
  };
  std::vector<Tet> tets;
  std::map<int, std::vector<std::array<long long, 3>>> surface;  // physical tag -> triangles (node tags)
  bool format = false, have_entities = false, have_nodes = false, have_elements = false;

  while (!lex.at_end()) {
    const std::string section = lex.word("a section");
    if (!format && section != "$MeshFormat") lex.fail("not a Gmsh mesh: it must begin with $MeshFormat");
    if (section.empty() || section[0] != '$') lex.fail(fmt::format("expected a $Section, got \"{}\"", section));
    const std::string name = section.substr(1);
    if (name == "MeshFormat") {
      const std::string version = lex.word("the version");
      const long long type = lex.integer("the file type");
      lex.integer("the data size");
      if (version.rfind("4.1", 0) != 0)
        lex.fail(fmt::format("format version {}; only 4.1 is read (gmsh -format msh41)", version));
      if (type != 0) lex.fail("binary .msh; only ASCII is read (Gmsh option Mesh.Binary = 0)");
      format = true;
    } else if (name == "PhysicalNames") {
      const long long n = lex.count("the number of physical names");
      for (long long i = 0; i < n; ++i) {
        const int dim = static_cast<int>(lex.integer("a dimension"));
        const int tag = static_cast<int>(lex.integer("a physical tag"));
        physical_name[{dim, tag}] = lex.word("a physical name");
      }
    } else if (name == "Entities") {
      long long count[4];
      for (auto& c : count) c = lex.count("an entity count");
      for (int dim = 0; dim < 4; ++dim)
        for (long long i = 0; i < count[dim]; ++i) {
          const int tag = static_cast<int>(lex.integer("an entity tag"));
          for (int k = 0; k < (dim == 0 ? 3 : 6); ++k) lex.number("a coordinate of the bounding box");
          Entity e;
          const long long np = lex.count("the number of physical tags");
          for (long long k = 0; k < np; ++k) e.physical.push_back(static_cast<int>(lex.integer("a physical tag")));
          if (dim > 0) {
            const long long nb = lex.count("the number of bounding entities");
            for (long long k = 0; k < nb; ++k) lex.integer("a bounding entity tag");
          }
          entities[{dim, tag}] = e;
        }
      have_entities = true;
    } else if (name == "PartitionedEntities") {
      lex.fail("a partitioned mesh; save it unpartitioned (tissue partitions it itself)");
    } else if (name == "Nodes") {
      const long long blocks = lex.count("the number of node blocks");
      lex.count("the number of nodes");
      lex.integer("the smallest node tag");
      lex.integer("the largest node tag");
      for (long long b = 0; b < blocks; ++b) {
        const int dim = static_cast<int>(lex.integer("an entity dimension"));
        lex.integer("an entity tag");
        const long long parametric = lex.integer("the parametric flag");
        const long long n = lex.count("the number of nodes in the block");
        std::vector<long long> tags(n);
        for (auto& t : tags) t = lex.integer("a node tag");
        for (long long i = 0; i < n; ++i) {
          Vec3 x;
          for (auto& c : x) c = lex.number("a node coordinate");
          for (int k = 0; k < (parametric ? dim : 0); ++k) lex.number("a parametric coordinate");
          if (!node.emplace(tags[i], x).second) lex.fail(fmt::format("node {} is defined twice", tags[i]));
        }
      }
      have_nodes = true;
    } else if (name == "Elements") {
      if (!have_nodes) lex.fail("$Elements before $Nodes");
      const long long blocks = lex.count("the number of element blocks");
      lex.count("the number of elements");
      lex.integer("the smallest element tag");
      lex.integer("the largest element tag");
      for (long long b = 0; b < blocks; ++b) {
        const int dim = static_cast<int>(lex.integer("an entity dimension"));
        const int entity = static_cast<int>(lex.integer("an entity tag"));
        const int type = static_cast<int>(lex.integer("an element type"));
        const long long n = lex.count("the number of elements in the block");
        const int nn = nodes_of(type);
        if (nn < 0) lex.fail(fmt::format("unknown element type {}", type));
        auto e = entities.find({dim, entity});
        const std::vector<int> none;
        const std::vector<int>& physical = e == entities.end() ? none : e->second.physical;
        std::vector<long long> v(nn);
        for (long long i = 0; i < n; ++i) {
          const long long tag = lex.integer("an element tag");
          for (auto& t : v) {
            t = lex.integer("a node tag");
            if (!node.count(t)) lex.fail(fmt::format("element {} names node {}, which $Nodes does not define", tag, t));
          }
          if (dim == 3) {
            if (type != 4)
              lex.fail(fmt::format("element {} is of type {} ({}); only 4-node tetrahedra (type 4) are supported",
                                   tag, type, type_name(type)));
            const Vec3 &p0 = node[v[0]], &p1 = node[v[1]], &p2 = node[v[2]], &p3 = node[v[3]];
            const double vol = signed_volume(p0, p1, p2, p3);
            if (!(vol > 0))
              lex.fail(fmt::format("tetrahedron {} is {} (volume {:.3e}; Gmsh orders a tetrahedron's nodes so that "
                                   "its volume is positive)", tag, vol < 0 ? "inverted" : "flat", vol));
            tets.push_back({{v[0], v[1], v[2], v[3]}, physical.empty() ? -1 : physical.front()});
          } else if (dim == 2 && !physical.empty()) {
            if (type != 2)
              lex.fail(fmt::format("element {} on a physical surface is of type {} ({}); only 3-node triangles "
                                   "(type 2) bound a tetrahedral mesh", tag, type, type_name(type)));
            for (int p : physical) surface[p].push_back({v[0], v[1], v[2]});
          }
        }
      }
      have_elements = true;
    } else {  // other sections ($NodeData, $Periodic, comments, ...) carry nothing the model uses
      const std::string end = "$End" + name;
      for (;;) {
        if (lex.at_end()) lex.fail(fmt::format("{} has no {}", section, end));
        if (lex.word(end.c_str()) == end) break;
      }
      continue;
    }
    lex.expect("$End" + name);
  }
  if (!format) throw InputError(path, "", "empty file, not a Gmsh mesh");
  if (!have_entities || !have_nodes || !have_elements)
    throw InputError(path, "", std::string("no $") + (!have_entities ? "Entities" : !have_nodes ? "Nodes" : "Elements") +
                                   " section");
  if (tets.empty())
    throw InputError(path, "", "no tetrahedra (mesh the volume, gmsh -3, and put it in a physical volume)");

  // Molecules: the nodes the tetrahedra use, in tag order.
  std::vector<long long> used;
  used.reserve(4 * tets.size());
  for (const auto& t : tets) used.insert(used.end(), t.tags.begin(), t.tags.end());
  std::sort(used.begin(), used.end());
  used.erase(std::unique(used.begin(), used.end()), used.end());
  std::unordered_map<long long, std::int64_t> index;
  TetMesh mesh;
  mesh.file = path;
  mesh.nodes.reserve(used.size());
  for (auto t : used) index[t] = static_cast<std::int64_t>(mesh.nodes.size()), mesh.nodes.push_back(node[t]);
  auto label = [&](int dim, int tag) {
    auto it = physical_name.find({dim, tag});
    return it != physical_name.end() ? it->second : std::to_string(tag);
  };
  std::map<int, int> region_index;  // physical tag -> index in region_names
  for (const auto& t : tets) {
    std::array<std::int64_t, 4> v;
    for (int k = 0; k < 4; ++k) v[k] = index[t.tags[k]];
    mesh.tets.push_back(v);
    int r = -1;
    if (t.physical >= 0) {
      auto [it, added] = region_index.emplace(t.physical, static_cast<int>(mesh.region_names.size()));
      if (added) mesh.region_names.push_back(label(3, t.physical));
      r = it->second;
    }
    mesh.tet_region.push_back(r);
  }
  for (const auto& [tag, triangles] : surface) {
    TetMesh::Surface s;
    s.name = label(2, tag);
    for (const auto& tri : triangles) {
      std::array<std::int64_t, 3> v;
      for (int k = 0; k < 3; ++k) {
        auto it = index.find(tri[k]);
        if (it == index.end())
          throw InputError(path, "", fmt::format("physical surface \"{}\" has node {}, which no tetrahedron uses",
                                                 s.name, tri[k]));
        v[k] = it->second;
      }
      s.triangles.push_back(v);
    }
    mesh.surfaces.push_back(std::move(s));
  }
  return mesh;
}

TetMesh read_mesh(const BodySpec& spec) { return read_gmsh(spec.file); }

}  // namespace tissue
