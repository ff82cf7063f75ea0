#include "partition/connection_table.hpp"

#include <algorithm>
#include <cstring>
#include <unordered_map>
#include <utility>

namespace tissue {

void ConnectionTable::set_rest_lengths(std::vector<double> per_connection) {
  *this = ConnectionTable();
  stiffness_.assign(per_connection.size(), 0.0);
  rest_length_ = std::move(per_connection);
}

void ConnectionTable::set_rest_lengths(std::vector<std::uint16_t> type, std::vector<double> table) {
  *this = ConnectionTable();
  stiffness_.assign(type.size(), 0.0);
  length_type_ = std::move(type), length_table_ = std::move(table);
}

ConnectionTable ConnectionTable::select(const std::vector<int>& which) const {
  ConnectionTable v;
  if (typed()) {
    for (int c : which) v.type_.push_back(type_[c]);
    v.type_stiffness_ = type_stiffness_, v.type_rest_length_ = type_rest_length_;
    return v;
  }
  for (int c : which) {
    v.stiffness_.push_back(stiffness_[c]);
    if (length_type_.empty())
      v.rest_length_.push_back(rest_length_[c]);
    else
      v.length_type_.push_back(length_type_[c]);
  }
  v.length_table_ = length_table_;
  return v;
}

bool ConnectionTable::compact() {
  const std::size_t nc = stiffness_.size();
  if (typed() || nc == 0) return typed();
  struct PairHash {
    std::size_t operator()(const std::pair<std::uint64_t, std::uint64_t>& p) const {
      return std::hash<std::uint64_t>()(p.first * 0x9E3779B97F4A7C15ULL ^ p.second);
    }
  };
  std::unordered_map<std::pair<std::uint64_t, std::uint64_t>, std::uint16_t, PairHash> types;
  std::vector<double> tk, tl;
  const ConnectionColumn length = rest_length_column();
  // Box lattices: per length type, the last k seen with it and its type, a shortcut past the hash (a lattice
  // repeats a few (k, l0) pairs); the same types in the same order of first appearance either way.
  struct Recent {
    std::uint64_t k_bits;
    int type;  // -1: none yet
  };
  std::vector<Recent> recent(length_type_.empty() ? 0 : length_table_.size(), Recent{0, -1});
  auto type_of = [&](std::size_t c) {  // by bits: two different doubles are two types, -0.0 and 0.0 included
    std::uint64_t kb, lb;
    std::memcpy(&kb, &stiffness_[c], 8);
    Recent* r = recent.empty() ? nullptr : &recent[length_type_[c]];
    if (r && r->type >= 0 && r->k_bits == kb) return static_cast<std::uint16_t>(r->type);
    const double l0 = length[static_cast<int>(c)];
    std::memcpy(&lb, &l0, 8);
    auto [it, added] = types.try_emplace({kb, lb}, static_cast<std::uint16_t>(std::min<std::size_t>(tk.size(), 65535)));
    if (added) tk.push_back(stiffness_[c]), tl.push_back(l0);
    if (r) *r = {kb, it->second};
    return it->second;
  };
  // The shortcut inline (most connections of a lattice), type_of for the rest: the same answers.
  auto lattice_type_of = [&](std::size_t c) {
    std::uint64_t kb;
    std::memcpy(&kb, &stiffness_[c], 8);
    const Recent& r = recent[length_type_[c]];
    return r.type >= 0 && r.k_bits == kb ? static_cast<std::uint16_t>(r.type) : type_of(c);
  };
  // First the table alone: past 65,536 types nothing changes.
  for (std::size_t c = 0; c < nc; ++c) {
    if (recent.empty()) type_of(c);
    else lattice_type_of(c);
    if (tk.size() > 65536) return false;
  }
  if (!length_type_.empty()) {
    // Box lattices: each connection's type over its length type, which nothing reads after connection c's own
    // lookup; the array becomes the types' (no fresh 2 B a connection to fault in and zero).
    for (std::size_t c = 0; c < nc; ++c) length_type_[c] = lattice_type_of(c);
    type_ = std::move(length_type_);
    length_type_ = std::vector<std::uint16_t>(), length_table_ = std::vector<double>();
    stiffness_ = std::vector<double>();
    type_stiffness_ = std::move(tk), type_rest_length_ = std::move(tl);
    return true;
  }
  // Then each connection's type, 2 bytes at the front of the stiffness array's own storage (byte 2c lies in
  // entry c / 4, already read), so no third per-connection array exists while both 8-byte ones do: that was
  // the set-up's peak (docs/benchmarks.md).
  unsigned char* packed = reinterpret_cast<unsigned char*>(stiffness_.data());
  for (std::size_t c = 0; c < nc; ++c) {
    const std::uint16_t t = type_of(c);
    std::memcpy(packed + 2 * c, &t, 2);
  }
  rest_length_ = std::vector<double>();
  length_type_ = std::vector<std::uint16_t>(), length_table_ = std::vector<double>();
  type_.resize(nc);
  std::memcpy(type_.data(), packed, 2 * nc);
  stiffness_ = std::vector<double>();
  type_stiffness_ = std::move(tk), type_rest_length_ = std::move(tl);
  return true;
}

}  // namespace tissue
