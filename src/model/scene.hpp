// The scene's vocabulary: what a user asks for (../shared/interface.md, docs/scene.md) as plain data, plus the
// error type of bad input. The bottom layer: every other folder reads these types; io/scene.hpp fills them from a
// TOML file, validated once on reading, so the rest of the program trusts them.
#pragma once
#include <array>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace tissue {

// Bad input: one line naming the file, the key and what is wrong. main() prints what() and exits 2. A line
// break or other control byte in any part (a quoted value, a file name) is written as an escape, so the message
// stays one line whatever the input held.
class InputError : public std::runtime_error {
public:
  InputError(const std::string& file, const std::string& key, const std::string& problem)
      : std::runtime_error(one_line(file + ": " + (key.empty() ? std::string() : key + ": ") + problem)) {}

private:
  static std::string one_line(const std::string& text) {
    static const char hex[] = "0123456789abcdef";
    std::string out;
    out.reserve(text.size());
    for (const char c : text) {
      const auto u = static_cast<unsigned char>(c);
      if (c == '\n') out += "\\n";
      else if (c == '\r') out += "\\r";
      else if (c == '\t') out += "\\t";
      else if (u < 0x20 || u == 0x7f) out += std::string("\\x") + hex[u >> 4] + hex[u & 15];
      else out += c;
    }
    return out;
  }
};

using Vec3 = std::array<double, 3>;

// A factor in time, piecewise linear through (time s, factor) points with increasing times; constant before the
// first and after the last point. Empty: factor 1 at every time.
using TimeHistory = std::vector<std::array<double, 2>>;
double history_factor(const TimeHistory& history, double t);

// A Prony series: E(t) = E (1 + sum_i gamma_i exp(-t / tau_i)), E the relaxed modulus. Empty: elastic.
struct PronySpec {
  std::vector<double> gamma, tau;  // as many of each; gamma >= 0, tau > 0 (s)
  bool empty() const { return gamma.empty(); }
};

// [body.fibres]: one fibre family, transversely isotropic about `direction` (docs/anisotropy.md). The body's (or
// region's) own youngs_modulus and poisson_ratio then mean E_T and nu_TT, across the fibres. Only homogenized on a
// box lattice with diagonals honours it (the per-cell fibre terms of src/physics/terms/cell_elasticity.cpp).
struct FibreSpec {
  Vec3 direction{0.0, 0.0, 1.0};      // unit (normalized by the reader)
  double youngs_modulus = 0.0;        // E_L, Pa
  double poisson_ratio = 0.0;         // nu_LT
  std::optional<double> shear_modulus;  // G_L, Pa; absent: G_T = E_T / (2 (1 + nu_TT)), no fibre-shear term
  bool tension_only = false;          // the fibre and coupling terms switch off while I4 < 1
  // toe = { law = "exp-linear", stretch, exponent }: the fibre's nominal stress against its stretch (Weiss);
  // toe_stretch = 0: no toe (the quadratic fibre term).
  double toe_stretch = 0.0, toe_exponent = 0.0;
};

// A box region of a body with its own material (heterogeneous bodies). Bounds are in metres, in the body's
// own frame (before offset); a molecule belongs to the last region whose closed box holds it.
struct RegionSpec {
  Vec3 lo{}, hi{};
  std::string name;  // shape = "mesh": the physical volume (instead of lo, hi)
  std::string material = "custom";
  double youngs_modulus = 0.0;  // Pa
  double density = 0.0;         // kg/m^3
  // nu: the region's own, else its preset's (homogenized only), else the body's (docs/poisson.md).
  std::optional<double> poisson_ratio;
  // The region's own [body.region.fibres], else the body's (a region inherits the body's fibres as it does nu).
  std::optional<FibreSpec> fibres;
  // [body.region.viscoelastic]: the region's own Prony series (box regions); empty: the body's acts. A connection
  // belongs to the region whose box holds its rest midpoint (the last such region).
  PronySpec viscoelastic;
};

struct BodySpec {
  enum class Shape { box, mesh } shape = Shape::box;  // read from the scene's "box" | "mesh"
  std::array<long, 3> molecules{2, 2, 2};
  Vec3 spacing{1.0, 1.0, 1.0};  // m; from size / (molecules - 1) when the scene gives size
  std::string topology = "face-diagonals";
  std::string material = "custom";
  double youngs_modulus = 0.0;  // Pa (from the preset unless the scene gives it)
  double density = 1000.0;      // kg/m^3
  // nu: given, or the preset's when the body is calibrated by homogenized; absent = 1/4 on lattices (today's
  // springs only, nothing more built). Only homogenized honours it (docs/poisson.md).
  std::optional<double> poisson_ratio;
  bool poisson_ratio_given = false;  // written in the scene (not a preset's): other methods refuse it
  Vec3 offset{0.0, 0.0, 0.0};   // m, where molecule (0,0,0) sits
  std::vector<RegionSpec> regions;
  std::optional<double> radius;  // m, a molecule's contact sphere; absent = half the smallest spacing
  // shape = "mesh": the Gmsh 4.1 file (relative paths from the scene file's directory); topology = "random":
  // the seed of the cloud. Both are explicit topologies (src/model/unstructured.hpp), whose faces are named.
  std::string file;
  long seed = 1;
  long interior_molecules = 0;  // shape = "mesh", topology = "random": points sampled inside the mesh's volume
  double mesh_size = 0.0;       // m; shape = "mesh" from a .geo: the largest element Gmsh makes (0: the .geo's own)
  bool random = false;          // topology = "random" (in the box, or in the mesh's volume), resolved by the reader
  // An explicit topology (a mesh's own tetrahedra, a random cloud), not a box lattice's stencil.
  bool unstructured() const { return shape == Shape::mesh || random; }
  PronySpec viscoelastic;  // [body.viscoelastic]; empty: elastic
  std::optional<FibreSpec> fibres;  // [body.fibres]; absent: isotropic, nothing built for it
  bool has_fibres() const {
    if (fibres) return true;
    for (const auto& r : regions)
      if (r.fibres) return true;
    return false;
  }
};

struct CalibrationSpec {
  std::string method = "linear";
  double divisor = 1.0;                       // C for "divided", start value for "iterative"
  std::map<std::string, double> stiffness;    // N/m per connection class (edge, face, body, tet), "manual"
  double tolerance = 1e-6;                    // iterative: relative error in E at which C is accepted
  long max_updates = 50;                      // iterative: outer updates of C before failing
  std::string key = "calibration";            // the table it was read from, for messages ("body[1].calibration")
  bool honours_poisson = false;               // the method's style honours a Poisson ratio (resolved by the reader)
};

struct FixSpec {
  std::string face;              // x- x+ y- y+ z- z+
  int body = 0;                  // which body's face ([[body]] index)
  // clamped: every component held; roller: the face-normal component (plus the fewest in-plane holds that stop
  // rigid motion). Read from the scene's "clamped" | "roller".
  enum class Mode { clamped, roller } mode = Mode::clamped;
  Vec3 displacement{0.0, 0.0, 0.0};  // m: the held components move by this times the history factor
  TimeHistory history;               // the factor in time (empty: 1)
};

struct LoadSpec {
  std::string face;
  Vec3 force{0.0, 0.0, 0.0};          // N, total over the face
  // traction: each molecule's share is its tributary area on the face; equal: the same share for all.
  enum class Distribution { traction, equal } distribution = Distribution::traction;
  int body = 0;                       // which body's face
  double period = 0.0;                // s; > 0: cyclic, the force scaled by sin(2 pi t / period) (dynamic)
  TimeHistory history;                // the force's factor in time (empty: 1)
};

struct PhysicsSpec {  // absent means off
  std::optional<Vec3> gravity;      // m/s^2
  std::optional<double> viscosity;  // N s/m per molecule
  bool contact = false;             // molecule-molecule contact (other bodies, non-neighbours of one body)
  double contact_stiffness = 0.0;   // N/m penalty; 0 = chosen from the bodies' springs
  double contact_skin = 0.0;        // m, Verlet-list skin; 0 = half the smallest molecule radius
};

struct ObstacleSpec {
  enum class Kind { plane, sphere } kind = Kind::plane;  // read from "plane" | "sphere"
  Vec3 point{}, normal{0, 0, 1};
  Vec3 center{};
  double radius = 0.0;
  double stiffness = 0.0;  // N/m penalty; 0 = chosen from the body
};

struct SolverSpec {
  std::string kind = "static";         // static | relaxation | dynamic
  double tolerance = 1e-10;            // relative force residual (static, relaxation)
  std::optional<double> time_step;     // s (relaxation, dynamic); absent = from the critical time step
  long steps = 1000;                   // dynamic, quasi-static: total step count of the run
  std::optional<double> end_time;      // quasi-static: s, instead of steps
  // quasi-static: each step is this many times the last (>= 1), up to max_time_step; a step that lands on a
  // history breakpoint starts again from time_step (a load's change is the fast part of creep and relaxation).
  double time_step_growth = 1.0;
  std::optional<double> max_time_step;
  long max_iterations = 0;             // relaxation/static cap; 0 = a default that grows with the lattice
  long load_steps = 1;                 // static: load increments
  // static, quasi-static: the Newton tangent as an assembled matrix, or applied from the positions without being
  // stored ("matrix-free": box lattices with the lattice multigrid only; elsewhere the assembled one, with a note)
  std::string tangent_operator = "assembled";
  // A time_step above the critical one (explicit integration unstable) is refused unless this is true; then it
  // is used as given, with a warning (the critical step is a Gershgorin bound: the true limit may be higher).
  bool allow_unstable_time_step = false;
};

struct OutputSpec {
  std::string directory = "out";
  long snapshot_every = 0;    // 0: final state only
  long checkpoint_every = 0;  // 0: none
  // dynamic: a history.csv row every this many steps (and at steps 0 and the last). A row costs about one step
  // (measure and reactions reduced, the row written; docs/benchmarks.md), so by default every 100th.
  long history_every = 100;
  std::vector<std::string> fields{"positions", "displacements", "forces"};  // snapshot datasets
  bool progress = true;       // the progress line on rank 0
};

struct PartitionSpec {
  // automatic ("auto", the default: blocks on one box lattice, metis otherwise) | metis (rank 0 alone) |
  // ptscotch (every rank, PETSc MatPartitioning) | blocks (partition/box_bisection.hpp: one box lattice only)
  enum class Method { automatic, metis, ptscotch, blocks } method = Method::automatic;
};

struct Scene {
  std::string file;  // the path it was read from (for messages)
  std::string text;  // the TOML text after --set overrides (kept in checkpoints)
  std::string title;
  BodySpec body;                 // the first body (== bodies[0]): single-body code reads this
  std::vector<BodySpec> bodies;  // [body] gives one, [[body]] several; molecules numbered body after body
  CalibrationSpec calibration;  // body 0's (== calibrations[0]): single-body code reads this
  // One per body: the body's own [body.calibration] table if it has one, else the top-level [calibration] (a
  // body's own table replaces the top-level one whole, no key is merged). Each body's connections are calibrated
  // by its own method (connections never join two bodies).
  std::vector<CalibrationSpec> calibrations;
  std::vector<FixSpec> fixes;
  std::vector<LoadSpec> loads;
  PhysicsSpec physics;
  std::vector<ObstacleSpec> obstacles;
  SolverSpec solver;
  OutputSpec output;
  PartitionSpec partition;
};

// Faces: "x-" -> axis 0, side 0; "z+" -> axis 2, side 1. Returns false for an unknown name.
bool parse_face(const std::string& face, int& axis, int& side);

}  // namespace tissue
