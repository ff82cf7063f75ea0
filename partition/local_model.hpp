// The rank's share of the body: its owned molecules (first, in original-id order, so their PETSc block ids are
// contiguous), then its ghosts (molecules owned elsewhere that share a connection with an owned one), and every
// connection with at least one owned end, in the global connection order.
//
// Why every connection touching an owned molecule, cut ones on both sides: each rank then sums the forces on
// its molecules by itself, in the same order whatever the partition, so results do not depend on the rank count
// and no reverse (ghost-to-owner) exchange of forces is needed; the price is computing cut connections twice.
#pragma once
#include <mpi.h>
#include <petscsys.h>

#include <algorithm>
#include <cstdint>
#include <vector>

#include "partition/calibration_inputs.hpp"
#include "partition/connection_table.hpp"
#include "partition/metis_partition.hpp"
#include "src/model/body.hpp"

namespace tissue {

// The connections this rank writes to files: those whose end a it owns (each connection is written by exactly
// one rank). A view, not a list: connections are sorted by (a, b) and owned molecules come first, so "end a is
// owned" is end_a[c] < owned.
class WrittenConnections {
public:
  class iterator {
  public:
    iterator(const int* end_a, int c, int n, int owned) : a_(end_a), c_(c), n_(n), owned_(owned) { skip(); }
    int operator*() const { return c_; }
    iterator& operator++() {
      ++c_;
      skip();
      return *this;
    }
    bool operator!=(const iterator& o) const { return c_ != o.c_; }

  private:
    void skip() {
      while (c_ < n_ && a_[c_] >= owned_) ++c_;
    }
    const int* a_;
    int c_, n_, owned_;
  };
  WrittenConnections(const std::vector<int>& end_a, const int& owned, const std::size_t& count)
      : end_a_(end_a), owned_(owned), count_(count) {}
  iterator begin() const { return {end_a_.data(), 0, static_cast<int>(end_a_.size()), owned_}; }
  iterator end() const { return {end_a_.data(), static_cast<int>(end_a_.size()), static_cast<int>(end_a_.size()), owned_}; }
  std::size_t size() const { return count_; }

private:
  const std::vector<int>& end_a_;
  const int& owned_;
  const std::size_t& count_;
};

// A per-local-molecule integer array stored as arithmetic runs when that is at most half the bytes: value[i] =
// the run's first value + its step * (i - the run's start). Ids and PETSc block ids are runs of step 1 (an owned
// block is consecutive molecules in id order), body indices of step 0, a box lattice's first connection ids of
// step the forward degree (three runs a row of the lattice). Why: at 10^6 molecules each plain array of 8 bytes a
// molecule is 8 MB (docs/benchmarks.md, "Explicit memory per molecule"). Meshes partitioned by METIS keep the
// plain array (runs of one molecule would cost more). Read-only by index once assigned: readers never see which
// storage is used.
template <class T>
class RunArray {
public:
  RunArray() = default;
  void assign(const std::vector<T>& values) {
    size_ = static_cast<int>(values.size());
    plain_.clear(), runs_.clear(), last_ = 0;
    std::size_t count = 0;
    for (int i = 0; i < size_; i = run_end(values, i)) ++count;
    if (count * sizeof(Run) * 2 > values.size() * sizeof(T)) {
      plain_ = values;
      return;
    }
    runs_.reserve(count);
    for (int i = 0; i < size_; i = run_end(values, i))
      runs_.push_back({i, i + 1 < size_ ? static_cast<std::int64_t>(values[i + 1] - values[i]) : 0, values[i]});
  }
  T operator[](int i) const {
    if (runs_.empty()) return plain_[i];
    // The run holding i: the last one read if it still holds i (loops read in order), else a binary search.
    std::size_t r = last_;
    if (!(runs_[r].start <= i && (r + 1 == runs_.size() || i < runs_[r + 1].start))) {
      r = static_cast<std::size_t>(std::upper_bound(runs_.begin(), runs_.end(), i,
                                                    [](int v, const Run& x) { return v < x.start; }) -
                                   runs_.begin()) - 1;
      last_ = r;
    }
    return static_cast<T>(runs_[r].first + runs_[r].step * (i - runs_[r].start));
  }
  std::size_t size() const { return static_cast<std::size_t>(size_); }
  bool empty() const { return size_ == 0; }
  // Values [begin, end) as a plain vector (e.g. the ghosts' block ids for PETSc).
  std::vector<T> slice(int begin, int end) const {
    std::vector<T> out;
    out.reserve(end > begin ? end - begin : 0);
    for (int i = begin; i < end; ++i) out.push_back((*this)[i]);
    return out;
  }
  std::vector<T> values() const { return slice(0, size_); }
  bool operator==(const RunArray& o) const { return values() == o.values(); }
  bool operator!=(const RunArray& o) const { return !(*this == o); }

private:
  struct Run {
    int start;
    std::int64_t step;
    T first;
  };
  // Where the run starting at i ends: values keep the step of their first two.
  static int run_end(const std::vector<T>& v, int i) {
    const int n = static_cast<int>(v.size());
    if (i + 1 >= n) return n;
    const auto step = v[i + 1] - v[i];
    int e = i + 2;
    while (e < n && v[e] - v[e - 1] == step) ++e;
    return e;
  }
  int size_ = 0;
  std::vector<T> plain_;  // every value, when runs would not halve the bytes
  std::vector<Run> runs_;  // else the runs, by start
  mutable std::size_t last_ = 0;
};

// The partition's layout of the rank's share: which molecules it holds (owned, then ghosts), where they sit in
// PETSc's numbering and in space, and the ends of its connections. What a connection's spring is (k, l0) is the
// connection table's (partition/connection_table.hpp); what only calibration reads (each molecule's E, ...) is
// handed to calibration separately (partition/calibration_inputs.hpp) and dropped after it.
struct MoleculeLayout {
  MPI_Comm comm = MPI_COMM_NULL;
  int rank = 0, size = 1;
  Body shape;  // the bodies' geometry only (body 0's n, h, offset, topology, and parts); global arrays left empty
  std::int64_t global_molecules = 0, global_connections = 0;
  PartitionStats partition;

  int owned = 0;                     // molecules this rank owns: local indices [0, owned)
  int local = 0;                     // owned + ghosts
  PetscInt first_block = 0;          // PETSc block id of local molecule 0
  RunArray<std::int64_t> id;         // original id of each local molecule
  RunArray<PetscInt> block;          // PETSc block id of each local molecule (ghosts too)
  std::vector<double> rest;          // 3 * local, rest positions
  std::vector<double> mass;          // local, kg
  RunArray<int> body;                // local, which body ([[body]] index) each molecule belongs to
  // local: the global id of the molecule's first connection to a higher id (the global connection order is
  // (a, b), so molecule a's connections to higher ids are numbered one after another from there).
  RunArray<std::int64_t> first_connection;

  // Connections, sorted by (a, b) in global ids: local end indices, class, and b's position among a's
  // connections to higher ids (with first_connection, the global id: 2 bytes a connection instead of 8). Box
  // lattices leave forward_rank empty: the position comes from the topology's stencil when a connection's id is
  // asked for (output plans, guard messages: never per step), and the 2 bytes a connection are saved.
  std::vector<int> end_a, end_b;
  std::vector<std::uint16_t> forward_rank;
  std::vector<ConnectionClass> connection_class;
  std::size_t written_count = 0;     // connections whose end a this rank owns
  // Meshes and clouds calibrated by homogenized only (the per-tetrahedron term; empty otherwise): the tetrahedra
  // with an owned corner, in increasing global id, 4 local corner indices each (every corner is a connection
  // neighbour of the owned one, hence local).
  std::vector<std::int64_t> tetrahedron_id;
  std::vector<int> tetrahedra;
  std::vector<int> tetrahedron_region;  // each tetrahedron's scene region of its body (-1: the body's own material)

  int connections() const { return static_cast<int>(end_a.size()); }
  std::int64_t connection_id(int c) const {
    return first_connection[end_a[c]] + (forward_rank.empty() ? lattice_forward_rank(c) : forward_rank[c]);
  }
  int lattice_forward_rank(int c) const;  // b's position among a's forward neighbours (box lattices)
  // The rank that owns end a writes the connection to files (each connection written exactly once).
  WrittenConnections written_here() const { return {end_a, owned, written_count}; }
};

// The rank's share of the body: the layout, and the connection table of its springs.
struct LocalModel : MoleculeLayout {
  ConnectionTable table;

  double k(int c) const { return table.k(c); }
  double l0(int c) const { return table.l0(c); }
  bool typed() const { return table.typed(); }
};

// Collective: ghost molecules per owned one, the largest over the ranks (PartitionStats::surface_to_volume).
double largest_ghost_ratio(const MoleculeLayout& layout);

// Collective. This rank's LocalModel of the scene, built rank by rank, and what calibration reads of it: box
// lattices from their stencils (partition/lattice_model.hpp), scenes with a mesh or a random cloud from blocks
// that rank 0 hands out (partition/explicit_model.hpp; mesh bodies read by `read_mesh`, io/gmsh_mesh.hpp's
// read_mesh).
LocalModel build_local_model(const Scene& scene, MPI_Comm comm, CalibrationInputs& inputs, const MeshReader& read_mesh = {});

}  // namespace tissue
