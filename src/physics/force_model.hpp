// The force model, Eq. 2: F = F_G + F_L + F_C + collisions, with only the terms the scene lists.
// Connection forces (the kernel, connection_forces()) and constant face loads are always there; every other term
// (gravity, viscous friction, cyclic loads, obstacles, molecule-molecule contact: src/physics/term.hpp and the
// registry in terms.cpp) exists only when the scene lists it, and costs nothing otherwise (not constructed).
#pragma once
#include <petscmat.h>

#include <cstdint>
#include <array>
#include <memory>
#include <vector>

#include "src/model/scene.hpp"
#include "partition/ghosted_vector.hpp"
#include "partition/local_model.hpp"
#include "src/physics/spring_kernel.hpp"
#include "src/physics/tangent.hpp"
#include "src/physics/term.hpp"

namespace tissue {

class ForceModel {
public:
  ForceModel(const Scene& scene, const LocalModel& model);

  // Forces on every owned molecule (3 * owned values of f; the 3 * local array is scratch for ghost slots).
  // x: local positions, ghosts up to date; v: owned velocities (read only when viscosity is on).
  // load_factor scales the applied face loads (load stepping); held components get zero force.
  void forces(const double* x, const double* v, double* f, double load_factor = 1.0) const;
  // Connection forces only, into f (3 * local, ghost slots scratch), nothing zeroed for held components.
  // Computed by SpringKernel (src/physics/spring_kernel.hpp).
  void connection_forces(const double* x, double* f) const;
  // Rank-local potential energy of the owned molecules' share: springs (half per end) and gravity and loads.
  double potential_energy(const double* x, double load_factor = 1.0) const;

  // Tangent stiffness -dF/dx of the connection forces, owned rows, held components' rows and columns replaced
  // by identity (so the matrix stays symmetric). J must come from create_tangent (its row pattern is cached here).
  PetscErrorCode assemble_tangent(const double* x, Mat J) const;
  PetscErrorCode create_tangent(Mat* J) const;  // AIJ, block size 3, exactly preallocated
  // The same tangent without storing it (the matrix-free static solver, src/solvers/matrix_free.hpp), each block
  // recomputed from the positions x (local, ghosts up to date) as assemble_tangent computes it:
  // out (3 * owned) = J in, in: 3 * local values (ghosts up to date), its held components zeroed here (scratch);
  // held components' rows and columns the identity's.
  // skip_cached: without the terms' blocks, which the caller adds from its own copy (cached_tangent_blocks).
  // final_rows (with skip_cached): called with out's owned rows as the springs' part of them becomes final
  // (SpringKernel::tangent), before the held rows are written, so that a term's product joins the same pass.
  // rest (x then the rest positions): the springs' part from those constants (SpringKernel::rest_tangent).
  PetscErrorCode apply_tangent(const double* x, double* in, double* out, bool skip_cached = false,
                               SpringKernel::FinalRows final_rows = nullptr, void* context = nullptr,
                               const RestStencil* rest = nullptr) const;
  // J's diagonal (3 * owned).
  PetscErrorCode tangent_diagonal(const double* x, double* diag, bool skip_cached = false) const;
  // Frees the connections by row that tangent_blocks built (76 B a molecule at face diagonals), when no assembled
  // tangent needs them; the next tangent_blocks builds them again. The matrix-free solver keeps them only while
  // it makes the coarse operators, not through the linear solves.
  void release_block_rows() const;
  // Whether some term's tangent is worth caching (Term::tangent_worth_caching), and then every term's blocks (the
  // cache holds a molecule's 27 blocks anyway), held components not masked; nothing when none is.
  bool has_cached_tangent() const;
  bool has_terms() const { return !terms_.empty(); }  // any term beyond the connections' springs
  bool terms_within_cells() const {  // every term's blocks within a lattice cell (Term::tangent_within_cells)
    for (const auto& t : terms_)
      if (!t->tangent_within_cells()) return false;
    return true;
  }
  PetscErrorCode cached_tangent_blocks(const double* x, Term::BlockAdd add, void* ctx) const;
  // Collective. Gershgorin's bound on the largest eigenvalue of D^-1 J (D: J's diagonal; held rows the identity's):
  // max over rows of 1 + sum_j!=i |J_ij| / J_ii. exact = false (and the bound not computed) when a term adds
  // blocks: they come after the connections' rows, and summing their magnitudes block by block would overstate
  // the bound. The Chebyshev smoother's interval on the finest level (src/solvers/newton_equilibrium.cpp).
  PetscErrorCode jacobi_gershgorin(const double* x, double* bound, bool* exact) const;
  // Every 3x3 block of -dF/dx (owned rows, local columns, held components not masked): the terms' in their own
  // order, each molecule's connection row (the diagonal block last) just before the terms' first block of its row,
  // then the connection rows no term named, in owned order. Blocks may repeat. At the rest positions the
  // connection rows are tangent_blocks_unless's (a box lattice's from its lattice offsets: round-off apart).
  PetscErrorCode tangent_blocks(const double* x, Term::BlockAdd add, void* ctx) const;
  // tangent_blocks with each owned row first shown to known(known_ctx, i, ends, n, inputs, m): what its blocks are
  // computed from alone: its connections' other ends in the row's order, each with 5 doubles (d = x_j - x_i, k,
  // l0; at the rest positions a box lattice's d from the lattice offsets, the same doubles for every connection of
  // an offset), then each term's columns and key (Term::rest_row). Rows with equal inputs and ends at the same
  // lattice offsets have equal blocks, to the bit; a row known answers true for is not streamed (LatticeGalerkin's
  // stream: a box lattice's rows at its reference state). Springs only, or at the rest positions when every term
  // has rest rows (Term::rest_rows; then each streamed row's connection row and its terms' blocks together, in
  // owned order); otherwise tangent_blocks, known never asked.
  // lattice (may be null): every local molecule's lattice index in its body (BoxGeometry::index; LatticeGalerkin's),
  // read instead of computed from the ids at the rest positions (the same offsets).
  using RowKnown = bool (*)(void* ctx, int i, const int* ends, int n, const double* inputs, int m);
  PetscErrorCode tangent_blocks_unless(const double* x, Term::BlockAdd add, void* ctx, RowKnown known,
                                       void* known_ctx, const std::array<int, 3>* lattice = nullptr) const;
  // Collective: the smallest time step bound the terms impose by themselves (infinity: none; Term::critical_time_step).
  double terms_critical_time_step() const;
  // Adds each term's force scale per owned molecule (N) to scale (the residual's round-off floor).
  void add_force_scale(const double* x, std::vector<double>& scale, std::vector<double>& squares) const;
  // The fibre field of the terms that carry fibres (Term::fibre_field), 3 and 1 values per owned molecule; false
  // (and nothing written) when no term has fibres on this rank.
  bool fibre_field(const double* x, double* direction, double* stretch) const;
  // The cells of the term that has them (Term::cells; none: global_count 0), at x (ghosts up to date).
  CellField cells(const double* x) const;

  const std::vector<std::uint8_t>& held() const { return held_; }   // 3 * owned: 1 = held component
  // The held components of owned molecules, ascending (few: faces only), so a step does not scan held().
  const std::vector<int>& held_owned() const { return held_owned_; }
  // The constant face loads at factor 1: component j (= 3 * owned molecule + axis) gets value (N).
  struct AppliedForce {
    int component;
    double value;
    int load;  // its [[load]] (scene order), whose history scales it
  };
  const std::vector<AppliedForce>& applied() const { return applied_; }
  double applied_norm() const { return applied_norm_; }             // global 2-norm of loads + gravity
  double largest_stiffness_rate() const;
  const SpringKernel& kernel() const { return kernel_; }
  // Whether the first term adds its forces inside the kernel's sweep (Term::adds_by_rows; -tissue_fuse_terms).
  bool fuses_first_term() const { return fuse_first_term_; }
  // Whether forces() is the connection forces alone (no load, term or held component).
  bool springs_only() const { return applied_.empty() && terms_.empty() && held_owned_.empty(); }  // max over molecules of 2 sum k / m (Gershgorin bound of omega^2)

  // Time of the next force evaluation (s): time-dependent terms (cyclic loads) and the loads' histories read it.
  // The dynamic and quasi-static solvers set it.
  void set_time(double t) const;
  // Moves the held components of owned molecules to where their [[fix]] holds them at time t (rest position plus
  // displacement times the fix's history factor); ghosts are left to the caller's update. Nothing moves for fixes
  // without a displacement.
  void place_held(double t, double* x) const;
  bool moves_held() const { return moves_held_; }
  // Collective: the total force each [[fix]] exerts on the body at x (scene order; a component held by several
  // fixes counts for the first), i.e. minus the other forces on its held components.
  // load_factor scales the loads as in forces() (the static solver's load steps).
  std::vector<Vec3> reactions(const double* x, const double* v, double* scratch, double load_factor = 1.0) const;
  // Collective: the same, from the last forces() call's forces on the held components (kept as it zeroes them),
  // with no new evaluation: what a dynamic run's history.csv row reads at each step.
  std::vector<Vec3> last_reactions() const;
  // The applied loads' total at time t (N), the [[load]] forces times their history (or cyclic) factors.
  Vec3 applied_total(double t) const;
  // Terms with internal variables that follow time (viscoelastic history, src/physics/term.hpp): the solver
  // begins each step with its dt and commits its end state.
  bool has_history() const;
  void begin_step(double dt) const;
  void commit_step(const double* x) const;
  // Checkpoints: the terms' internal variables per local connection, history_width() values a connection (each
  // history term's columns in the terms' order); set_history puts saved ones back (Term::load_history).
  int history_width() const;
  std::vector<double> history() const;
  void set_history(const std::vector<double>& rows) const;
  // The per-cell internal variables (Term::cell_history_width; one term at most has cells): null when none.
  Term* cell_history() const;
  // The terms built for this scene, by name (the connection forces and constant loads are not listed).
  std::vector<std::string> term_names() const;
  // The terms themselves (the matrix-free tangent asks them for their own products: Term::has_tangent_state).
  const std::vector<std::unique_ptr<Term>>& terms() const { return terms_; }
  // Every listed term keeps the total energy from growing (TermStyle::energy_never_grows; true with none).
  bool energy_never_grows() const;
  // Some listed term reads the velocities (TermStyle::reads_velocity).
  bool reads_velocity() const;
  // Some listed term asks Newton's line search to go by the energy (TermStyle::energy_line_search).
  bool energy_line_search() const;
  // Collective: the contact force totals of the last force evaluation, summed over the ranks; nullopt-like
  // (has_obstacles/has_contact false) when the scene has no such term.
  struct Contact {
    bool obstacles = false, molecules = false;
    ContactTotals totals;
  };
  Contact contact_totals() const;

private:
  const LocalModel& model_;
  SpringKernel kernel_;  // the connection forces (src/physics/spring_kernel.hpp)
  std::vector<std::uint8_t> held_;
  std::vector<int> held_owned_;
  std::vector<int> held_ghosts_;  // the held components of ghosts (3 * owned .. 3 * local - 1)
  mutable std::vector<double> tangent_held_in_;  // apply_tangent's copy of the held inputs, kept between products
  std::vector<AppliedForce> applied_;  // non-zero components only
  std::vector<std::unique_ptr<Term>> terms_;  // only what the scene lists, in the registry's order
  // The first term adds its forces in pieces inside the kernel's sweep (Term::adds_by_rows), with the loads
  // added to each run of final rows just before: applied_ in the order of their components (stable: a component's
  // own loads keep their order). Off with -tissue_fuse_terms false (benchmarks, tests).
  bool fuse_first_term_ = false;
  // The term runs on batches of at least this many final rows (-tissue_fuse_rows): each switch between the two
  // kernels refills L1 with the other's blocks (cachegrind: a switch every lattice row doubled both kernels' L1
  // misses), while a batch's x and f stay in L2 (docs/benchmarks.md).
  int term_batch_ = 2048;
  std::vector<int> applied_by_row_;
  std::vector<const TermStyle*> term_styles_;  // the style of each (what it can do)
  double applied_norm_ = 0.0;
  mutable double time_ = 0.0;
  const Scene& scene_;
  std::vector<int> held_fix_;            // parallel to held_owned_: the fix that holds the component
  mutable std::vector<double> tangent_ghost_rows_;  // apply_tangent's scratch for the ghosts' rows (24 B a ghost)
  mutable std::vector<double> held_force_;  // parallel to held_owned_: the last forces() call's force there
  bool moves_held_ = false;              // some fix has a displacement
  mutable std::vector<double> load_scale_;  // per [[load]]: its history factor at time_ (1 without history)
  // tangent_blocks' connection rows alone (owned order, the diagonal block last).
  PetscErrorCode connection_blocks(const double* x, Term::BlockAdd add, void* ctx) const;
  // Owned molecule i's connection row (the diagonal block last); the rows made (create_rows).
  PetscErrorCode connection_row(const double* x, int i, Term::BlockAdd add, void* ctx) const;
  PetscErrorCode connection_row_of(int i, const int* ends, const double* inputs, int count, Term::BlockAdd add,
                                   void* ctx) const;
  // Whether x is the rest positions to the bit (every local molecule's).
  bool at_rest(const double* x) const;
  // Owned molecule i's connection row's inputs (tangent_blocks_unless), ends and inputs resized to its count,
  // which is returned; at_rest: a box lattice's separations from its lattice offsets.
  int row_inputs(const double* x, int i, bool at_rest, std::vector<int>& ends, std::vector<double>& inputs,
                 const std::array<int, 3>* lattice = nullptr) const;
  // The tangent's block-row pattern and CSR storage (src/physics/tangent.hpp), built by create_tangent.
  mutable TangentStorage tangent_;
  // Terms whose tangent has rows of ghosts (Term::tangent_has_ghost_rows): the matrix-free product's and the
  // diagonal's buffer for them (3 * local, zeroed), made on first use.
  bool ghost_rows() const;
  double* ghost_row_buffer() const;
  mutable std::unique_ptr<GhostedVector> ghost_rows_;
};

}  // namespace tissue
