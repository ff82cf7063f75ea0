#include "partition/ghosted_vector.hpp"

#include <algorithm>
#include <cstdint>
#include <stdexcept>

#include "partition/agreement.hpp"

namespace tissue {

namespace {
void check(PetscErrorCode ierr, const char* what) {
  if (ierr) throw std::runtime_error(std::string("PETSc failed in ") + what);
}
}  // namespace

GhostedVector::GhostedVector(const LocalModel& model, int width) {
  std::vector<PetscInt> ghosts = model.block.slice(model.owned, model.local);
  check(VecCreateGhostBlock(model.comm, width, width * model.owned, PETSC_DECIDE, static_cast<PetscInt>(ghosts.size()),
                            ghosts.data(), &vec_), "VecCreateGhostBlock");
  // Its local-to-global map (a PetscInt a local molecule) serves VecSetValuesLocal only, which nothing here calls.
  check(VecSetLocalToGlobalMapping(vec_, nullptr), "VecSetLocalToGlobalMapping");
  // The local form stays open for the vector's lifetime: the kernels read and write it directly.
  check(VecGhostGetLocalForm(vec_, &local_), "VecGhostGetLocalForm");
  check(VecGetArray(local_, &array_), "VecGetArray");
}

GhostedVector::~GhostedVector() {
  if (local_) {
    VecRestoreArray(local_, &array_);
    VecGhostRestoreLocalForm(vec_, &local_);
  }
  if (vec_) VecDestroy(&vec_);
}

void GhostedVector::update_ghosts() {
  // The array stays borrowed from the local form, which shares memory with the global vector: the scatter
  // writes the ghost slots in place.
  check(VecGhostUpdateBegin(vec_, INSERT_VALUES, SCATTER_FORWARD), "VecGhostUpdateBegin");
  check(VecGhostUpdateEnd(vec_, INSERT_VALUES, SCATTER_FORWARD), "VecGhostUpdateEnd");
}

}  // namespace tissue


namespace tissue {

void GhostedVector::add_ghosts_to_owners() {
  check(VecGhostUpdateBegin(vec_, ADD_VALUES, SCATTER_REVERSE), "VecGhostUpdateBegin");
  check(VecGhostUpdateEnd(vec_, ADD_VALUES, SCATTER_REVERSE), "VecGhostUpdateEnd");
}

StreamGhosts::StreamGhosts(const LocalModel& model) {
  // Each rank's block ids [first, first + owned): PETSc's ownership ranges, in rank order.
  const std::int64_t mine[2] = {static_cast<std::int64_t>(model.first_block), model.owned};
  std::vector<std::int64_t> ranges(2 * static_cast<std::size_t>(model.size));
  MPI_Allgather(mine, 2, MPI_INT64_T, ranges.data(), 2, MPI_INT64_T, model.comm);
  std::vector<int> owners;  // the ranks that own molecules, by first block id
  for (int r = 0; r < model.size; ++r)
    if (ranges[2 * r + 1] > 0) owners.push_back(r);
  auto owner_of = [&](std::int64_t block) {
    const auto it = std::upper_bound(owners.begin(), owners.end(), block,
                                     [&](std::int64_t b, int r) { return b < ranges[2 * r]; });
    const int r = it == owners.begin() ? -1 : *(it - 1);
    if (r < 0 || block >= ranges[2 * r] + ranges[2 * r + 1]) throw std::runtime_error("StreamGhosts: ghost owned by no rank");
    return r;
  };
  // The checks below guard invariants of the partition; agreed, so that a failure is one on every rank.
  std::vector<int> owner(model.local - model.owned), counts(model.size, 0);
  agree(model.comm, [&] {
    for (int g = model.owned; g < model.local; ++g) ++counts[owner[g - model.owned] = owner_of(model.block[g])];
  });
  // The requests grouped by owner (a counting sort, each group in ghost order).
  std::vector<int> at(model.size, 0);
  for (int r = 1; r < model.size; ++r) at[r] = at[r - 1] + counts[r - 1];
  std::vector<std::int64_t> requests(owner.size());
  ghost_rows_.resize(owner.size());
  for (int g = model.owned; g < model.local; ++g) {
    const int q = at[owner[g - model.owned]]++;
    requests[q] = model.block[g], ghost_rows_[q] = g;
  }
  plan_ = ExchangePlan(model.comm, counts);
  const std::vector<std::int64_t> asked = plan_.forward(requests);
  send_rows_.resize(asked.size());
  agree(model.comm, [&] {
    for (std::size_t q = 0; q < asked.size(); ++q) {
      const std::int64_t row = asked[q] - static_cast<std::int64_t>(model.first_block);
      if (row < 0 || row >= model.owned) throw std::runtime_error("StreamGhosts: asked for a molecule not owned here");
      send_rows_[q] = static_cast<int>(row);
    }
  });
  out_.resize(3 * send_rows_.size());
  in_.resize(3 * ghost_rows_.size());
}

void StreamGhosts::update(double* x, std::size_t stride) {
  for (std::size_t q = 0; q < send_rows_.size(); ++q)
    for (int d = 0; d < 3; ++d) out_[3 * q + d] = x[d * stride + send_rows_[q]];
  plan_.backward(out_.data(), in_.data(), 3);
  for (std::size_t q = 0; q < ghost_rows_.size(); ++q)
    for (int d = 0; d < 3; ++d) x[d * stride + ghost_rows_[q]] = in_[3 * q + d];
}

}  // namespace tissue
