// Reading a scene: TOML text (io/toml_text.hpp) -> --set overrides (io/scene_overrides.hpp) -> the schema, read
// through Section (io/scene_section.hpp) -> Scene. Every problem becomes one InputError naming the file and the
// dotted key; nothing past this file re-checks the scene. This file is the schema.
#include "io/scene.hpp"

#include <limits>
#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "io/scene_overrides.hpp"
#include "io/scene_section.hpp"
#include "io/toml_text.hpp"
#include "src/calibration/calibration.hpp"
#include "src/model/body.hpp"
#include "src/model/cell_law.hpp"
#include "src/model/material.hpp"
#include "src/model/topology.hpp"
#include "src/solvers/solver.hpp"

namespace tissue {

namespace {

using scene_reader::apply_override;
using scene_reader::join;
using scene_reader::max_scene_bytes;
using scene_reader::parse_toml;
using scene_reader::Section;
using scene_reader::Table;
using scene_reader::Value;

const std::vector<std::string> face_names = {"x-", "x+", "y-", "y+", "z-", "z+"};
const std::vector<std::string> field_names = {"positions", "displacements",     "velocities",
                                              "forces",    "connection_strain", "connection_force"};

std::vector<std::string> material_names() {
  std::vector<std::string> names{"custom"};
  for (const auto& p : tissue_presets()) names.push_back(p.name);
  return names;
}

// material / youngs_modulus / density, for the body and for each region: a preset gives defaults for both,
// "custom" needs the modulus.
void read_material(const Section& s, std::string& material, double& E, double& density,
                   std::optional<double>* poisson_ratio = nullptr) {
  material = s.choice("material", material_names()).value_or("custom");
  const TissuePreset* preset = material == "custom" ? nullptr : find_tissue(material);
  auto e = s.number("youngs_modulus");
  if (!e && !preset) s.fail("youngs_modulus", "missing (required with material = \"custom\")");
  E = e ? *e : preset->youngs_modulus;
  s.positive("youngs_modulus", E);
  density = s.number("density").value_or(preset ? preset->density : 1000.0);
  s.positive("density", density);
  if (!poisson_ratio) return;
  // The given nu only; a preset's is applied once the calibration method is known (apply_preset_poisson).
  *poisson_ratio = s.number("poisson_ratio");
  // The isotropic target needs K > 0 and mu > 0; the stable range of the lattice is documented in
  // docs/poisson.md ("Range").
  if (*poisson_ratio && !(**poisson_ratio > -1.0 && **poisson_ratio <= 0.499))
    s.fail("poisson_ratio", fmt::format("must be in (-1, 0.499], got {}", **poisson_ratio));
}

// The Poisson ratio a body and its regions get, once the body's calibration method is known: the scene's, else
// the preset's when homogenized honours it; an explicit nu with another method is refused (naming
// calibration.method), a preset's is ignored with a note (src/calibration/calibration.cpp prints it).
void apply_poisson(const Section& body_table, BodySpec& b, const CalibrationSpec& c) {
  const bool homogenized = c.honours_poisson;  // homogenized
  bool given = b.poisson_ratio.has_value();
  for (const auto& r : b.regions) given = given || r.poisson_ratio.has_value();
  b.poisson_ratio_given = given;
  if (given && !homogenized)
    throw InputError(body_table.file(), c.key + ".method",
                     fmt::format("{} cannot honour a poisson_ratio (nu = 1/4 is built in: central springs); use "
                                 "method = \"homogenized\" or remove poisson_ratio", c.method));
  if (!homogenized) return;
  const TopologyStyle* lattice = b.unstructured() ? nullptr : find_topology(b.topology);
  // Meshes and clouds: the per-tetrahedron term carries E, nu and fibres (body_has_tetrahedra), per mesh region
  // (each tetrahedron the material of its physical volume).
  const bool carries = b.unstructured() || (lattice && lattice->carries_poisson());
  if (b.unstructured() && b.random && !b.regions.empty())
    body_table.fail("region", "homogenized on molecules sampled in a mesh takes the body's own material; regions are "
                              "not supported with it yet (docs/poisson.md)");
  if (b.unstructured() && !b.viscoelastic.empty())
    body_table.fail("viscoelastic", "homogenized on a mesh or random cloud is elastic only (docs/poisson.md)");
  if (given && !carries) {
    std::vector<std::string> names;
    for (const auto& t : topology_styles())
      if (t.carries_poisson()) names.push_back(fmt::format("\"{}\"", t.name));
    body_table.fail("poisson_ratio", fmt::format("needs topology {} (the body has \"{}\")", join(names, " or "),
                                                 b.topology));
  }
  auto preset_nu = [](const std::string& material) -> std::optional<double> {
    const TissuePreset* p = material == "custom" ? nullptr : find_tissue(material);
    return p ? std::optional<double>(p->poisson_ratio) : std::nullopt;
  };
  if (!b.poisson_ratio) b.poisson_ratio = preset_nu(b.material);
  for (auto& r : b.regions) {
    if (!r.poisson_ratio) r.poisson_ratio = preset_nu(r.material);
    if (!r.poisson_ratio) r.poisson_ratio = b.poisson_ratio;
  }
  // A body of one nu = 1/4 everywhere builds nothing new: keep it absent.
  bool all_quarter = !b.poisson_ratio || *b.poisson_ratio == 0.25;
  for (const auto& r : b.regions) all_quarter = all_quarter && (!r.poisson_ratio || *r.poisson_ratio == 0.25);
  if (all_quarter && !given) {
    b.poisson_ratio.reset();
    for (auto& r : b.regions) r.poisson_ratio.reset();
  }
  if (b.poisson_ratio || !b.regions.empty()) {
    if (!carries) {
      b.poisson_ratio.reset();  // a preset's nu on a topology that cannot carry it: 1/4 as before
      for (auto& r : b.regions) r.poisson_ratio.reset();
    }
  }
}

// [body.fibres] (and [body.region.fibres]): one fibre family (docs/anisotropy.md). The five constants are checked
// once the body's nu_TT is known (apply_fibres).
// A tissue preset with fibre values (ligament, tendon) gives E_L, nu_LT and G_L unless the table does.
FibreSpec read_fibres(const Section& s, const std::string& material) {
  s.allow({"direction", "youngs_modulus", "poisson_ratio", "shear_modulus", "tension_only", "toe"});
  const TissuePreset* p = material == "custom" ? nullptr : find_tissue(material);
  if (p && !(p->transverse_modulus > 0)) p = nullptr;
  s.require("direction", "the fibre direction, 3 numbers (normalized by the reader)");
  if (!p) s.require("youngs_modulus", "E_L, the modulus along the fibres (Pa)");
  if (!p) s.require("poisson_ratio", "nu_LT, the contraction across the fibres under tension along them");
  FibreSpec f;
  const Vec3 d = *s.vec3("direction");
  const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  if (!(n > 0) || !std::isfinite(n)) s.fail("direction", "must be a non-zero vector");
  for (int a = 0; a < 3; ++a) f.direction[a] = d[a] / n;
  f.youngs_modulus = p ? s.number("youngs_modulus").value_or(p->youngs_modulus) : *s.number("youngs_modulus");
  s.positive("youngs_modulus", f.youngs_modulus);
  f.poisson_ratio = p ? s.number("poisson_ratio").value_or(p->fibre_poisson_ratio) : *s.number("poisson_ratio");
  f.shear_modulus = s.number("shear_modulus");
  if (!f.shear_modulus && p) f.shear_modulus = p->fibre_shear_modulus;
  if (f.shear_modulus) s.positive("shear_modulus", *f.shear_modulus);
  f.tension_only = s.boolean("tension_only").value_or(false);
  if (s.has("toe")) {
    const Section t = s.table("toe");
    t.allow({"law", "stretch", "exponent"});
    t.require("law", "the toe law: \"exp-linear\"");
    t.choice("law", {"exp-linear"});
    t.require("stretch", "the fibre stretch where the toe ends and the linear part starts (> 1)");
    t.require("exponent", "the exponential's rate c4 (> 0)");
    f.toe_stretch = *t.number("stretch");
    if (!(f.toe_stretch > 1.0)) t.fail("stretch", fmt::format("must be > 1, got {}", f.toe_stretch));
    f.toe_exponent = *t.number("exponent");
    t.positive("exponent", f.toe_exponent);
    if (f.toe_exponent * (f.toe_stretch - 1.0) > 700.0)
      t.fail("exponent", fmt::format("exponent x (stretch - 1) = {} overflows the exponential (at most 700)",
                                     f.toe_exponent * (f.toe_stretch - 1.0)));
  }
  return f;
}

// [fibres] of a body or region: with a fibre preset its youngs_modulus, unless given, is the preset's E_T.
void read_fibre_material(const Section& s, const std::string& material, double& E, std::optional<FibreSpec>& fibres) {
  fibres = read_fibres(s.table("fibres"), material);
  const TissuePreset* p = material == "custom" ? nullptr : find_tissue(material);
  if (p && p->transverse_modulus > 0 && !s.has("youngs_modulus")) E = p->transverse_modulus;
}

// Fibres: only homogenized on a box lattice with diagonals honours them; the five constants must be a positive
// definite transversely isotropic material whose matrix the lattice can carry (cell_law.hpp).
void apply_fibres(const Section& body_table, const BodySpec& b, const CalibrationSpec& c) {
  if (!b.has_fibres()) return;
  if (c.method != "homogenized")
    throw InputError(body_table.file(), c.key + ".method",
                     fmt::format("{} cannot honour fibres (central springs are isotropic); use method = "
                                 "\"homogenized\" or remove [body.fibres]", c.method));
  if (!b.unstructured() && b.topology != "face-diagonals" && b.topology != "body-diagonals")
    body_table.fail("fibres", fmt::format("needs topology \"face-diagonals\" or \"body-diagonals\" (the body has "
                                          "\"{}\")", b.topology));
  auto check = [](const Section& where, double E, const std::optional<double>& nu, const FibreSpec& f) {
    const TransverseIsotropy t = transverse_isotropy(E, nu.value_or(std::nan("")), f);
    const std::string problem = ti_problem(t);
    if (!problem.empty()) where.fail("fibres", problem);
    const FibreModuli m = fibre_moduli(t);
    if ((f.tension_only || f.toe_stretch > 0) && !(m.E_f > 0))
      where.fail("fibres", fmt::format("tension_only and toe need fibres stiffer than the matrix (fibre modulus E_f "
                                       "= {} Pa <= 0)", m.E_f));
  };
  const std::vector<Section> regions = body_table.tables("region");
  if (b.fibres) {
    // The body's own material, and every region that inherits the body's fibres.
    check(body_table, b.youngs_modulus, b.poisson_ratio, *b.fibres);
  }
  for (std::size_t i = 0; i < b.regions.size() && i < regions.size(); ++i) {
    const RegionSpec& r = b.regions[i];
    if (r.fibres) check(regions[i], r.youngs_modulus, r.poisson_ratio, *r.fibres);
    else if (b.fibres) check(regions[i], r.youngs_modulus, r.poisson_ratio, *b.fibres);
  }
}

// history = [[t0, f0], [t1, f1], ...]: (time s, factor) pairs, times increasing.
TimeHistory read_history(const Section& s) {
  TimeHistory h;
  if (!s.has("history")) return h;
  const Value& v = s.get("history");
  const char* want = "expected an array of [time, factor] pairs, times increasing";
  if (!v.is_array() || v.as_array().empty()) s.fail("history", want);
  for (const Value& p : v.as_array()) {
    if (!p.is_array() || p.as_array().size() != 2) s.fail("history", want);
    std::array<double, 2> point{};
    for (int j = 0; j < 2; ++j) {
      const Value& x = p.as_array()[j];
      if (x.is_integer()) point[j] = static_cast<double>(x.as_integer());
      else if (x.is_floating()) point[j] = x.as_floating();
      else s.fail("history", want);
      if (!std::isfinite(point[j])) s.fail("history", "every time and factor must be finite");
    }
    if (!h.empty() && !(point[0] > h.back()[0]))
      s.fail("history", fmt::format("times must increase, got {} after {}", point[0], h.back()[0]));
    if (point[0] < 0) s.fail("history", fmt::format("times start at 0 or later, got {}", point[0]));
    h.push_back(point);
  }
  return h;
}

// A list of numbers (gamma = [...], tau = [...]).
std::vector<double> read_numbers(const Section& s, const std::string& k) {
  const Value& v = s.get(k);
  if (!v.is_array() || v.as_array().empty()) s.fail(k, "expected a non-empty array of numbers");
  std::vector<double> out;
  for (const Value& x : v.as_array()) {
    if (x.is_integer()) out.push_back(static_cast<double>(x.as_integer()));
    else if (x.is_floating() && std::isfinite(x.as_floating())) out.push_back(x.as_floating());
    else s.fail(k, "expected a non-empty array of finite numbers");
  }
  return out;
}

// [body.viscoelastic]: a Prony series, gamma_i >= 0 and tau_i > 0, as many of each.
PronySpec read_viscoelastic(const Section& s) {
  s.allow({"gamma", "tau"});
  s.require("gamma", "the Prony weights, E(t) = E (1 + sum gamma_i exp(-t / tau_i))");
  s.require("tau", "the Prony time constants (s)");
  PronySpec p{read_numbers(s, "gamma"), read_numbers(s, "tau")};
  if (p.gamma.size() != p.tau.size())
    s.fail("tau", fmt::format("{} time constants for {} weights (gamma)", p.tau.size(), p.gamma.size()));
  for (double g : p.gamma) s.non_negative("gamma", g);
  // (the instantaneous modulus E (1 + sum gamma) must stay a number: 1e300 overflowed into a misleading failure)
  double sum = 0;
  for (double g : p.gamma) sum += g;
  if (sum > 1e6)
    s.fail("gamma", fmt::format("sums to {:g}: the instantaneous modulus would be more than 1e6 times the relaxed "
                                "one (no tissue is)", sum));
  for (double t : p.tau) s.positive("tau", t);
  return p;
}

// shape = "mesh": a Gmsh file, its physical volumes as regions (by name). The file is read with the body.
BodySpec read_mesh_body(const Section& s, BodySpec b) {
  s.allow({"shape", "file", "topology", "material", "youngs_modulus", "density", "offset", "region", "radius",
           "calibration", "seed", "interior_molecules", "mesh_size", "viscoelastic", "poisson_ratio", "fibres"});
  s.require("file", "the Gmsh mesh (.msh) or geometry (.geo) of the body");
  b.file = *s.string("file");
  if (b.file.empty()) s.fail("file", "empty path");
  namespace fs = std::filesystem;
  if (fs::path(b.file).is_relative()) b.file = (fs::path(s.file()).parent_path() / b.file).lexically_normal().string();
  std::error_code ec;
  if (!fs::is_regular_file(b.file, ec))
    s.fail("file", fmt::format("cannot open \"{}\": {}", b.file,
                               !fs::exists(b.file, ec) ? "no such file"
                               : fs::is_directory(b.file, ec) ? "a directory, not a mesh file"
                                                              : "not a regular file"));
  // A .geo is meshed at run time (io/gmsh_mesh.hpp); mesh_size (m) caps its elements' size, over the .geo's own.
  if (s.has("mesh_size") && fs::path(b.file).extension() != ".geo")
    s.fail("mesh_size", "only a .geo geometry is meshed at run time; a mesh file is used as it is");
  b.mesh_size = s.number("mesh_size").value_or(0.0);
  if (s.has("mesh_size")) s.positive("mesh_size", b.mesh_size);
  // topology = "random": the mesh's boundary nodes and interior_molecules points at random inside it, Delaunay
  // (src/model/mesh_cloud.hpp); "mesh": the mesh's own tetrahedra.
  b.topology = s.choice("topology", {"mesh", "random"}).value_or("mesh");
  b.random = b.topology == "random";
  if (s.has("viscoelastic")) b.viscoelastic = read_viscoelastic(s.table("viscoelastic"));
  for (const char* k : {"seed", "interior_molecules"})
    if (s.has(k) && !b.random) s.fail(k, "only topology = \"random\" has it");
  b.seed = s.integer("seed").value_or(b.seed);
  if (b.random) {
    s.require("interior_molecules", "the number of molecules to sample inside the mesh's volume");
    b.interior_molecules = *s.integer("interior_molecules");
    s.at_least("interior_molecules", b.interior_molecules, 1);
    if (b.interior_molecules > 2000000000L)
      s.fail("interior_molecules", fmt::format("{} molecules, more than the 2e9 supported", b.interior_molecules));
  }
  // poisson_ratio and [body.fibres]: homogenized only (the per-tetrahedron term, docs/poisson.md).
  read_material(s, b.material, b.youngs_modulus, b.density, &b.poisson_ratio);
  if (s.has("fibres")) read_fibre_material(s, b.material, b.youngs_modulus, b.fibres);
  b.offset = s.vec3("offset").value_or(b.offset);
  b.radius = s.number("radius");
  if (b.radius) s.positive("radius", *b.radius);
  for (const auto& r : s.tables("region")) {
    r.allow({"name", "material", "youngs_modulus", "density", "poisson_ratio", "fibres"});
    RegionSpec spec;
    r.require("name", "the physical volume of the mesh (a mesh's regions are named, not boxes)");
    spec.name = *r.string("name");
    read_material(r, spec.material, spec.youngs_modulus, spec.density, &spec.poisson_ratio);
    if (r.has("fibres")) read_fibre_material(r, spec.material, spec.youngs_modulus, spec.fibres);
    b.regions.push_back(spec);
  }
  return b;
}

BodySpec read_body(const Section& s) {
  BodySpec b;
  const std::string shape = s.string("shape").value_or("box");
  if (shape != "box" && shape != "mesh") s.fail("shape", fmt::format("unknown value \"{}\" (one of: box, mesh)", shape));
  b.shape = shape == "mesh" ? BodySpec::Shape::mesh : BodySpec::Shape::box;
  if (b.shape == BodySpec::Shape::mesh) return read_mesh_body(s, b);
  s.allow({"shape", "molecules", "spacing", "size", "topology", "material", "youngs_modulus", "density", "offset",
           "region", "radius", "calibration", "seed", "poisson_ratio", "viscoelastic",
           "fibres"});  // calibration: read by build_scene

  s.require("molecules", "3 integers, molecules along x, y, z");
  b.molecules = *s.int3("molecules");
  double total = 1;
  for (long n : b.molecules) {
    if (n < 2)
      s.fail("molecules", fmt::format("every count must be >= 2, got [{}, {}, {}]", b.molecules[0], b.molecules[1],
                                      b.molecules[2]));
    total *= static_cast<double>(n);
  }
  if (total > 2e9) s.fail("molecules", fmt::format("{:.0f} molecules, more than the 2e9 supported", total));

  if (s.has("spacing") && s.has("size")) s.fail("size", "give spacing or size, not both");
  if (s.has("spacing")) {
    b.spacing = *s.vec3("spacing");
    s.positive3("spacing", b.spacing);
  } else if (s.has("size")) {
    Vec3 size = *s.vec3("size");
    s.positive3("size", size);
    for (int a = 0; a < 3; ++a) b.spacing[a] = size[a] / static_cast<double>(b.molecules[a] - 1);
  } else {
    s.fail("spacing", "missing (give spacing = [hx, hy, hz] or size = [Lx, Ly, Lz])");
  }

  std::vector<std::string> topologies = topology_names();
  topologies.push_back("random");  // explicit: src/model/random_cloud.hpp
  b.topology = s.choice("topology", topologies).value_or(b.topology);
  b.random = b.topology == "random";
  if (s.has("viscoelastic")) b.viscoelastic = read_viscoelastic(s.table("viscoelastic"));
  if (s.has("seed") && !b.random) s.fail("seed", "only topology = \"random\" has a seed");
  b.seed = s.integer("seed").value_or(b.seed);
  if (b.random && !s.tables("region").empty())
    s.fail("region", "a random box has no regions yet (give the body one material)");
  read_material(s, b.material, b.youngs_modulus, b.density, &b.poisson_ratio);
  if (s.has("fibres")) read_fibre_material(s, b.material, b.youngs_modulus, b.fibres);
  b.offset = s.vec3("offset").value_or(b.offset);
  b.radius = s.number("radius");
  if (b.radius) s.positive("radius", *b.radius);

  for (const auto& r : s.tables("region")) {
    r.allow({"lo", "hi", "material", "youngs_modulus", "density", "poisson_ratio", "fibres", "viscoelastic"});
    RegionSpec spec;
    r.require("lo");
    r.require("hi");
    spec.lo = *r.vec3("lo");
    spec.hi = *r.vec3("hi");
    for (int a = 0; a < 3; ++a)
      if (spec.lo[a] > spec.hi[a])
        r.fail("hi", fmt::format("hi[{}] = {} is below lo[{}] = {}", a, spec.hi[a], a, spec.lo[a]));
    read_material(r, spec.material, spec.youngs_modulus, spec.density, &spec.poisson_ratio);
    if (r.has("fibres")) read_fibre_material(r, spec.material, spec.youngs_modulus, spec.fibres);
    if (r.has("viscoelastic")) spec.viscoelastic = read_viscoelastic(r.table("viscoelastic"));
    b.regions.push_back(spec);
  }
  return b;
}

// The connection classes a topology uses, from a one-cell body (exact for any registered topology).
std::set<std::string> classes_of(const BodySpec& body) {
  if (body.unstructured()) return {"edge"};  // tetrahedron edges, one class
  const std::string& topology = body.topology;
  Body cell;
  cell.n = {2, 2, 2};
  cell.h = {1.0, 1.0, 1.0};
  find_topology(topology)->build(cell);
  std::set<std::string> classes;
  for (const auto& c : cell.connections) classes.insert(class_name(c.cls));
  return classes;
}

// A [calibration] table (the top-level one, or a body's own [body.calibration]) for the body `index` of
// `nbodies` (nullptr: a top-level table no body uses, checked for its own keys only). A manual stiffness and a
// method that needs a topology are checked against this body's topology; iterative (a tension test of the whole
// scene, main() wraps the solver) is refused with several bodies.
CalibrationSpec read_calibration(const Section& s, const BodySpec* body, int index, int nbodies) {
  CalibrationSpec c;
  c.key = s.path();
  s.allow({"method", "divisor", "stiffness", "tolerance", "max_updates"});
  auto methods = calibration_method_names();
  c.method = s.choice("method", std::vector<std::string>(methods.begin(), methods.end())).value_or(c.method);
  c.divisor = s.number("divisor").value_or(c.divisor);
  s.positive("divisor", c.divisor);
  c.tolerance = s.number("tolerance").value_or(c.tolerance);
  s.positive("tolerance", c.tolerance);
  c.max_updates = s.integer("max_updates").value_or(c.max_updates);
  s.at_least("max_updates", c.max_updates, 1);

  if (s.has("stiffness")) {
    Section k = s.table("stiffness");
    k.allow({"edge", "face", "body"});
    for (const char* cls : {"edge", "face", "body"}) {
      if (auto x = k.number(cls)) {
        k.non_negative(cls, *x);
        c.stiffness[cls] = *x;
      }
    }
  }
  const CalibrationStyle& style = *find_calibration(c.method);
  c.honours_poisson = style.honours_poisson;
  if (style.wrap_solver && nbodies > 1)
    s.fail("method", fmt::format("{} fits C by a tension test of the whole scene: not available with several "
                                 "bodies ({} here); find C with the body alone in a one-body scene, then give it "
                                 "calibration = {{ method = \"divided\", divisor = C }}", c.method, nbodies));
  if (!body) return c;
  if (style.reads_stiffness) {
    s.require("stiffness", fmt::format("method = \"{}\" needs stiffness = {{ edge = ..., ... }} in N/m", c.method));
    for (const auto& cls : classes_of(*body))
      if (!c.stiffness.count(cls))
        s.table("stiffness")
            .fail(cls, fmt::format("missing: topology \"{}\" has {} connections", body->topology, cls));
  }
  // The body this table calibrates, for messages when the scene has several.
  const std::string which = nbodies > 1 ? fmt::format(" (body {} has \"{}\")", index, body->topology)
                                        : fmt::format(" (the body has \"{}\")", body->topology);
  const std::string problem = calibration_topology_problem(style, body->topology);
  if (!problem.empty()) s.fail("method", problem + which);
  return c;
}

SolverSpec read_solver(const Section& s) {
  SolverSpec v;
  s.allow({"kind", "tolerance", "time_step", "steps", "end_time", "max_iterations", "load_steps",
           "allow_unstable_time_step", "time_step_growth", "max_time_step", "operator"});
  v.kind = s.choice("kind", solver_names()).value_or(v.kind);
  v.tolerance = s.number("tolerance").value_or(v.tolerance);
  if (!(v.tolerance > 0 && v.tolerance < 1))
    s.fail("tolerance", fmt::format("must be in (0, 1), got {}", v.tolerance));
  v.time_step = s.number("time_step");
  if (v.time_step) s.positive("time_step", *v.time_step);
  v.steps = s.integer("steps").value_or(v.steps);
  s.at_least("steps", v.steps, 0);
  v.end_time = s.number("end_time");
  if (v.end_time) s.non_negative("end_time", *v.end_time);
  if (v.end_time && s.has("steps")) s.fail("end_time", "give steps or end_time, not both");
  v.max_iterations = s.integer("max_iterations").value_or(v.max_iterations);
  s.at_least("max_iterations", v.max_iterations, 0);
  v.load_steps = s.integer("load_steps").value_or(v.load_steps);
  s.at_least("load_steps", v.load_steps, 1);
  // Not given: empty, and the solver picks (newton_equilibrium.cpp: matrix-free on springs-only box lattices with
  // the lattice multigrid, where it was measured never slower; assembled elsewhere). A Scene made in code without
  // this parser keeps the struct's "assembled".
  v.tangent_operator = s.choice("operator", {"assembled", "matrix-free"}).value_or("");
  v.allow_unstable_time_step = s.boolean("allow_unstable_time_step").value_or(false);
  v.time_step_growth = s.number("time_step_growth").value_or(v.time_step_growth);
  if (!(v.time_step_growth >= 1.0 && v.time_step_growth <= 10.0))
    s.fail("time_step_growth", fmt::format("must be in [1, 10], got {}", v.time_step_growth));
  v.max_time_step = s.number("max_time_step");
  if (v.max_time_step) s.positive("max_time_step", *v.max_time_step);
  if (v.max_time_step && v.time_step && *v.max_time_step < *v.time_step)
    s.fail("max_time_step", fmt::format("{} is below time_step {}", *v.max_time_step, *v.time_step));
  return v;
}

ObstacleSpec read_obstacle(const Section& s) {
  ObstacleSpec o;
  s.require("kind", "plane or sphere");
  o.kind = *s.choice("kind", {"plane", "sphere"}) == "plane" ? ObstacleSpec::Kind::plane : ObstacleSpec::Kind::sphere;
  if (o.kind == ObstacleSpec::Kind::plane) {
    s.allow({"kind", "point", "normal", "stiffness"});
    s.require("point");
    s.require("normal");
    o.point = *s.vec3("point");
    o.normal = *s.vec3("normal");
    if (o.normal[0] == 0 && o.normal[1] == 0 && o.normal[2] == 0) s.fail("normal", "must not be zero");
  } else {
    s.allow({"kind", "center", "radius", "stiffness"});
    s.require("center");
    s.require("radius");
    o.center = *s.vec3("center");
    o.radius = *s.number("radius");
    s.positive("radius", o.radius);
  }
  o.stiffness = s.number("stiffness").value_or(o.stiffness);
  s.non_negative("stiffness", o.stiffness);
  return o;
}

OutputSpec read_output(const Section& s) {
  OutputSpec o;
  s.allow({"directory", "snapshot_every", "checkpoint_every", "history_every", "fields", "progress"});
  o.directory = s.string("directory").value_or(o.directory);
  if (o.directory.empty()) s.fail("directory", "must not be empty");
  o.snapshot_every = s.integer("snapshot_every").value_or(o.snapshot_every);
  s.at_least("snapshot_every", o.snapshot_every, 0);
  o.checkpoint_every = s.integer("checkpoint_every").value_or(o.checkpoint_every);
  s.at_least("checkpoint_every", o.checkpoint_every, 0);
  o.history_every = s.integer("history_every").value_or(o.history_every);
  s.at_least("history_every", o.history_every, 1);
  if (auto f = s.strings("fields")) {
    std::set<std::string> seen;
    for (const auto& name : *f) {
      if (std::find(field_names.begin(), field_names.end(), name) == field_names.end())
        s.fail("fields", fmt::format("unknown field \"{}\" (one of: {})", name, join(field_names)));
      if (!seen.insert(name).second) s.fail("fields", fmt::format("\"{}\" is listed twice", name));
    }
    o.fields = *f;
  }
  o.progress = s.boolean("progress").value_or(o.progress);
  return o;
}

Scene build_scene(const Value& root, const std::string& file) {
  Scene scene;
  scene.file = file;
  Section top(file, root, "");
  top.allow({"title", "body", "calibration", "fix", "load", "physics", "obstacle", "solver", "output", "partition"});
  scene.title = top.string("title").value_or("");
  top.require("body", "a scene needs a [body] table (or [[body]] tables, one per body)");
  std::vector<Section> body_tables;
  if (top.get("body").is_array()) {  // [[body]]: several bodies, numbered in the order given
    body_tables = top.tables("body");
    if (body_tables.empty()) top.fail("body", "an empty array: give at least one [[body]]");
  } else {
    body_tables.push_back(top.table("body"));
  }
  for (const auto& b : body_tables) scene.bodies.push_back(read_body(b));
  scene.body = scene.bodies[0];
  const int nbodies = static_cast<int>(scene.bodies.size());
  // Each body's calibration: its own [body.calibration] table, else the top-level [calibration] (read once per
  // body: a manual stiffness or a method's topology is checked against each body that uses it). An absent
  // [calibration] is read as an empty one, for those checks.
  const Value none = Value(Table{});
  const Section calibration =
      top.has("calibration") ? top.table("calibration") : Section(file, none, "calibration");
  bool default_used = false;
  for (int b = 0; b < nbodies; ++b) {
    const Section& own = body_tables[b];
    default_used = default_used || !own.has("calibration");
    scene.calibrations.push_back(read_calibration(own.has("calibration") ? own.table("calibration") : calibration,
                                                  &scene.bodies[b], b, nbodies));
    apply_poisson(own, scene.bodies[b], scene.calibrations[b]);
    apply_fibres(own, scene.bodies[b], scene.calibrations[b]);
  }
  if (!default_used) read_calibration(calibration, nullptr, 0, nbodies);  // unused, but its keys must be valid
  scene.calibration = scene.calibrations[0];
  scene.body = scene.bodies[0];  // with its Poisson ratio resolved
  // The cell term needs the lattice path's ghost layer (every cell corner): a scene with a mesh or random body is
  // built by the explicit path instead.
  for (int b = 0; b < nbodies; ++b)
    if (scene.bodies[b].unstructured() && scene_has_cells(scene))
      body_tables[b].fail("shape", "a mesh or random body cannot share a scene with a body that has a "
                                   "poisson_ratio (or cells far from cubic) under homogenized (docs/poisson.md)");
  auto which_body = [&](const Section& t) {
    int b = static_cast<int>(t.integer("body").value_or(0));
    if (b < 0 || b >= nbodies)
      t.fail("body", fmt::format("no body {} (the scene has {} bod{})", b, nbodies, nbodies == 1 ? "y" : "ies"));
    return b;
  };

  // A face: x- .. z+ on a box, a physical surface's name on a mesh (checked against the file with the body).
  auto face_of = [&](const Section& t) {
    const int b = static_cast<int>(t.integer("body").value_or(0));
    if (scene.bodies[b].shape != BodySpec::Shape::mesh) return *t.choice("face", face_names);
    auto name = t.string("face");
    if (name->empty()) t.fail("face", "empty: give the name of a physical surface of the mesh");
    return *name;
  };

  // Fixes: at most one per face of a body.
  std::map<std::pair<int, std::string>, std::string> fixed;  // (body, face) -> which fix[i]
  for (const auto& f : top.tables("fix")) {
    f.allow({"face", "mode", "body", "displacement", "history"});
    FixSpec spec;
    spec.body = which_body(f);
    f.require("face", "one of " + join(face_names));
    spec.face = face_of(f);
    if (f.choice("mode", {"clamped", "roller"}).value_or("clamped") == "roller") spec.mode = FixSpec::Mode::roller;
    spec.displacement = f.vec3("displacement").value_or(spec.displacement);
    spec.history = read_history(f);
    auto [it, added] = fixed.emplace(std::make_pair(spec.body, spec.face), f.path());
    if (!added) f.fail("face", fmt::format("face {} is already fixed by {}", spec.face, it->second));
    scene.fixes.push_back(spec);
  }
  for (const auto& l : top.tables("load")) {
    l.allow({"face", "force", "distribution", "body", "period", "history"});
    LoadSpec spec;
    spec.body = which_body(l);
    l.require("face", "one of " + join(face_names));
    spec.face = face_of(l);
    if (fixed.count({spec.body, spec.face}))
      l.fail("face", fmt::format("face {} is also fixed (a fixed face cannot be loaded)", spec.face));
    l.require("force", "[Fx, Fy, Fz] in N, the total over the face");
    spec.force = *l.vec3("force");
    if (spec.force[0] == 0 && spec.force[1] == 0 && spec.force[2] == 0) l.fail("force", "must not be zero");
    if (l.choice("distribution", {"traction", "equal"}).value_or("traction") == "equal")
      spec.distribution = LoadSpec::Distribution::equal;
    spec.period = l.number("period").value_or(0.0);
    if (l.has("period")) l.positive("period", spec.period);
    spec.history = read_history(l);
    if (spec.period > 0 && !spec.history.empty()) l.fail("history", "a cyclic load (period) has no history");
    scene.loads.push_back(spec);
  }

  if (top.has("physics")) {
    Section p = top.table("physics");
    p.allow({"gravity", "viscosity", "contact", "contact_stiffness", "contact_skin"});
    scene.physics.gravity = p.vec3("gravity");
    scene.physics.viscosity = p.number("viscosity");
    if (scene.physics.viscosity) p.non_negative("viscosity", *scene.physics.viscosity);
    scene.physics.contact = p.boolean("contact").value_or(false);
    scene.physics.contact_stiffness = p.number("contact_stiffness").value_or(0.0);
    p.non_negative("contact_stiffness", scene.physics.contact_stiffness);
    scene.physics.contact_skin = p.number("contact_skin").value_or(0.0);
    p.non_negative("contact_skin", scene.physics.contact_skin);
  }
  for (const auto& o : top.tables("obstacle")) scene.obstacles.push_back(read_obstacle(o));

  if (top.has("solver")) scene.solver = read_solver(top.table("solver"));
  // Equilibrium needs the rigid motion held: by a [[fix]], or (relaxation only, which never inverts the
  // stiffness) by the obstacles the body rests on.
  const SolverStyle& solver = *find_solver(scene.solver.kind);
  std::vector<std::string> settling, in_time;  // the kinds that may rest on obstacles, that integrate in time
  for (const auto& k : solver_styles()) {
    if (k.settles_on_obstacles) settling.emplace_back(k.name);
    if (k.integrates_time) in_time.emplace_back(fmt::format("\"{}\"", k.name));
  }
  const bool held_by_contact = solver.settles_on_obstacles && !scene.obstacles.empty();
  if (!solver.integrates_time && scene.fixes.empty() && !held_by_contact)
    throw InputError(file, "solver.kind",
                     fmt::format("a {} solve needs at least one [[fix]] (rigid motion is unbounded){}",
                                 scene.solver.kind,
                                 scene.obstacles.empty() ? ""
                                                         : fmt::format("; {} may rest on obstacles instead",
                                                                       join(settling, " or "))));
  // Each loaded body of several (a [[load]] on it, or gravity): held by its own [[fix]], unless contact between
  // the bodies may hold it. (An unloaded, unheld body stays where it is.)
  const bool gravity = scene.physics.gravity && *scene.physics.gravity != Vec3{0.0, 0.0, 0.0};
  if (!solver.integrates_time && !held_by_contact && !scene.physics.contact && scene.bodies.size() > 1)
    for (std::size_t b = 0; b < scene.bodies.size(); ++b) {
      const auto on_b = [&](const auto& spec) { return spec.body == static_cast<int>(b); };
      if (std::none_of(scene.fixes.begin(), scene.fixes.end(), on_b) &&
          (gravity || std::any_of(scene.loads.begin(), scene.loads.end(), on_b)))
        throw InputError(file, fmt::format("body[{}]", b),
                         fmt::format("a {} solve needs a [[fix]] on every loaded body (rigid motion of this one "
                                     "under its load is unbounded; with physics.contact = true bodies may hold "
                                     "each other)",
                                     scene.solver.kind));
    }
  for (std::size_t i = 0; i < scene.loads.size(); ++i)
    if (scene.loads[i].period > 0 && !solver.integrates_time)
      throw InputError(file, fmt::format("load[{}].period", i),
                       "a cyclic load needs solver.kind = " + join(in_time, " or "));
  // Loads and holds in time, and the Prony history, need a solver that follows time; a prescribed displacement
  // moves held molecules, which only the quasi-static solver does for now.
  if (!solver.moves_holds) {
    std::vector<std::string> moving, histories;  // the kinds that move holds; that follow loads in time
    for (const auto& k : solver_styles()) {
      if (k.moves_holds) moving.emplace_back(fmt::format("\"{}\"", k.name));
      if (k.moves_holds || k.integrates_time) histories.emplace_back(fmt::format("\"{}\"", k.name));
    }
    for (std::size_t i = 0; i < scene.fixes.size(); ++i) {
      const FixSpec& f = scene.fixes[i];
      if (f.displacement != Vec3{0.0, 0.0, 0.0} || !f.history.empty())
        throw InputError(file, fmt::format("fix[{}].{}", i, f.history.empty() ? "displacement" : "history"),
                         "a moving hold needs solver.kind = " + join(moving, " or "));
    }
    for (std::size_t i = 0; i < scene.loads.size(); ++i)
      if (!scene.loads[i].history.empty() && !solver.integrates_time)
        throw InputError(file, fmt::format("load[{}].history", i),
                         "a load history needs solver.kind = " + join(histories, " or "));
  }
  if (top.has("output")) scene.output = read_output(top.table("output"));
  if (solver.needs_time_step && !scene.solver.time_step)
    throw InputError(file, "solver.time_step", fmt::format("missing: a {} run needs its time step (s)", solver.name));
  if (!solver.needs_time_step && (scene.solver.time_step_growth != 1.0 || scene.solver.max_time_step))
    throw InputError(file, scene.solver.max_time_step ? "solver.max_time_step" : "solver.time_step_growth",
                     "only a quasi-static run grows its time step");
  if (scene.output.checkpoint_every > 0 && !solver.checkpointed)
    throw InputError(file, "output.checkpoint_every", fmt::format("a {} run is not checkpointed yet (give 0)", solver.name));
  if (top.has("partition")) {
    Section p = top.table("partition");
    p.allow({"method"});
    const std::string method = p.choice("method", {"auto", "metis", "ptscotch", "blocks"}).value_or("auto");
    if (method == "metis") scene.partition.method = PartitionSpec::Method::metis;
    if (method == "ptscotch") scene.partition.method = PartitionSpec::Method::ptscotch;
    if (method == "blocks") {
      const bool one_box = scene.bodies.size() <= 1 && !scene.body.unstructured();
      if (!one_box)
        throw InputError(file, "partition.method", "\"blocks\" cuts one box lattice; meshes, clouds and several bodies "
                                                   "take \"metis\" or \"ptscotch\"");
      scene.partition.method = PartitionSpec::Method::blocks;
    }
  }
  return scene;
}

}  // namespace

Scene parse_scene(const std::string& text, const std::string& name, const std::vector<std::string>& overrides) {
  Value root = parse_toml(text, name);
  for (const auto& o : overrides) apply_override(root, o);
  Scene scene = build_scene(root, name);
  // A mesh path relative to the scene file would be read from the checkpoint's directory on restart: the text
  // keeps the absolute path.
  Value& body = root.as_table().at("body");
  for (std::size_t i = 0; i < scene.bodies.size(); ++i)
    if (scene.bodies[i].shape == BodySpec::Shape::mesh)
      (body.is_array() ? body.as_array()[i] : body).as_table()["file"] =
          std::filesystem::absolute(scene.bodies[i].file).string();
  // 17 significant digits and no width limit: parse_scene(text) gives back the same Scene. toml11 splits a basic
  // string longer than the width with line-ending backslashes, which eat a space at the split (a title lost a
  // space on restart: tests/fuzz_regressions/scene/crash-toml11-long-string-split-space.toml).
  scene.text = toml::format(root, std::numeric_limits<std::size_t>::max());
  return scene;
}

Scene read_scene(const std::string& path, const std::vector<std::string>& overrides) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw InputError(path, "", "is a directory, not a scene file");
  // (a device would be read without end: /dev/zero; a pipe is read to its end, as `tissue run <(make_scene)`)
  if (std::filesystem::is_character_file(path, ec) || std::filesystem::is_block_file(path, ec))
    throw InputError(path, "", "a device, not a scene file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "", std::string("cannot open: ") + std::strerror(errno));
  auto size = std::filesystem::file_size(path, ec);
  if (!ec && size > max_scene_bytes)
    throw InputError(path, "",
                     fmt::format("not a scene: {} bytes (a scene is at most {})", size, max_scene_bytes));
  // Read in pieces, at most one byte more than a scene may have (a pipe has no size to check first).
  std::string text;
  char piece[1 << 16];
  while (text.size() <= max_scene_bytes && in.read(piece, sizeof piece).gcount() > 0)
    text.append(piece, static_cast<std::size_t>(in.gcount()));
  if (in.bad()) throw InputError(path, "", std::string("cannot read: ") + std::strerror(errno));
  if (text.size() > max_scene_bytes)
    throw InputError(path, "", fmt::format("not a scene: more than {} bytes", max_scene_bytes));
  return parse_scene(text, path, overrides);
}

}  // namespace tissue
