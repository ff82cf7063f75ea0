// A physics term: one part of Eq. 2's total force besides the connection forces (gravity, viscous friction,
// obstacles, molecule-molecule contact, cyclic loads). Each term is one file in src/physics/terms/ holding its
// class and its registration line TISSUE_TERM(id, {...}) (CMake lists those lines in a generated file that
// terms.cpp reads; nothing else is edited); the ForceModel builds only the terms the scene lists, so an absent term allocates
// nothing and costs nothing. Terms run after the connection kernel, one virtual call per term and evaluation
// (never per connection), and loop over the owned molecules themselves. Each adds to a molecule's force in the
// same order on every rank, so results stay independent of the partition.
#pragma once
#include <petscmat.h>

#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "src/model/scene.hpp"
#include "partition/local_model.hpp"

namespace tissue {

// The cells a term holds (the cell term's lattice cells), for the snapshots: this rank's share, each cell on exactly
// one rank, with dense global ids so the writer can put them in id order.
struct CellField {
  int nodes = 0;                      // corners per cell: 8 (hexahedron, XDMF/VTK corner order) or 4 (tetrahedron)
  std::int64_t global_count = 0;      // the cells of all ranks (the same on every rank)
  std::vector<std::int64_t> id;       // this rank's cells: global ids in 0 .. global_count - 1
  std::vector<std::int64_t> corners;  // nodes molecule ids (original) per cell
  std::vector<double> volume_ratio;   // J = det F per cell
  std::vector<double> fibre_stretch;  // |F a| of the cell's stiffest fibre family per cell (0: no fibre)
};

struct TermContext {
  const Scene& scene;
  const LocalModel& model;
};

// What contact terms report (summed over this rank's owned molecules; the ForceModel reduces).
struct ContactTotals {
  Vec3 obstacles{0, 0, 0};         // total force the obstacles exert on the bodies
  std::vector<double> bodies;      // 3 per body: force that molecules of other bodies exert on it
  std::vector<double> bodies_self; // 3 per body: self-contact (non-neighbouring molecules of one body), sums to 0
};

class Term {
public:
  virtual ~Term() = default;
  // Adds the term's forces on the owned molecules to f[0 .. 3 owned). x: local positions (ghosts up to date);
  // v: owned velocities; time: s (dynamic runs). Collective when the term communicates (contact).
  virtual void add_forces(const double* x, const double* v, double time, double* f) = 0;
  // Terms that can add their forces in pieces during the connection kernel's sweep, each piece as soon as the
  // forces on its owned molecules are final (connections and constant loads), while x and f are still in cache:
  // the cell term on box lattices (ForceModel::forces; it asks before every evaluation). Only the first term in
  // the order is fused (so that each molecule still sums connections, loads, then the terms in order), and only
  // one that reads neither v nor the time.
  virtual bool adds_by_rows() const { return false; }
  // Such terms: adds the pieces from `from` on, in add_forces' order, while each piece's owned molecules are all
  // below `below` (local index), and returns the next piece; below = owned adds the rest. The pieces of one
  // evaluation add exactly what one add_forces call adds, in the same order for every molecule (the same bits).
  virtual int add_forces_below(const double* x, int below, int from, double* f) { return from; }
  // The term's potential energy, this rank's owned share (0 for dissipative or time-dependent terms).
  virtual double potential_energy(const double* x) const { return 0.0; }
  // Adds an upper bound of the term's stiffness per owned molecule (N/m, Gershgorin row sum halved) to ksum, for
  // the critical time step.
  virtual void add_stiffness_bound(std::vector<double>& ksum) const {}
  // Adds -dF/dx of the term, owned rows, to J (block size 3, PETSc block ids model.block) through `add`, which
  // drops held components. Terms whose force does not depend on x add nothing.
  using BlockAdd = PetscErrorCode (*)(void* ctx, int row, int col, const double K[9]);
  virtual PetscErrorCode add_tangent(const double* x, BlockAdd add, void* ctx) const { return 0; }
  // Terms whose add_tangent costs far more than the springs' blocks (the cell term: nine dual-number stress
  // evaluations a cell): the matrix-free tangent computes their blocks once per Newton iteration and keeps them
  // (src/solvers/matrix_free.hpp) instead of recomputing them on every matrix-vector product.
  virtual bool tangent_worth_caching() const { return false; }
  // Terms that apply their own tangent in the matrix-free product from a state computed once per Newton iteration
  // and kept by the caller, far smaller than their cached blocks (the cell term: dP/dF per cell, 81 doubles, where
  // its blocks take 27 a molecule): tangent_state_size() doubles, filled by tangent_state at x (local positions,
  // ghosts up to date). apply_tangent_state adds K u to the owned rows of out (u: local, ghosts up to date, held
  // components zero; held rows are the caller's to overwrite); add_tangent_state_diagonal adds K's diagonal. Both
  // give add_tangent's blocks' products and diagonal to round-off.
  virtual bool has_tangent_state() const { return false; }
  virtual std::size_t tangent_state_size() const { return 0; }
  virtual void tangent_state(const double* x, double* state) const {}
  // x: the positions the state was made at (unchanged since), which a state may leave out (the cell term's
  // volumetric-only cells recompute F from it).
  virtual void apply_tangent_state(const double* x, const double* state, const double* u, double* out) const {}
  virtual void add_tangent_state_diagonal(const double* x, const double* state, double* diag) const {}
  // Terms whose product goes in pieces, each adding to owned rows below some row (the cell term's blocks): the
  // matrix-free product runs them from the springs' sweep as its rows become final (ForceModel::apply_tangent's
  // final_rows), while they are in cache. apply_tangent_state_below applies pieces [from, ...) whose rows are all
  // below `below` and returns the next; all of them, from 0, add exactly what apply_tangent_state adds, in the
  // same order for every row (the same bits).
  virtual bool tangent_by_rows() const { return false; }
  virtual int apply_tangent_state_below(const double* x, const double* state, const double* u, int below, int from,
                                        double* out) const {
    return from;
  }
  // Such terms whose product costs no more than the springs' (measured: docs/benchmarks.md): the static solve is
  // then matrix-free by default (the cell term without fibres).
  virtual bool tangent_state_fast() const { return false; }
  // Terms whose tangent blocks join only corners of one lattice cell (one body, neighbours in the 27-point
  // stencil): the lattice multigrid's check of the pattern (LatticeGalerkin::applies) computes none of them.
  virtual bool tangent_within_cells() const { return false; }
  // Terms whose tangent blocks at the rest positions (x the rest array to the bit) are known row by row: rest_row
  // appends owned row i's columns (local, in add_rest_row's order) and a key, such that rows with equal keys and
  // columns at the same lattice offsets have equal blocks to the bit; add_rest_row adds row i's blocks as
  // add_tangent adds them at rest (the same sums in the same order). ForceModel::tangent_blocks_unless shows a row
  // to its consumer before computing it (LatticeGalerkin's skip of rows equal to their class's first).
  virtual bool rest_rows() const { return false; }
  virtual void rest_row(int i, std::vector<int>& columns, std::vector<double>& key) const {}
  virtual PetscErrorCode add_rest_row(int i, BlockAdd add, void* ctx) const { return 0; }
  // Terms whose tangent holds one rank-one volume coupling per lattice cell, k (b . u)^2 with b the cell's one-point
  // divergence on its 8 corners (b = +-g per axis, corner c's signs the bits of c): the cell term's volumetric part
  // at rest. Fills the cells with an owned corner (8 local corners each, corner c = (c & 1, c >> 1 & 1, c >> 2 & 1)),
  // k and g per cell; the lattice multigrid's volume smoother (src/solvers/volume_smoother.hpp) holds them exactly.
  struct VolumeCoupling {
    std::vector<int> corners;  // 8 per cell
    std::vector<double> k;     // per cell: kappa_c V0
    std::vector<double> g;     // 3 per cell: 1 / (4 h) per axis
  };
  virtual bool volume_coupling(VolumeCoupling& out) const { return false; }
  // Contact terms: the force totals of the last evaluation (this rank's owned molecules).
  virtual void add_totals(ContactTotals& t) const {}
  // Terms whose tangent couples molecules no connection joins: the local columns each owned row needs beyond its
  // connections' (extra[i] for owned molecule i), for the tangent's fixed pattern.
  virtual void add_couplings(std::vector<std::vector<int>>& extra) const {}
  // Terms whose tangent has rows of ghosts (add_tangent then passes rows >= owned too, columns local: the
  // tetrahedron term's patches couple molecules two rings apart): the force model adds those rows on their
  // owners (off-process assembly; the matrix-free product and the diagonal send them back to the owners).
  virtual bool tangent_has_ghost_rows() const { return false; }
  // Such terms: (row, column) PETSc block id pairs of those ghost rows, flat, for the owners' fixed pattern.
  virtual void add_remote_couplings(std::vector<std::int64_t>& pairs) const {}
  // A bound on the stable explicit time step the term imposes by itself (s), used instead of the springs'
  // Gershgorin bound when finite (a wave-speed bound: the cell term's h / c_p).
  virtual double critical_time_step() const { return std::numeric_limits<double>::infinity(); }
  // The scale of the term's force round-off per local molecule (N; the floor multiplies it by eps), for the
  // residual's round-off floor: `scale` += the force at unit strain (summed, a worst case), `squares` += the
  // squares of the forces' share from positions, resolved only to eps R / 2 at magnitude R (a corner of a cell
  // with gradients g sees a strain round-off of eps R |g| / 2; these add at random). `x`: 3 * local positions.
  virtual void add_force_scale(const double* x, std::vector<double>& scale, std::vector<double>& squares) const {}
  // Terms that carry fibres (the cell term, docs/anisotropy.md): per owned molecule the mean over its fibre cells
  // of the deformed fibre direction F a / |F a| (3 values, normalized; 0 where no cell has fibres) and of the
  // fibre stretch |F a| (0 there). Returns false when the term has no fibres on any molecule of this rank.
  virtual bool fibre_field(const double* x, double* direction, double* stretch) const { return false; }
  // Terms made of cells: fills `out` with this rank's cells at x (local positions, ghosts up to date).
  virtual void cells(const double* x, CellField& out) const {}

  // Terms with internal variables that follow the time steps (the viscoelastic history of an elastic term: springs
  // now, per-cell terms later). Until the first begin_step such a term adds nothing, so static and relaxation
  // solves find the relaxed equilibrium. begin_step: the next evaluations are a step of dt (s; 0: a step at one
  // instant, the instantaneous response) from the committed state; commit_step: the state at x ends the step.
  virtual bool has_history() const { return false; }
  virtual void begin_step(double dt) {}
  virtual void commit_step(const double* x) {}
  // Checkpoints: the committed internal variables, history_width() values per local connection c (row c of
  // connections() rows). load_history puts saved ones back; the history then acts as after a committed step.
  virtual int history_width() const { return 0; }
  virtual void save_history(double* rows) const {}
  virtual void load_history(const double* rows) {}
  // The same for internal variables per cell (the cell term's history on its stress): cell_history_width() values
  // per cell, cells with dense global ids 0 .. cell_history_count() - 1. A cell may be on several ranks (each
  // evaluates every cell with an owned corner), all holding the same values: save_cell_history gives the cells
  // this rank writes (each cell on exactly one rank) and their rows; cell_history_ids the cells this rank holds,
  // the order of load_cell_history's rows (which then act as after a committed step).
  virtual int cell_history_width() const { return 0; }
  virtual std::int64_t cell_history_count() const { return 0; }
  virtual void save_cell_history(std::vector<std::int64_t>& ids, std::vector<double>& rows) const {}
  virtual std::vector<std::int64_t> cell_history_ids() const { return {}; }
  virtual void load_cell_history(const double* rows) {}
};

using TermFactory = std::unique_ptr<Term> (*)(const TermContext&);

// What a term's contact forces are, for the summary (Measurements::contact_force, body_contact_force).
enum class ContactReport { none, obstacles, molecules };

// A physics term and what it can do: the force model, the guards and the measurements ask these capabilities,
// never the term's name.
struct TermStyle {
  const char* name;
  bool (*listed)(const Scene&);  // does the scene ask for this term?
  TermFactory make;
  const char* description;
  int order;  // terms add their forces in increasing order (a fixed order keeps results bit for bit)
  // The total energy (kinetic + springs + potential - work of the loads) never grows with the term: it is
  // conservative (a potential) or dissipative; the dynamic guard's energy-growth check holds only then.
  bool energy_never_grows = false;
  ContactReport contact = ContactReport::none;
  // The term reads the velocities (viscous friction): a checkpoint of a dynamic run then keeps the half-step
  // velocity its last evaluation read, so that a restart evaluates the same forces.
  bool reads_velocity = false;
  // The term is an energy of each cell's deformation gradient: in bending and near incompressibility a good
  // Newton step can raise the residual norm many-fold, so Newton's line search goes by the energy instead
  // (PETSc's cp: the energy's critical point along the step; docs/benchmarks.md).
  bool energy_line_search = false;
};

// Registers a term, in its own file: TISSUE_TERM(gravity, {"gravity", listed, make, "...", 10, true}).
#define TISSUE_TERM(id, ...)                      \
  const TermStyle& term_style_##id() {            \
    static const TermStyle style __VA_ARGS__;    \
    return style;                                 \
  }

// The registry (terms.cpp), in the order terms add their forces.
const std::vector<TermStyle>& term_styles();

// The penalty stiffness each body's molecules get by default (N/m): the mean over the body's molecules of the
// summed stiffness of their connections, 2 sum_c k_c / N (collective; one value per body).
std::vector<double> body_support_stiffness(const LocalModel& model);

}  // namespace tissue

namespace tissue {
// Adds a face load's share on each owned molecule (traction or equal distribution) to out[0 .. 3 owned).
void add_face_load(const LoadSpec& load, const LocalModel& model, double* out);
}  // namespace tissue
