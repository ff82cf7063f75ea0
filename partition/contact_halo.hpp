// The contact halo: a second, distance-based set of ghosts. Molecule-molecule contact needs, on each rank, the
// positions of the other ranks' molecules within the contact reach (cutoff + skin) of its own, whether or not a
// connection joins them, so the connection ghosts of local_model are not enough. rebuild() finds them from the
// current positions (each rank's owned bounding box, grown by the reach, is gathered by all; each rank sends the
// owned molecules that fall within reach of another rank's box); update() refreshes their positions with the same
// lists (one MPI_Alltoallv of positions). The contact term rebuilds when some molecule has moved more than half
// the skin since the last rebuild, so between rebuilds no pair can come within the cutoff unseen.
#pragma once
#include <mpi.h>

#include <cstdint>
#include <vector>

#include "partition/exchange.hpp"
#include "partition/local_model.hpp"

namespace tissue {

class ContactHalo {
public:
  ContactHalo(const LocalModel& model, double reach) : m_(model), reach_(reach) {}
  void set_reach(double reach) { reach_ = reach; }  // m; takes effect at the next rebuild
  // Collective. Finds the halo for the owned positions x (3 * owned values used).
  void rebuild(const double* x);
  // Collective. Refreshes the halo's positions from the owned positions x (same molecules as the last rebuild).
  void update(const double* x);

  int size() const { return static_cast<int>(id_.size()); }
  const std::vector<std::int64_t>& id() const { return id_; }     // original ids, in receive order
  const std::vector<int>& body() const { return body_; }           // which body each belongs to
  const double* positions() const { return x_.data(); }            // 3 per halo molecule
  long rebuilds() const { return rebuilds_; }

private:
  const LocalModel& m_;
  double reach_;
  std::vector<int> send_;                        // owned local indices, grouped by destination rank
  ExchangePlan plan_;                            // molecules per rank, both ways
  std::vector<std::int64_t> id_;
  std::vector<int> body_;
  std::vector<double> x_, buffer_;
  long rebuilds_ = 0;
};

}  // namespace tissue
