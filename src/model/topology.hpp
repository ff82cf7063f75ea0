// Topologies: which molecules of a box a connection joins. A new topology is one new file in
// src/model/topologies/: its stencil (the lattice offsets of a molecule's neighbours), its explicit builder, and
// its registration line TISSUE_TOPOLOGY(id, {...}) (CMake lists those lines in a generated file; nothing else is
// edited).
//
// Two views of the same topology: the stencil answers "who are molecule g's neighbours" for any g, so each rank
// generates only the connections of its own molecules (partition/lattice_model.cpp) and no rank ever holds the
// whole connection list; the explicit builder enumerates every connection (and tetrahedron) of the body, the
// independent reference the tests check the stencil against (tests/whole_body.hpp).
#pragma once
#include <array>
#include <string>
#include <vector>

#include "src/model/body.hpp"

namespace tissue {

// Fills body.connections (any order; tests/whole_body's build_body sorts them) and, for tetrahedral meshes, body.tetrahedra.
using TopologyBuilder = void (*)(Body& body);

// A lattice offset (di, dj, dk) to a neighbour; its class is the number of non-zero components minus one.
struct StencilOffset {
  int d[3];
};

// The families of connections in a lattice cell that a cell law splits its stiffness among (homogenized, the cell
// term: src/model/cell_law.hpp): the edges, plus both diagonals of every face, plus the body diagonals. A Kuhn
// topology (its cells split into tetrahedra) has none.
enum class CellFamilies { none, edges, face_diagonals, body_diagonals };

struct TopologyStyle {
  const char* name;
  TopologyBuilder build;
  const char* description;
  std::vector<StencilOffset> stencil;  // every offset, both signs (the relation is symmetric)
  bool tetrahedra = false;             // connections are the edges of the cells' Kuhn tetrahedra (Eq. 5 needs them)
  CellFamilies cells = CellFamilies::none;
  // Diagonals give the cell shear of its own: homogenized reaches any Poisson ratio in range (docs/poisson.md).
  bool carries_poisson() const { return cells == CellFamilies::face_diagonals || cells == CellFamilies::body_diagonals; }
};

struct Neighbour {
  std::int64_t id;
  ConnectionClass cls;
  int direction;  // its offset's index in the topology's stencil
};

// The neighbours of molecule g (global id) in its box, in increasing id order (the order of the global
// connection list and of the METIS graph). `out` is cleared first.
void lattice_neighbours(const TopologyStyle& style, const BoxGeometry& box, std::int64_t g, std::vector<Neighbour>& out);

// The same neighbours, from a stencil laid on one box once: each offset's id step and class, and the margin its
// offsets reach along each axis. A molecule at least that far from every face has every neighbour, already in id
// order when the steps increase (any box whose sides hold more molecules than an offset spans): its list is g plus
// the steps, with no bounds check and no sort. Others go through lattice_neighbours. Why: the lattice set-up asks
// for every molecule's neighbours several times (partition, counts, ghosts, connections).
class LatticeStencil {
public:
  LatticeStencil(const TopologyStyle& style, const BoxGeometry& box);
  void neighbours(std::int64_t g, std::vector<Neighbour>& out) const {
    const auto ijk = box_.index(g);
    bool inside = sorted_;
    for (int d = 0; d < 3; ++d) inside = inside && ijk[d] >= reach_[d] && ijk[d] < box_.n[d] - reach_[d];
    if (!inside) return near_face(g, ijk, out);
    out.resize(step_.size());
    for (std::size_t s = 0; s < step_.size(); ++s) out[s] = {g + step_[s], cls_[s], static_cast<int>(s)};
  }
  // The rest distance of a neighbour in that direction: BoxGeometry::rest_distance's double for its offset.
  double rest_distance(const Neighbour& x) const { return distance_[x.direction]; }
  std::size_t directions() const { return step_.size(); }
  // Whether molecule g has its whole stencil, and then its lowest and highest neighbour ids.
  bool interior(std::int64_t g, std::int64_t& lowest, std::int64_t& highest) const {
    const auto ijk = box_.index(g);
    bool inside = sorted_ && !step_.empty();
    for (int d = 0; d < 3; ++d) inside = inside && ijk[d] >= reach_[d] && ijk[d] < box_.n[d] - reach_[d];
    if (inside) lowest = g + step_.front(), highest = g + step_.back();
    return inside;
  }
  // An interior molecule's forward neighbours (higher ids) are the stencil's last `forward` directions, as the
  // steps increase: from direction forward_begin() on, id g + step(s), class connection_class(s).
  std::size_t forward_begin() const { return step_.size() - static_cast<std::size_t>(forward_); }
  std::int64_t step(std::size_t s) const { return step_[s]; }
  ConnectionClass connection_class(std::size_t s) const { return cls_[s]; }
  // Molecule g's neighbour count and how many of them have higher ids, without the list: from the stencil inside,
  // from the list (left in `out`) near a face. The set-up's counting passes need no more.
  void counts(std::int64_t g, std::vector<Neighbour>& out, int& degree, int& forward) const {
    const auto ijk = box_.index(g);
    bool inside = sorted_;
    for (int d = 0; d < 3; ++d) inside = inside && ijk[d] >= reach_[d] && ijk[d] < box_.n[d] - reach_[d];
    if (inside) {
      degree = static_cast<int>(step_.size()), forward = forward_;
      return;
    }
    near_face(g, ijk, out);
    degree = static_cast<int>(out.size()), forward = 0;
    for (const auto& x : out) forward += x.id > g;
  }

private:
  // Near a face: the offsets that stay in the box, by the same steps (sorted steps keep the list sorted);
  // lattice_neighbours' sort where they are not.
  void near_face(std::int64_t g, const std::array<long, 3>& ijk, std::vector<Neighbour>& out) const {
    if (!sorted_) return lattice_neighbours(*style_, box_, g, out);
    out.clear();
    for (std::size_t s = 0; s < step_.size(); ++s) {
      const int* d = style_->stencil[s].d;
      bool in = true;
      for (int a = 0; a < 3; ++a) in = in && ijk[a] + d[a] >= 0 && ijk[a] + d[a] < box_.n[a];
      if (in) out.push_back({g + step_[s], cls_[s], static_cast<int>(s)});
    }
  }
  const TopologyStyle* style_;
  BoxGeometry box_;
  std::vector<std::int64_t> step_;  // per stencil offset, in the stencil's order: the id difference
  std::vector<ConnectionClass> cls_;
  std::vector<double> distance_;  // per stencil offset: the rest distance
  long reach_[3] = {0, 0, 0};
  bool sorted_ = false;  // the steps increase strictly: interior lists need no sort
  int forward_ = 0;       // steps > 0: an interior molecule's neighbours with higher ids
};

// Tetrahedral topology: how many of the cells' Kuhn tetrahedra contain both molecules a and b (the connection's
// incident tetrahedra, Van Gelder's Eq. 5), and the volume of one (every Kuhn tetrahedron of a box has the same).
int kuhn_tetrahedra_on(const BoxGeometry& box, std::int64_t a, std::int64_t b);
double kuhn_tetrahedron_volume(const BoxGeometry& box);

// Registers a topology, in its own file: TISSUE_TOPOLOGY(face_diagonals, {"face-diagonals", ...}).
#define TISSUE_TOPOLOGY(id, ...)                     \
  const TopologyStyle& topology_style_##id() {       \
    static const TopologyStyle style __VA_ARGS__;   \
    return style;                                    \
  }

// Building blocks the topologies share (src/model/topologies/): a connection p-q (stored with a < b), the axis
// stencil and explicit builders that others extend.
void add_connection(Body& b, std::int64_t p, std::int64_t q, ConnectionClass c);
std::vector<StencilOffset> axis_offsets();
std::vector<StencilOffset> with_face_diagonals(std::vector<StencilOffset> s);
void build_rectangular(Body& b);
void build_face_diagonals(Body& b);

// Every registered topology, in the order of their files' names; find_topology returns nullptr for an unknown name.
const std::vector<TopologyStyle>& topology_styles();
const TopologyStyle* find_topology(const std::string& name);
std::vector<std::string> topology_names();

}  // namespace tissue
