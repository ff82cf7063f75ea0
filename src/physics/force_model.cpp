#include "src/physics/force_model.hpp"

#include <petsc/private/petscimpl.h>  // PetscObjectStateIncrease: J changes through its SeqAIJ parts

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "partition/exchange.hpp"
#include "src/physics/named_faces.hpp"

namespace tissue {

void add_face_load(const LoadSpec& load, const LocalModel& model, double* out) {
  if (const NamedFace* face = model.shape.named_face(load.body, load.face)) add_named_face_load(load, *face, model, out);
}

ForceModel::ForceModel(const Scene& scene, const LocalModel& model)
    : model_(model), kernel_(model), scene_(scene), load_scale_(scene.loads.size(), 1.0) {
  const Body& s = model.shape;
  held_.assign(3 * model.local, 0);
  std::vector<int> first_fix(3 * model.owned, -1);  // which fix holds an owned component first
  std::vector<const NamedFace*> fixed_face;  // looked up once per fix (the scene check found every one)
  for (const auto& fix : scene.fixes) fixed_face.push_back(s.named_face(fix.body, fix.face));
  for (int i = 0; i < model.local; ++i)
    for (std::size_t f = 0; f < scene.fixes.size(); ++f) {
      if (fixed_face[f] && s.body_of(model.id[i]) == scene.fixes[f].body)
        hold_named(*fixed_face[f], scene.fixes[f], model.id[i], &held_[3 * i]);
      if (i < model.owned)
        for (int d = 0; d < 3; ++d)
          if (held_[3 * i + d] && first_fix[3 * i + d] < 0) first_fix[3 * i + d] = static_cast<int>(f);
    }
  for (int j = 0; j < 3 * model.owned; ++j)
    if (held_[j]) held_owned_.push_back(j), held_fix_.push_back(first_fix[j]);
  for (int j = 3 * model.owned; j < 3 * model.local; ++j)
    if (held_[j]) held_ghosts_.push_back(j);
  for (const auto& fix : scene.fixes) moves_held_ = moves_held_ || fix.displacement != Vec3{0.0, 0.0, 0.0};

  // Constant face loads; cyclic ones (period > 0) are a term of their own. Kept sparse: only loaded faces carry
  // them, and a dense copy would cost 24 bytes a molecule.
  std::vector<double> constant(3 * model.owned, 0.0), cyclic;
  bool any_cyclic = false;
  for (const auto& load : scene.loads) any_cyclic = any_cyclic || load.period > 0;
  if (any_cyclic) cyclic.assign(3 * model.owned, 0.0);
  // Loads with a history keep their own entries (each scaled by its factor); without any, one summed entry per
  // component as before (all factors 1).
  bool any_history = false;
  for (const auto& load : scene.loads) any_history = any_history || !load.history.empty();
  for (std::size_t l = 0; l < scene.loads.size(); ++l) {
    const LoadSpec& load = scene.loads[l];
    if (!any_history || load.period > 0) {
      add_face_load(load, model, (load.period > 0 ? cyclic : constant).data());
      continue;
    }
    std::vector<double> own(3 * model.owned, 0.0);
    add_face_load(load, model, own.data());
    for (int j = 0; j < 3 * model.owned; ++j) {
      constant[j] += own[j];  // for the residual's reference below
      if (own[j] != 0.0) applied_.push_back({j, own[j], static_cast<int>(l)});
    }
  }
  for (const auto& style : term_styles())
    if (style.listed(scene)) terms_.push_back(style.make(TermContext{scene, model})), term_styles_.push_back(&style);

  // The reference of the relative residual: loads (cyclic ones at their amplitude) and gravity.
  const Vec3 g = scene.physics.gravity ? *scene.physics.gravity : Vec3{0, 0, 0};
  double sum = 0;
  for (int i = 0; i < model.owned; ++i)
    for (int d = 0; d < 3; ++d) {
      double fe = constant[3 * i + d] + (any_cyclic ? cyclic[3 * i + d] : 0.0) + model.mass[i] * g[d];
      if (!held_[3 * i + d]) sum += fe * fe;
    }
  if (!any_history)
    for (int j = 0; j < 3 * model.owned; ++j)
      if (constant[j] != 0.0) applied_.push_back({j, constant[j], 0});
  MPI_Allreduce(&sum, &applied_norm_, 1, MPI_DOUBLE, MPI_SUM, model.comm);
  applied_norm_ = std::sqrt(applied_norm_);

  // The first term inside the kernel's sweep (Term::adds_by_rows). The switch is PETSc's options database, read
  // the same on every rank (nothing collective depends on it).
  PetscBool fuse = PETSC_TRUE;
  if (PetscOptionsGetBool(nullptr, nullptr, "-tissue_fuse_terms", &fuse, nullptr))
    throw InputError("PETSc options", "-tissue_fuse_terms", "expects true or false");
  fuse_first_term_ = fuse && !terms_.empty() && terms_[0]->adds_by_rows();
  PetscInt batch = term_batch_;
  PetscBool given = PETSC_FALSE;
  if (PetscOptionsGetInt(nullptr, nullptr, "-tissue_fuse_rows", &batch, &given) || (given && batch < 1))
    throw InputError("PETSc options", "-tissue_fuse_rows", "expects a whole number >= 1");
  term_batch_ = static_cast<int>(batch);
  if (fuse_first_term_) {
    applied_by_row_.resize(applied_.size());
    for (std::size_t q = 0; q < applied_.size(); ++q) applied_by_row_[q] = static_cast<int>(q);
    std::stable_sort(applied_by_row_.begin(), applied_by_row_.end(),
                     [&](int p, int q) { return applied_[p].component < applied_[q].component; });
  }
}

std::vector<std::string> ForceModel::term_names() const {
  std::vector<std::string> names;
  for (const TermStyle* s : term_styles_) names.emplace_back(s->name);  // the style names the term
  return names;
}

bool ForceModel::energy_never_grows() const {
  for (const TermStyle* s : term_styles_)
    if (!s->energy_never_grows) return false;
  return true;
}

bool ForceModel::energy_line_search() const {
  for (const TermStyle* s : term_styles_)
    if (s->energy_line_search) return true;
  return false;
}

bool ForceModel::reads_velocity() const {
  for (const TermStyle* s : term_styles_)
    if (s->reads_velocity) return true;
  return false;
}

ForceModel::Contact ForceModel::contact_totals() const {
  Contact c;
  const int nb = model_.shape.bodies();
  c.totals.bodies.assign(3 * nb, 0.0);
  c.totals.bodies_self.assign(3 * nb, 0.0);
  for (std::size_t i = 0; i < terms_.size(); ++i) {
    c.obstacles = c.obstacles || term_styles_[i]->contact == ContactReport::obstacles;
    c.molecules = c.molecules || term_styles_[i]->contact == ContactReport::molecules;
    terms_[i]->add_totals(c.totals);
  }
  std::vector<double> local(3 + 6 * nb), global(3 + 6 * nb);
  std::copy(c.totals.obstacles.begin(), c.totals.obstacles.end(), local.begin());
  std::copy(c.totals.bodies.begin(), c.totals.bodies.end(), local.begin() + 3);
  std::copy(c.totals.bodies_self.begin(), c.totals.bodies_self.end(), local.begin() + 3 + 3 * nb);
  MPI_Allreduce(local.data(), global.data(), static_cast<int>(local.size()), MPI_DOUBLE, MPI_SUM, model_.comm);
  std::copy(global.begin(), global.begin() + 3, c.totals.obstacles.begin());
  std::copy(global.begin() + 3, global.begin() + 3 + 3 * nb, c.totals.bodies.begin());
  std::copy(global.begin() + 3 + 3 * nb, global.end(), c.totals.bodies_self.begin());
  return c;
}

void ForceModel::connection_forces(const double* x, double* f) const { kernel_.forces(x, f); }

namespace {
// The loads and the first term's pieces on each run of rows the connection kernel hands over as final.
struct RowPass {
  const ForceModel::AppliedForce* applied;
  const int* order;  // applied by component
  int loads, next_load;
  const double* load_scale;
  double load_factor;
  Term* term;
  const double* x;
  double* f;
  int next_piece;
  int term_below;  // the term has added its pieces below this row
  int batch;       // ForceModel::term_batch_
};
void row_pass(void* context, int, int end) {
  RowPass& p = *static_cast<RowPass*>(context);
  for (; p.next_load < p.loads && p.applied[p.order[p.next_load]].component < 3 * end; ++p.next_load) {
    const ForceModel::AppliedForce& a = p.applied[p.order[p.next_load]];
    p.f[a.component] += p.load_factor * p.load_scale[a.load] * a.value;
  }
  if (end - p.term_below < p.batch) return;  // the rest after the kernel (ForceModel::forces)
  p.next_piece = p.term->add_forces_below(p.x, end, p.next_piece, p.f);
  p.term_below = end;
}
}  // namespace

void ForceModel::forces(const double* x, const double* v, double* f, double load_factor) const {
  std::size_t first = 0;  // the terms still to add
  if (fuse_first_term_ && terms_[0]->adds_by_rows()) {
    // The first term's pieces one plane behind the kernel's front, where x and f are in cache (a molecule still
    // gets its connections, then its loads, then the term: the same bits as the passes below).
    RowPass pass{applied_.data(), applied_by_row_.data(), static_cast<int>(applied_by_row_.size()), 0,
                 load_scale_.data(), load_factor, terms_[0].get(), x, f, 0, 0, term_batch_};
    kernel_.forces(x, f, row_pass, &pass);
    terms_[0]->add_forces_below(x, model_.owned, pass.next_piece, f);  // the last batch
    first = 1;
  } else {
    connection_forces(x, f);
    for (const auto& a : applied_) f[a.component] += load_factor * load_scale_[a.load] * a.value;
  }
  for (std::size_t t = first; t < terms_.size(); ++t)
    terms_[t]->add_forces(x, v, time_, f);  // one call per term, none per connection
  held_force_.resize(held_owned_.size());
  for (std::size_t q = 0; q < held_owned_.size(); ++q) held_force_[q] = f[held_owned_[q]], f[held_owned_[q]] = 0.0;
}

double ForceModel::potential_energy(const double* x, double load_factor) const {
  double e = 0;
  model_.for_each_written([&](int c, int a, int b) {  // each connection counted once over all ranks
    const double* xa = x + 3 * a;
    const double* xb = x + 3 * b;
    double d0 = xb[0] - xa[0], d1 = xb[1] - xa[1], d2 = xb[2] - xa[2];
    double stretch = std::sqrt(d0 * d0 + d1 * d1 + d2 * d2) - model_.l0(c);
    e += 0.5 * model_.k(c) * stretch * stretch;
  });
  for (const auto& a : applied_)
    e -= load_factor * load_scale_[a.load] * a.value * (x[a.component] - model_.rest[a.component]);
  for (const auto& t : terms_) e += t->potential_energy(x);
  return e;
}

void ForceModel::set_time(double t) const {
  time_ = t;
  for (std::size_t l = 0; l < load_scale_.size(); ++l) load_scale_[l] = history_factor(scene_.loads[l].history, t);
}

void ForceModel::place_held(double t, double* x) const {
  if (!moves_held_) return;
  std::vector<double> factor(scene_.fixes.size());
  for (std::size_t f = 0; f < factor.size(); ++f) factor[f] = history_factor(scene_.fixes[f].history, t);
  for (std::size_t q = 0; q < held_owned_.size(); ++q) {
    const int j = held_owned_[q], f = held_fix_[q];
    x[j] = model_.rest[j] + factor[f] * scene_.fixes[f].displacement[j % 3];
  }
}

std::vector<Vec3> ForceModel::reactions(const double* x, const double* v, double* f, double load_factor) const {
  connection_forces(x, f);
  for (const auto& a : applied_) f[a.component] += load_factor * load_scale_[a.load] * a.value;
  for (const auto& t : terms_) t->add_forces(x, v, time_, f);
  std::vector<double> local(3 * scene_.fixes.size(), 0.0), global(local.size(), 0.0);
  for (std::size_t q = 0; q < held_owned_.size(); ++q) local[3 * held_fix_[q] + held_owned_[q] % 3] -= f[held_owned_[q]];
  MPI_Allreduce(local.data(), global.data(), static_cast<int>(local.size()), MPI_DOUBLE, MPI_SUM, model_.comm);
  for (int i : held_owned_) f[i] = 0.0;
  std::vector<Vec3> r(scene_.fixes.size());
  for (std::size_t k = 0; k < r.size(); ++k) r[k] = {global[3 * k], global[3 * k + 1], global[3 * k + 2]};
  return r;
}

std::vector<Vec3> ForceModel::last_reactions() const {
  std::vector<double> local(3 * scene_.fixes.size(), 0.0), global(local.size(), 0.0);
  for (std::size_t q = 0; q < held_force_.size(); ++q) local[3 * held_fix_[q] + held_owned_[q] % 3] -= held_force_[q];
  MPI_Allreduce(local.data(), global.data(), static_cast<int>(local.size()), MPI_DOUBLE, MPI_SUM, model_.comm);
  std::vector<Vec3> r(scene_.fixes.size());
  for (std::size_t k = 0; k < r.size(); ++k) r[k] = {global[3 * k], global[3 * k + 1], global[3 * k + 2]};
  return r;
}

Vec3 ForceModel::applied_total(double t) const {
  Vec3 total{0, 0, 0};
  for (const auto& load : scene_.loads) {
    const double factor = load.period > 0 ? std::sin(2.0 * M_PI * t / load.period) : history_factor(load.history, t);
    for (int d = 0; d < 3; ++d) total[d] += factor * load.force[d];
  }
  return total;
}

bool ForceModel::has_history() const {
  for (const auto& t : terms_)
    if (t->has_history()) return true;
  return false;
}

void ForceModel::begin_step(double dt) const {
  for (const auto& t : terms_) t->begin_step(dt);
}

void ForceModel::commit_step(const double* x) const {
  for (const auto& t : terms_) t->commit_step(x);
}

int ForceModel::history_width() const {
  int w = 0;
  for (const auto& t : terms_) w += t->history_width();
  return w;
}

std::vector<double> ForceModel::history() const {
  const int n = model_.connections(), width = history_width();
  std::vector<double> rows(static_cast<std::size_t>(n) * width), part;
  int column = 0;
  for (const auto& t : terms_)
    if (const int w = t->history_width()) {
      part.resize(static_cast<std::size_t>(n) * w);
      t->save_history(part.data());
      for (int c = 0; c < n; ++c)
        std::copy(part.begin() + static_cast<std::size_t>(c) * w, part.begin() + static_cast<std::size_t>(c + 1) * w,
                  rows.begin() + static_cast<std::size_t>(c) * width + column);
      column += w;
    }
  return rows;
}

void ForceModel::set_history(const std::vector<double>& rows) const {
  const int n = model_.connections(), width = history_width();
  std::vector<double> part;
  int column = 0;
  for (const auto& t : terms_)
    if (const int w = t->history_width()) {
      part.resize(static_cast<std::size_t>(n) * w);
      for (int c = 0; c < n; ++c)
        std::copy(rows.begin() + static_cast<std::size_t>(c) * width + column,
                  rows.begin() + static_cast<std::size_t>(c) * width + column + w,
                  part.begin() + static_cast<std::size_t>(c) * w);
      t->load_history(part.data());
      column += w;
    }
}

Term* ForceModel::cell_history() const {
  for (const auto& t : terms_)
    if (t->cell_history_width() > 0) return t.get();
  return nullptr;
}

double ForceModel::largest_stiffness_rate() const {
  std::vector<double> ksum(model_.local, 0.0);
  const ConnectionColumn k = model_.table.stiffness_column();  // the storage asked once, not per connection
  model_.end_a.for_each_pair(model_.end_b, [&](int c, int a, int b) {
    ksum[a] += k[c];
    ksum[b] += k[c];
  });
  for (const auto& t : terms_) t->add_stiffness_bound(ksum);
  double rate = 0;
  for (int i = 0; i < model_.owned; ++i) rate = std::max(rate, 2.0 * ksum[i] / model_.mass[i]);
  double global = 0;
  MPI_Allreduce(&rate, &global, 1, MPI_DOUBLE, MPI_MAX, model_.comm);
  return global;
}

PetscErrorCode ForceModel::create_tangent(Mat* J) const {
  std::vector<std::vector<int>> extra;
  for (const auto& t : terms_) {
    if (extra.empty()) extra.resize(model_.owned);
    t->add_couplings(extra);
  }
  bool any = false;
  for (const auto& e : extra) any = any || !e.empty();
  if (!any) extra.clear();
  if (!ghost_rows()) return tangent_.create(model_, J, extra);
  // Rows of ghosts (couplings two rings deep): each (row, column) pair goes to the row's owner, whose pattern
  // gets the column (its block id: it need not be local there).
  std::vector<std::int64_t> pairs;
  for (const auto& t : terms_) t->add_remote_couplings(pairs);
  std::vector<std::int64_t> firsts(model_.size + 1, 0);
  const std::int64_t mine = model_.first_block;
  MPI_Allgather(&mine, 1, MPI_INT64_T, firsts.data(), 1, MPI_INT64_T, model_.comm);
  firsts[model_.size] = std::numeric_limits<std::int64_t>::max();
  auto owner = [&](std::int64_t block) {
    return static_cast<int>(std::upper_bound(firsts.begin(), firsts.end() - 1, block) - firsts.begin()) - 1;
  };
  std::vector<int> counts(model_.size, 0);
  for (std::size_t q = 0; q < pairs.size(); q += 2) ++counts[owner(pairs[q])];
  std::vector<int> start(model_.size, 0);
  for (int r = 1; r < model_.size; ++r) start[r] = start[r - 1] + counts[r - 1];
  std::vector<std::int64_t> grouped(pairs.size());
  for (std::size_t q = 0; q < pairs.size(); q += 2) {
    const int at = start[owner(pairs[q])]++;
    grouped[2 * at] = pairs[q], grouped[2 * at + 1] = pairs[q + 1];
  }
  const ExchangePlan plan(model_.comm, counts);
  const std::vector<std::int64_t> mine_pairs = plan.forward(grouped, 2);
  std::vector<std::vector<PetscInt>> extra_blocks(model_.owned);
  for (std::size_t q = 0; q < mine_pairs.size(); q += 2)
    extra_blocks[mine_pairs[q] - model_.first_block].push_back(static_cast<PetscInt>(mine_pairs[q + 1]));
  return tangent_.create(model_, J, extra, extra_blocks, model_.size > 1);
}

double ForceModel::terms_critical_time_step() const {
  double dt = std::numeric_limits<double>::infinity();
  if (terms_.empty()) return dt;  // every rank builds the same terms
  for (const auto& t : terms_) dt = std::min(dt, t->critical_time_step());
  double global = dt;
  MPI_Allreduce(&dt, &global, 1, MPI_DOUBLE, MPI_MIN, model_.comm);
  return global;
}

bool ForceModel::fibre_field(const double* x, double* direction, double* stretch) const {
  for (const auto& t : terms_)
    if (t->fibre_field(x, direction, stretch)) return true;
  return false;
}

void ForceModel::add_force_scale(const double* x, std::vector<double>& scale, std::vector<double>& squares) const {
  for (const auto& t : terms_) t->add_force_scale(x, scale, squares);
}

CellField ForceModel::cells(const double* x) const {
  CellField out;
  for (const auto& t : terms_) {
    CellField c;
    t->cells(x, c);
    if (c.global_count == 0) continue;
    if (out.global_count > 0) throw std::logic_error("two terms hold cells: the snapshots write one cell field");
    out = std::move(c);
  }
  return out;
}

PetscErrorCode ForceModel::assemble_tangent(const double* x, Mat J) const {
  PetscFunctionBeginUser;
  const int n = model_.owned;
  PetscCheck(static_cast<int>(tangent_.row_start.size()) == n + 1, model_.comm, PETSC_ERR_ORDER,
             "assemble_tangent needs a matrix from create_tangent");
  // Each block row is computed whole (row-major 3 x 3 ncols, columns in block order) and copied straight into
  // the AIJ arrays (the pattern is fixed by create_tangent): every value is written exactly once, so no zeroing
  // pass and no MatSetValues search.
  Mat Ad, Ao;
  PetscCall(aij_parts(J, &Ad, &Ao));
  const PetscInt *dia, *dja, *oia = nullptr, *oja;
  PetscInt rows;
  PetscBool done;
  PetscCall(MatGetRowIJ(Ad, 0, PETSC_FALSE, PETSC_FALSE, &rows, &dia, &dja, &done));
  if (Ao) PetscCall(MatGetRowIJ(Ao, 0, PETSC_FALSE, PETSC_FALSE, &rows, &oia, &oja, &done));
  PetscScalar *dv, *ov = nullptr;
  PetscCall(MatSeqAIJGetArray(Ad, &dv));
  if (Ao) PetscCall(MatSeqAIJGetArray(Ao, &ov));
  const PetscInt first = model_.first_block, last = model_.first_block + n;
  std::vector<double> vals;
  std::vector<PetscInt> cols;
  for (int i = 0; i < n; ++i) {
    const int begin = tangent_.row_start[i], ncols = tangent_.row_start[i + 1] - begin;
    const int* rc = tangent_.row_cols.data() + begin;
    const int width = 3 * ncols;
    // With couplings two rings deep the row's pattern has columns beyond rc (zero here, the terms add them).
    const bool whole = !tangent_.block_start.empty();
    const PetscInt* pattern = whole ? tangent_.row_blocks.data() + tangent_.block_start[i] : nullptr;
    const int npattern = whole ? tangent_.block_start[i + 1] - tangent_.block_start[i] : ncols;
    vals.assign(3 * width, 0.0);
    cols.resize(ncols);
    for (int q = 0; q < ncols; ++q) cols[q] = model_.block[rc[q]];
    auto slot = [&](int j) {
      return static_cast<int>(std::lower_bound(cols.begin(), cols.end(), model_.block[j]) - cols.begin());
    };
    const int self = slot(i);
    const double* xi = x + 3 * i;
    for (int p = tangent_.conn_start[i]; p < tangent_.conn_start[i + 1]; ++p) {
      const int c = tangent_.row_conns[p];
      const int j = model_.end_a[c] == i ? model_.end_b[c] : model_.end_a[c];
      const double* xj = x + 3 * j;
      double d[3] = {xj[0] - xi[0], xj[1] - xi[1], xj[2] - xi[2]};
      const double len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2], len = std::sqrt(len2);
      const double k = model_.k(c), geo = 1.0 - model_.l0(c) / len;
      const int other = slot(j);
      // K = k [ n n^T + (1 - l0/l)(I - n n^T) ]: the material part along the spring, the geometric part across.
      for (int r = 0; r < 3; ++r)
        for (int s = 0; s < 3; ++s) {
          const double nn = d[r] * d[s] / len2;
          const double K = k * (nn + geo * ((r == s ? 1.0 : 0.0) - nn));
          vals[r * width + 3 * self + s] += K;
          vals[r * width + 3 * other + s] -= K;
        }
    }
    // Held components: their row and column are the identity's (the column's held flag is the neighbour's).
    for (int q = 0; q < ncols; ++q)
      for (int s = 0; s < 3; ++s)
        if (held_[3 * rc[q] + s])
          for (int r = 0; r < 3; ++r) vals[r * width + 3 * q + s] = 0.0;
    for (int r = 0; r < 3; ++r)
      if (held_[3 * i + r]) {
        std::fill(vals.begin() + r * width, vals.begin() + (r + 1) * width, 0.0);
        vals[r * width + 3 * self + r] = 1.0;
      }
    for (int r = 0; r < 3; ++r) {
      double* d = dv + dia[3 * i + r];
      double* o = ov ? ov + oia[3 * i + r] : nullptr;
      const double* v = vals.data() + r * width;
      for (int p = 0, q = 0; p < npattern; ++p) {
        const PetscInt col = whole ? pattern[p] : cols[q];
        double*& to = col >= first && col < last ? d : o;
        if (q < ncols && cols[q] == col) {
          to[0] = v[0], to[1] = v[1], to[2] = v[2];
          v += 3, ++q;
        } else {
          to[0] = to[1] = to[2] = 0.0;
        }
        to += 3;
      }
    }
  }
  // The terms' blocks (obstacles, contact, cells) are added on top, with the same held mask: blocks whose column
  // is owned straight into the diagonal part's arrays (a binary search in the row's sorted columns; a cell
  // term adds 64 blocks per cell, and MatSetValuesBlocked's per-entry path cost 3x the springs' assembly),
  // the others (ghost columns) through MatSetValuesBlocked once the arrays are given back.
  struct OffBlock {
    PetscInt row, col;
    double K[9];
  };
  std::vector<OffBlock> off;
  if (!terms_.empty()) {
    auto put = [&](int row, int col, const double K[9]) -> PetscErrorCode {
      OffBlock b{model_.block[row], model_.block[col], {}};
      for (int r = 0; r < 3; ++r)
        for (int s = 0; s < 3; ++s) b.K[3 * r + s] = held_[3 * row + r] || held_[3 * col + s] ? 0.0 : K[3 * r + s];
      if (row >= n || b.col < first || b.col >= last) {  // a ghost's row or column
        off.push_back(b);
        return 0;
      }
      const PetscInt c0 = 3 * (b.col - first);
      double* at[3];
      for (int r = 0; r < 3; ++r) {
        const PetscInt *begin = dja + dia[3 * row + r], *end = dja + dia[3 * row + r + 1];
        const PetscInt* q = std::lower_bound(begin, end, c0);
        if (end - q < 3 || q[0] != c0 || q[2] != c0 + 2) {  // not in the pattern: MatSetValuesBlocked says so
          off.push_back(b);
          return 0;
        }
        at[r] = dv + (q - dja);  // the block's 3 columns are adjacent
      }
      for (int r = 0; r < 3; ++r) at[r][0] += b.K[3 * r], at[r][1] += b.K[3 * r + 1], at[r][2] += b.K[3 * r + 2];
      return 0;
    };
    using Put = decltype(put);
    auto add = [](void* ctx, int row, int col, const double K[9]) -> PetscErrorCode {
      return (*static_cast<Put*>(ctx))(row, col, K);
    };
    for (const auto& t : terms_) PetscCall(t->add_tangent(x, add, &put));
  }
  PetscCall(MatSeqAIJRestoreArray(Ad, &dv));
  if (Ao) PetscCall(MatSeqAIJRestoreArray(Ao, &ov));
  PetscCall(MatRestoreRowIJ(Ad, 0, PETSC_FALSE, PETSC_FALSE, &rows, &dia, &dja, &done));
  if (Ao) PetscCall(MatRestoreRowIJ(Ao, 0, PETSC_FALSE, PETSC_FALSE, &rows, &oia, &oja, &done));
  PetscCall(PetscObjectStateIncrease(reinterpret_cast<PetscObject>(J)));  // J changed through its parts
  for (const OffBlock& b : off) PetscCall(MatSetValuesBlocked(J, 1, &b.row, 1, &b.col, b.K, ADD_VALUES));
  PetscCall(MatAssemblyBegin(J, MAT_FINAL_ASSEMBLY));
  PetscCall(MatAssemblyEnd(J, MAT_FINAL_ASSEMBLY));
  PetscFunctionReturn(0);
}

}  // namespace tissue

namespace tissue {

// The matrix-free tangent (src/solvers/matrix_free.hpp): a connection's block is k [n n^T + g (I - n n^T)] with
// g = 1 - l0 / l, as assemble_tangent writes it, so K u = k [g u + (1 - g) n (n . u)] needs no block stored;
// a connection's term goes to both of its owned ends, so each is computed once.
namespace {
// Connection c from molecule a to b at positions x: d = x_b - x_a, |d|^2, its stiffness k and g = 1 - l0 / |d|.
struct Stretch {
  Stretch(const LocalModel& m, const double* x, int a, int b, int c) {
    for (int r = 0; r < 3; ++r) d[r] = x[3 * b + r] - x[3 * a + r];
    len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    k = m.k(c), geo = 1.0 - m.l0(c) / std::sqrt(len2);
  }
  double d[3], len2, k, geo;
};
}  // namespace

PetscErrorCode ForceModel::apply_tangent(const double* x, double* in, double* out, bool skip_cached,
                                         SpringKernel::FinalRows final_rows, void* context,
                                         const RestStencil* rest) const {
  PetscFunctionBeginUser;
  const int n = model_.owned, local = model_.local;
  // Held components: their rows are the identity's (out = in), their columns zero (in read as 0).
  // By the lists of held components, not a pass over every component's flag (3 B a molecule each product).
  std::vector<double>& held_in = tangent_held_in_;
  held_in.resize(held_owned_.size());
  for (std::size_t h = 0; h < held_owned_.size(); ++h) held_in[h] = in[held_owned_[h]];
  for (int q : held_owned_) in[q] = 0.0;
  for (int q : held_ghosts_) in[q] = 0.0;
  // Each connection once (one square root), both ends; the ghosts' rows are dropped (their owners compute them).
  // The ghosts' rows go to scratch kept between products (24 B a ghost; a box's ghosts are a few planes).
  tangent_ghost_rows_.resize(3 * static_cast<std::size_t>(local - n));
  if (rest)
    kernel_.rest_tangent(*rest, in, out, tangent_ghost_rows_.data(), skip_cached ? final_rows : nullptr, context);
  else
    kernel_.tangent(x, in, out, tangent_ghost_rows_.data(), skip_cached ? final_rows : nullptr, context);
  if (!terms_.empty()) {
    struct Apply {
      const double* in;
      double* out;
    } apply{in, out};
    auto add = [](void* p, int row, int col, const double K[9]) -> PetscErrorCode {
      const auto& a = *static_cast<const Apply*>(p);
      const double* u = a.in + 3 * col;  // held components zero already
      for (int r = 0; r < 3; ++r) a.out[3 * row + r] += K[3 * r] * u[0] + K[3 * r + 1] * u[1] + K[3 * r + 2] * u[2];
      return 0;
    };
    if (!skip_cached) {
      // Rows of ghosts go to a ghosted buffer whose ghost slots are then added to their owners.
      double* rows = ghost_rows() ? ghost_row_buffer() : out;
      apply.out = rows;
      for (const auto& t : terms_) PetscCall(t->add_tangent(x, add, &apply));
      if (rows != out) {
        ghost_rows_->add_ghosts_to_owners();
        for (int q = 0; q < 3 * n; ++q) out[q] += rows[q];
      }
    }
  }
  for (std::size_t h = 0; h < held_owned_.size(); ++h) out[held_owned_[h]] = held_in[h];
  PetscFunctionReturn(0);
}

PetscErrorCode ForceModel::tangent_diagonal(const double* x, double* diag, bool skip_cached) const {
  PetscFunctionBeginUser;
  const int n = model_.owned;
  std::fill(diag, diag + 3 * n, 0.0);
  // A chunk of connections at a time: their inputs gathered, their diagonal terms computed vectorized
  // (tangent_diagonal_terms: the same operations), then summed in connection order as before, so to the bit.
  constexpr int kChunk = 256;
  alignas(64) double d[3][kChunk] = {}, ks[kChunk] = {}, ls[kChunk] = {}, K[3][kChunk];
  int ea[kChunk], eb[kChunk], filled = 0;
  const ConnectionColumn kc = model_.table.stiffness_column(), lc = model_.table.rest_length_column();
  auto flush = [&] {
    tangent_diagonal_terms(filled, d[0], d[1], d[2], ks, ls, K[0], K[1], K[2]);
    for (int q = 0; q < filled; ++q) {
      const int a = ea[q], b = eb[q];
      for (int r = 0; r < 3; ++r) {
        if (a < n) diag[3 * a + r] += K[r][q];
        if (b < n) diag[3 * b + r] += K[r][q];
      }
    }
    filled = 0;
  };
  model_.end_a.for_each_pair(model_.end_b, [&](int c, int a, int b) {
    ea[filled] = a, eb[filled] = b;
    for (int r = 0; r < 3; ++r) d[r][filled] = x[3 * b + r] - x[3 * a + r];
    ks[filled] = kc[c], ls[filled] = lc[c];
    if (++filled == kChunk) flush();
  });
  flush();
  if (!terms_.empty()) {
    auto add = [](void* p, int row, int col, const double K[9]) -> PetscErrorCode {
      if (row == col)
        for (int r = 0; r < 3; ++r) static_cast<double*>(p)[3 * row + r] += K[4 * r];
      return 0;
    };
    if (!skip_cached) {
      double* rows = ghost_rows() ? ghost_row_buffer() : diag;  // as in apply_tangent
      for (const auto& t : terms_) PetscCall(t->add_tangent(x, add, rows));
      if (rows != diag) {
        ghost_rows_->add_ghosts_to_owners();
        for (int q = 0; q < 3 * n; ++q) diag[q] += rows[q];
      }
    }
  }
  for (int h : held_owned_) diag[h] = 1.0;
  PetscFunctionReturn(0);
}

void ForceModel::release_block_rows() const {
  if (!tangent_.row_start.empty()) return;  // create_tangent's pattern: the assembled tangent's
  // swap, not `= {}`: assigning an empty list keeps the capacity (35 MB a rank at 10^6, held through the solve).
  std::vector<int>().swap(tangent_.conn_start);
  std::vector<int>().swap(tangent_.row_conns);
}

bool ForceModel::has_cached_tangent() const {
  for (const auto& t : terms_)
    if (t->tangent_worth_caching()) return true;
  return false;
}

// Once one term is worth caching, every term's blocks go to the cache: its 27 blocks a molecule are there anyway,
// and the viscoelastic term's (a history trial per connection) cost as much again as the springs' on every product.
PetscErrorCode ForceModel::cached_tangent_blocks(const double* x, Term::BlockAdd add, void* ctx) const {
  PetscFunctionBeginUser;
  if (!has_cached_tangent()) PetscFunctionReturn(0);
  for (const auto& t : terms_) PetscCall(t->add_tangent(x, add, ctx));
  PetscFunctionReturn(0);
}

PetscErrorCode ForceModel::jacobi_gershgorin(const double* x, double* bound, bool* exact) const {
  PetscFunctionBeginUser;
  // Any block from a term makes the bound inexact (see the header); the cached terms' are not even computed.
  struct Count {
    long blocks = 0;
  } count;
  auto tally = [](void* p, int, int, const double*) -> PetscErrorCode {
    static_cast<Count*>(p)->blocks++;
    return 0;
  };
  bool mine_exact = !has_cached_tangent();
  for (const auto& t : terms_)
    if (mine_exact) PetscCall(t->add_tangent(x, tally, &count));
  mine_exact = mine_exact && count.blocks == 0;
  // Row by row as connection_blocks streams them (each connection's block once, the diagonal block last), so no
  // array is needed.
  struct Rows {
    const std::vector<std::uint8_t>& held;
    int row = -1;
    double diag[3] = {}, off[3] = {};
    double bound = 1.0;  // a held row's
    void close() {
      for (int r = 0; r < 3 && row >= 0; ++r)
        if (!held[3 * row + r]) bound = std::max(bound, 1.0 + off[r] / diag[r]);
    }
  } rows{held_};
  auto add = [](void* p, int i, int j, const double K[9]) -> PetscErrorCode {
    auto& s = *static_cast<Rows*>(p);
    if (i != s.row) {
      s.close();
      s.row = i;
      for (int r = 0; r < 3; ++r) s.diag[r] = s.off[r] = 0.0;
    }
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) {
        if (s.held[3 * i + r] || s.held[3 * j + c]) continue;
        if (i == j && r == c)
          s.diag[r] += K[4 * r];
        else
          s.off[r] += std::abs(K[3 * r + c]);
      }
    return 0;
  };
  if (mine_exact) {
    PetscCall(connection_blocks(x, add, &rows));
    rows.close();
  }
  int mine = mine_exact ? 1 : 0, all = 0;
  PetscCallMPI(MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_MIN, model_.comm));
  PetscCallMPI(MPI_Allreduce(&rows.bound, bound, 1, MPI_DOUBLE, MPI_MAX, model_.comm));
  *exact = all == 1;
  PetscFunctionReturn(0);
}

bool ForceModel::ghost_rows() const {
  for (const auto& t : terms_)
    if (t->tangent_has_ghost_rows()) return true;
  return false;
}

double* ForceModel::ghost_row_buffer() const {
  if (!ghost_rows_) ghost_rows_ = std::make_unique<GhostedVector>(model_);
  double* rows = ghost_rows_->array();
  std::fill(rows, rows + 3 * model_.local, 0.0);
  return rows;
}

PetscErrorCode ForceModel::tangent_blocks(const double* x, Term::BlockAdd add, void* ctx) const {
  PetscFunctionBeginUser;
  PetscCheck(!ghost_rows(), model_.comm, PETSC_ERR_SUP, "tangent_blocks: a term's tangent has rows of ghosts");
  const int n = model_.owned;
  if (static_cast<int>(tangent_.conn_start.size()) != n + 1) tangent_.create_rows(model_);
  // A molecule's connection row just before the terms' first run of its row, so that a consumer summing a row
  // at a time (LatticeGalerkin's stream) takes the springs' and the cells' blocks as one run, one scatter a row.
  // At the rest positions the springs' rows from the lattice offsets (row_inputs), as tangent_blocks_unless's:
  // then a box lattice's interior rows are equal to the bit (the cell term's are at rest: F = I exactly), and
  // LatticeGalerkin sums one row of each class instead of every row.
  struct Merge {
    const ForceModel& forces;
    const double* x;
    Term::BlockAdd add;
    void* ctx;
    std::vector<std::uint8_t> done;
    int row = -1;
    bool at_rest;
    std::vector<int> ends;
    std::vector<double> inputs;
    PetscErrorCode connections(int i) {
      if (!at_rest) return forces.connection_row(x, i, add, ctx);
      const int count = forces.row_inputs(x, i, true, ends, inputs);
      return forces.connection_row_of(i, ends.data(), inputs.data(), count, add, ctx);
    }
  } merge{*this, x, add, ctx, std::vector<std::uint8_t>(n, 0), -1, at_rest(x), {}, {}};
  auto merged = [](void* p, int i, int j, const double K[9]) -> PetscErrorCode {
    auto& m = *static_cast<Merge*>(p);
    if (i != m.row && i < static_cast<int>(m.done.size()) && !m.done[i]) {
      PetscCall(m.connections(i));
      m.done[i] = 1;
    }
    m.row = i;
    return m.add(m.ctx, i, j, K);
  };
  for (const auto& t : terms_) PetscCall(t->add_tangent(x, merged, &merge));
  for (int i = 0; i < n; ++i)
    if (!merge.done[i]) PetscCall(merge.connections(i));
  PetscFunctionReturn(0);
}

PetscErrorCode ForceModel::connection_blocks(const double* x, Term::BlockAdd add, void* ctx) const {
  PetscFunctionBeginUser;
  const int n = model_.owned;
  if (static_cast<int>(tangent_.conn_start.size()) != n + 1) tangent_.create_rows(model_);
  for (int i = 0; i < n; ++i) PetscCall(connection_row(x, i, add, ctx));
  PetscFunctionReturn(0);
}

bool ForceModel::at_rest(const double* x) const {
  return std::equal(x, x + 3 * static_cast<std::size_t>(model_.local), model_.rest.begin());
}

int ForceModel::row_inputs(const double* x, int i, bool at_rest, std::vector<int>& ends,
                           std::vector<double>& inputs, const std::array<int, 3>* lattice) const {
  const int first = tangent_.conn_start[i], count = tangent_.conn_start[i + 1] - first;
  ends.resize(count), inputs.resize(5 * static_cast<std::size_t>(count));
  // At the rest positions, a box lattice's separations from its lattice offsets, ((i' - i) h_x, ...): the doubles
  // each rest length was made from (BoxGeometry::rest_distance), the same for every connection of an offset. The
  // positions' differences vary in the last bits from place to place wherever h is not a power of two, and then
  // no row of a class had its first row's inputs (LatticeGalerkin's skip); the blocks differ at round-off.
  const BoxGeometry& box = model_.shape.part(model_.id[i]);
  const bool on_lattice = at_rest && !box.unstructured();
  // The indices from `lattice` where given (three 64-bit divisions an end otherwise): the same offsets.
  auto index = [&](int m) {
    if (!lattice) return box.index(model_.id[m]);
    return std::array<long, 3>{lattice[m][0], lattice[m][1], lattice[m][2]};
  };
  const auto ii = on_lattice ? index(i) : std::array<long, 3>{};
  // What Stretch and connection_row read, in their order.
  for (int q = 0; q < count; ++q) {
    const int c = tangent_.row_conns[first + q];
    const int j = model_.end_a[c] == i ? model_.end_b[c] : model_.end_a[c];
    double* in = inputs.data() + 5 * q;
    if (on_lattice && model_.body[i] == model_.body[j]) {
      const auto ij = index(j);
      for (int r = 0; r < 3; ++r) in[r] = static_cast<double>(ij[r] - ii[r]) * box.h[r];
    } else {
      for (int r = 0; r < 3; ++r) in[r] = x[3 * j + r] - x[3 * i + r];
    }
    in[3] = model_.k(c), in[4] = model_.l0(c);
    ends[q] = j;
  }
  return count;
}

PetscErrorCode ForceModel::tangent_blocks_unless(const double* x, Term::BlockAdd add, void* ctx, RowKnown known,
                                                 void* known_ctx, const std::array<int, 3>* lattice) const {
  PetscFunctionBeginUser;
  const int n = model_.owned;
  if (static_cast<int>(tangent_.conn_start.size()) != n + 1) tangent_.create_rows(model_);
  const bool rest = at_rest(x);
  bool rows = terms_.empty() || rest;
  for (const auto& t : terms_) rows = rows && t->rest_rows();
  if (!rows) PetscFunctionReturn(tangent_blocks(x, add, ctx));
  // A row's ends and inputs: its connections' (5 doubles each), then each term's columns and key.
  std::vector<int> ends, columns;
  std::vector<double> inputs, key;
  for (int i = 0; i < n; ++i) {
    const int count = row_inputs(x, i, rest, ends, inputs, lattice);
    if (!terms_.empty()) {
      columns.clear(), key.clear();
      for (const auto& t : terms_) t->rest_row(i, columns, key);
      ends.insert(ends.end(), columns.begin(), columns.end());
      inputs.insert(inputs.end(), key.begin(), key.end());
    }
    if (known(known_ctx, i, ends.data(), static_cast<int>(ends.size()), inputs.data(),
              static_cast<int>(inputs.size())))
      continue;
    PetscCall(connection_row_of(i, ends.data(), inputs.data(), count, add, ctx));
    for (const auto& t : terms_) PetscCall(t->add_rest_row(i, add, ctx));
  }
  PetscFunctionReturn(0);
}

// -K of a spring's tangent block, K = k (n n^T + geo (I - n n^T)) with n n^T = d d^T / |d|^2: symmetric to the bit
// (d[r] d[s] = d[s] d[r] exactly), so its upper triangle only, 6 divisions.
static inline void minus_spring_block(const double* d, double len2, double k, double geo, double minus[9]) {
  for (int r = 0; r < 3; ++r)
    for (int s = r; s < 3; ++s) {
      const double nn = d[r] * d[s] / len2;
      const double K = k * (nn + geo * ((r == s ? 1.0 : 0.0) - nn));
      minus[3 * r + s] = minus[3 * s + r] = -K;
    }
}

// connection_row's arithmetic from the row's inputs (Stretch's d, k, l0; tangent_blocks_unless).
PetscErrorCode ForceModel::connection_row_of(int i, const int* ends, const double* inputs, int count, Term::BlockAdd add,
                                             void* ctx) const {
  PetscFunctionBeginUser;
  double self[9] = {};
  for (int q = 0; q < count; ++q) {
    const double* d = inputs + 5 * q;
    const double len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2], k = d[3], geo = 1.0 - d[4] / std::sqrt(len2);
    double minus[9];
    minus_spring_block(d, len2, k, geo, minus);
    for (int e = 0; e < 9; ++e) self[e] -= minus[e];
    PetscCall(add(ctx, i, ends[q], minus));
  }
  PetscCall(add(ctx, i, i, self));
  PetscFunctionReturn(0);
}

PetscErrorCode ForceModel::connection_row(const double* x, int i, Term::BlockAdd add, void* ctx) const {
  PetscFunctionBeginUser;
  double self[9] = {};
  for (int p = tangent_.conn_start[i]; p < tangent_.conn_start[i + 1]; ++p) {
    const int c = tangent_.row_conns[p];
    const int j = model_.end_a[c] == i ? model_.end_b[c] : model_.end_a[c];
    const Stretch st(model_, x, i, j, c);
    const double* d = st.d;
    const double len2 = st.len2, k = st.k, geo = st.geo;
    double minus[9];
    minus_spring_block(d, len2, k, geo, minus);
    for (int e = 0; e < 9; ++e) self[e] -= minus[e];  // += K, exactly
    PetscCall(add(ctx, i, j, minus));
  }
  PetscCall(add(ctx, i, i, self));
  PetscFunctionReturn(0);
}

}  // namespace tissue
