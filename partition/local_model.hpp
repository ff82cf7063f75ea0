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

// One end (a or b) of every local connection, in one of two storages. Plain: one int a connection. Runs: a box
// lattice's connections come in rows (one molecule's forward connections, the same end a, sorted by end b) and
// consecutive molecules repeat a row's pattern (the local offsets end b - end a), so a run keeps only its first
// connection, its first molecule and its pattern: end a = first molecule + (c - first connection) / directions,
// end b = end a + the pattern's offset. At 10^6 molecules that is 0.7 MB instead of 71 MB for both ends
// (docs/benchmarks.md, "Explicit memory per molecule"). Readers index it as before (values are the same ints); a
// loop in connection order finds its run at once (the last run read is remembered), other reads by a binary
// search. Only the plain storage has data().
class ConnectionEnd {
public:
  void assign(std::vector<int> values) {
    plain_ = std::move(values);
    size_ = plain_.size();
    runs_.clear(), pattern_start_.clear(), offsets_.clear(), last_ = 0;
  }
  int operator[](int c) const {
    if (runs_.empty()) return plain_[c];
    const Run& r = runs_[find(c)];
    const int start = pattern_start_[r.pattern], directions = pattern_start_[r.pattern + 1] - start;
    const int q = c - r.first_connection, a = r.first_molecule + q / directions;
    return is_b_ ? a + offsets_[start + q % directions] : a;
  }
  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  bool plain() const { return runs_.empty(); }
  // c's position among the connections of its end a here (its row), counted from the row's first.
  int row_position(int c) const {
    if (runs_.empty()) {
      int r = 0;
      while (r < c && plain_[c - r - 1] == plain_[c]) ++r;
      return r;
    }
    const Run& r = runs_[find(c)];
    return (c - r.first_connection) % (pattern_start_[r.pattern + 1] - pattern_start_[r.pattern]);
  }
  const int* data() const { return plain_.data(); }  // the plain storage only
  // f(c, a, b) for every connection c in increasing order, a = (*this)[c] and b = end_b[c]: from the runs, with
  // no search and no division, when both ends are runs of the same rows (to_runs), else value by value. For the
  // passes over every connection outside the force kernel (energy, guards, time step bound).
  template <class F>
  void for_each_pair(const ConnectionEnd& end_b, F&& f) const {
    const int n = static_cast<int>(size_);
    if (runs_.empty() || end_b.runs_.size() != runs_.size()) {
      for (int c = 0; c < n; ++c) f(c, (*this)[c], end_b[c]);
      return;
    }
    for (std::size_t r = 0; r < runs_.size(); ++r) {
      const int last = r + 1 < runs_.size() ? runs_[r + 1].first_connection : n;
      const int start = end_b.pattern_start_[runs_[r].pattern];
      const int directions = end_b.pattern_start_[runs_[r].pattern + 1] - start;
      const int* offset = end_b.offsets_.data() + start;
      int c = runs_[r].first_connection;
      for (int a = runs_[r].first_molecule; c < last; ++a)
        for (int j = 0; j < directions && c < last; ++j, ++c) f(c, a, a + offset[j]);
    }
  }
  // Values [c0, c1) into out, in connection order: one run lookup, no division a value (writers of files walk
  // every connection; operator[] costs a division each).
  void decode(int c0, int c1, int* out) const {
    if (runs_.empty()) {
      std::copy(plain_.begin() + c0, plain_.begin() + c1, out);
      return;
    }
    for (int c = c0; c < c1;) {
      const std::size_t ri = find(c);
      const Run& r = runs_[ri];
      const int end = ri + 1 < runs_.size() ? std::min(c1, runs_[ri + 1].first_connection) : c1;
      const int start = pattern_start_[r.pattern], directions = pattern_start_[r.pattern + 1] - start;
      const int q = c - r.first_connection;
      int a = r.first_molecule + q / directions, d = q % directions;
      for (; c < end; ++c) {
        *out++ = is_b_ ? a + offsets_[start + d] : a;
        if (++d == directions) d = 0, ++a;
      }
    }
  }
  std::vector<int> values() const {
    std::vector<int> out(size_);
    for (std::size_t c = 0; c < size_; ++c) out[c] = (*this)[static_cast<int>(c)];
    return out;
  }
  bool operator==(const ConnectionEnd& o) const { return values() == o.values(); }
  bool operator!=(const ConnectionEnd& o) const { return !(*this == o); }
  std::size_t bytes() const {
    return plain_.capacity() * sizeof(int) + runs_.capacity() * sizeof(Run) +
           (pattern_start_.capacity() + offsets_.capacity()) * sizeof(int);
  }
  // Stores both ends (plain, of the same connections sorted by end a) as runs when each takes at most a quarter
  // of its plain bytes and gives back every value; returns whether it did (else both stay as they are).
  static bool to_runs(ConnectionEnd& a, ConnectionEnd& b);

private:
  struct Run {
    int first_connection, first_molecule, pattern;
  };
  std::size_t find(int c) const {
    auto holds = [&](std::size_t r) {
      return runs_[r].first_connection <= c && (r + 1 == runs_.size() || c < runs_[r + 1].first_connection);
    };
    if (holds(last_)) return last_;
    if (last_ + 1 < runs_.size() && holds(last_ + 1)) return ++last_;
    last_ = static_cast<std::size_t>(std::upper_bound(runs_.begin(), runs_.end(), c, [](int v, const Run& r) {
              return v < r.first_connection;
            }) - runs_.begin()) - 1;
    return last_;
  }
  bool is_b_ = false;
  std::size_t size_ = 0;
  std::vector<int> plain_;
  std::vector<Run> runs_;
  std::vector<int> pattern_start_;  // pattern p: offsets_[pattern_start_[p] .. pattern_start_[p + 1])
  std::vector<int> offsets_;
  mutable std::size_t last_ = 0;
};

// The connections this rank writes to files: those whose end a it owns (each connection is written by exactly
// one rank). A view, not a list: connections are sorted by (a, b) and owned molecules come first, so "end a is
// owned" is end_a[c] < owned.
class WrittenConnections {
public:
  class iterator {
  public:
    iterator(const ConnectionEnd* end_a, int c, int n, int owned) : a_(end_a), c_(c), n_(n), owned_(owned) { skip(); }
    int operator*() const { return c_; }
    iterator& operator++() {
      ++c_;
      skip();
      return *this;
    }
    bool operator!=(const iterator& o) const { return c_ != o.c_; }

  private:
    void skip() {
      while (c_ < n_ && (*a_)[c_] >= owned_) ++c_;
    }
    const ConnectionEnd* a_;
    int c_, n_, owned_;
  };
  WrittenConnections(const ConnectionEnd& end_a, const int& owned, const std::size_t& count)
      : end_a_(end_a), owned_(owned), count_(count) {}
  iterator begin() const { return {&end_a_, 0, static_cast<int>(end_a_.size()), owned_}; }
  iterator end() const { return {&end_a_, static_cast<int>(end_a_.size()), static_cast<int>(end_a_.size()), owned_}; }
  std::size_t size() const { return count_; }

private:
  const ConnectionEnd& end_a_;
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

  // Connections, sorted by (a, b) in global ids: local end indices (plain, or as runs of a lattice's rows once
  // the dynamic solver's stiffness is final: ConnectionEnd), class, and b's position among a's
  // connections to higher ids (with first_connection, the global id: 2 bytes a connection instead of 8). Box
  // lattices leave forward_rank empty: the position comes from the topology's stencil when a connection's id is
  // asked for (output plans, guard messages: never per step), and the 2 bytes a connection are saved.
  ConnectionEnd end_a, end_b;
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
  // f(c, a, b) for the same connections in the same order, with their ends (ConnectionEnd::for_each_pair).
  template <class F>
  void for_each_written(F&& f) const {
    end_a.for_each_pair(end_b, [&](int c, int a, int b) {
      if (a < owned) f(c, a, b);
    });
  }
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
