// Each local connection's stiffness k (N/m) and rest length l0 (m), and how they are stored: the storage policy
// lives here, so the rest of the code asks k(c) and l0(c) (or a column, in the force kernels) and never which
// arrays exist.
//
// Why several storages: at 10^8 connections every byte a connection is 100 MB. A box lattice has a handful of
// distinct rest lengths (one per stencil direction and body), so it keeps a 2-byte length type per connection;
// meshes and random clouds keep one length each. While calibration may still change k, k is one double per
// connection; once it is final and the (k, l0) pairs take few values, both become one 2-byte connection type
// (compact()): 16 bytes a connection less.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

namespace tissue {

// A per-connection value as the kernels read it: value[c], or value[type[c]] when stored by type.
struct ConnectionColumn {
  const std::uint16_t* type = nullptr;  // null: one value per connection
  const double* value = nullptr;
  double operator[](int c) const { return type ? value[type[c]] : value[c]; }
};

class ConnectionTable {
public:
  // Set-up, by the model builders: rest lengths one per connection (explicit topologies) or by length type (box
  // lattices; at most 65,536 distinct lengths). Either also sets every stiffness to 0, one per connection.
  void set_rest_lengths(std::vector<double> per_connection);
  void set_rest_lengths(std::vector<std::uint16_t> type, std::vector<double> table);

  // Calibration writes k here, one per connection (not available once compact()).
  std::vector<double>& stiffness() { return stiffness_; }
  const std::vector<double>& stiffness() const { return stiffness_; }

  // Replaces k and l0 by connection types when there are at most 65,536 distinct (k, l0) pairs; returns whether
  // the table is stored by type. Exact: the types hold the same doubles. Call it only once k no longer changes.
  bool compact();

  bool typed() const { return !type_.empty(); }
  bool calibrated() const { return typed() || !stiffness_.empty(); }  // false once stiffness_ was never set up
  double k(int c) const { return typed() ? type_stiffness_[type_[c]] : stiffness_[c]; }
  double l0(int c) const { return rest_length_column()[c]; }
  // Inline: k(c) and l0(c) are read once a connection by set-up passes (checks, calibration).
  ConnectionColumn stiffness_column() const {
    if (typed()) return {type_.data(), type_stiffness_.data()};
    return {nullptr, stiffness_.data()};
  }
  ConnectionColumn rest_length_column() const {
    if (typed()) return {type_.data(), type_rest_length_.data()};
    if (!length_type_.empty()) return {length_type_.data(), length_table_.data()};
    return {nullptr, rest_length_.data()};
  }
  // Box lattices: how many distinct rest lengths (0 when stored per connection or by connection type).
  std::size_t length_types() const { return length_table_.size(); }
  std::size_t connection_types() const { return type_stiffness_.size(); }

  // The same connections' table restricted to `which` (indices into this one), storage kept: a body's view.
  ConnectionTable select(const std::vector<int>& which) const;

private:
  std::vector<double> stiffness_;                 // per connection, until compact()
  std::vector<double> rest_length_;               // per connection (explicit topologies), until compact()
  std::vector<std::uint16_t> length_type_;        // box lattices: index into length_table_, until compact()
  std::vector<double> length_table_;
  std::vector<std::uint16_t> type_;               // after compact(): index into the two type tables
  std::vector<double> type_stiffness_, type_rest_length_;
};

}  // namespace tissue
