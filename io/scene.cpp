// Reading a scene: TOML text -> --set overrides -> validation -> Scene. Every problem becomes one InputError
// naming the file and the dotted key; nothing past this file re-checks the scene.
#include "io/scene.hpp"

#include <limits>
#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <set>
#include <sstream>
#include <toml.hpp>

#include "src/calibration/calibration.hpp"
#include "src/model/body.hpp"
#include "src/model/material.hpp"
#include "src/model/topology.hpp"
#include "src/solvers/solver.hpp"

namespace tissue {

namespace {

// std::map tables keep the serialized text (Scene::text) in a fixed, sorted order.
using Value = toml::basic_value<toml::discard_comments, std::map, std::vector>;
using Table = Value::table_type;

const std::size_t max_scene_bytes = 16u << 20;  // a scene is a page of text, not a data file
const int max_nesting = 64;                     // deep [[[[ would overflow the recursive TOML parser

std::string join(const std::vector<std::string>& names, const char* separator = ", ") {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : separator) + n;
  return s;
}

const char* type_name(const Value& v) {
  switch (v.type()) {
    case toml::value_t::boolean:
      return "a boolean";
    case toml::value_t::integer:
      return "an integer";
    case toml::value_t::floating:
      return "a float";
    case toml::value_t::string:
      return "a string";
    case toml::value_t::offset_datetime:
    case toml::value_t::local_datetime:
    case toml::value_t::local_date:
    case toml::value_t::local_time:
      return "a date/time";
    case toml::value_t::array:
      return "an array";
    case toml::value_t::table:
      return "a table";
    default:
      return "nothing";
  }
}

// Rejects what the TOML parser should never see: binary bytes, bad UTF-8, absurd size or nesting. TOML allows
// no control characters but tab, so these are errors in any TOML file anyway; catching them here keeps the
// message to one clear line.
void check_text(const std::string& text, const std::string& file) {
  if (text.size() > max_scene_bytes)
    throw InputError(file, "",
                     fmt::format("not a scene: {} bytes (a scene is at most {})", text.size(), max_scene_bytes));
  long line = 1;
  for (std::size_t i = 0; i < text.size(); ++i) {
    auto c = static_cast<unsigned char>(text[i]);
    if (c == '\n') ++line;
    if ((c < 0x20 && c != '\t' && c != '\n' && c != '\r') || c == 0x7f)
      throw InputError(file, "", fmt::format("not a TOML file: control byte 0x{:02x} on line {}", c, line));
    if (c < 0x80) continue;
    // UTF-8 as RFC 3629 has it: a lead byte and 1-3 continuation bytes, no overlongs (C0, C1, E0 80-9F,
    // F0 80-8F), no surrogates (ED A0-BF), nothing above U+10FFFF (F4 90-BF, F5-FF). toml11 reads past its buffer
    // on any of these inside a literal string (found by tests/fuzz/fuzz_scene;
    // tests/fuzz_regressions/scene/crash-toml11-literal-string-invalid-utf8.toml).
    int extra = (c >= 0xc2 && c <= 0xdf) ? 1 : (c >> 4) == 0xe ? 2 : (c >= 0xf0 && c <= 0xf4) ? 3 : -1;
    bool ok = extra > 0 && i + extra < text.size();
    for (int k = 1; ok && k <= extra; ++k) ok = (static_cast<unsigned char>(text[i + k]) >> 6) == 0x2;
    if (ok) {
      auto c1 = static_cast<unsigned char>(text[i + 1]);
      ok = !((c == 0xe0 && c1 < 0xa0) || (c == 0xed && c1 > 0x9f) || (c == 0xf0 && c1 < 0x90) ||
             (c == 0xf4 && c1 > 0x8f));
    }
    if (!ok) throw InputError(file, "", fmt::format("not a TOML file: invalid UTF-8 on line {}", line));
    i += extra;
  }
  // Bracket depth outside strings and comments (the line is counted only for the message).
  int depth = 0;
  for (std::size_t i = 0; i < text.size(); ++i) {
    char c = text[i];
    if (c == '#') {
      while (i + 1 < text.size() && text[i + 1] != '\n') ++i;
    } else if (c == '"' || c == '\'') {
      bool triple = text.compare(i, 3, std::string(3, c)) == 0;
      std::size_t j = i + (triple ? 3 : 1);
      for (; j < text.size(); ++j) {
        if (c == '"' && text[j] == '\\')
          ++j;  // an escaped character
        else if (text[j] == '\n' && !triple)
          break;
        else if (text[j] == c && (!triple || text.compare(j, 3, std::string(3, c)) == 0)) {
          j += triple ? 2 : 0;
          break;
        }
      }
      i = std::min(j, text.size());
    } else if (c == '[' || c == '{') {
      if (++depth > max_nesting)
        throw InputError(file, "",
                         fmt::format("not a scene: brackets nested deeper than {} on line {}", max_nesting,
                                     1 + std::count(text.begin(), text.begin() + i, '\n')));
    } else if (c == ']' || c == '}') {
      depth = std::max(0, depth - 1);
    }
  }
}

// toml11's messages are several lines with a source excerpt; keep the first line and the line number.
std::string condense(const toml::exception& e) {
  std::string msg = e.what();
  msg = msg.substr(0, msg.find('\n'));
  for (const char* prefix : {"[error] ", "toml::"}) {
    if (msg.compare(0, std::strlen(prefix), prefix) == 0) msg.erase(0, std::strlen(prefix));
  }
  // Drop the parser's function name ("parse_table: ...").
  auto colon = msg.find(": ");
  if (colon != std::string::npos && msg.find(' ') > colon) msg.erase(0, colon + 2);
  auto line = e.location().line();
  return line > 0 ? fmt::format("line {}: {}", line, msg) : msg;
}

Value parse_toml(const std::string& text, const std::string& file) {
  check_text(text, file);
  std::istringstream in(text);
  try {
    return toml::parse<toml::discard_comments, std::map, std::vector>(in, file);
  } catch (const toml::exception& e) {
    throw InputError(file, "", "not valid TOML, " + condense(e));
  } catch (const std::exception& e) {
    std::string msg = e.what();
    throw InputError(file, "", "not valid TOML: " + msg.substr(0, msg.find('\n')));
  }
}

// ---- --set overrides ----

bool is_index(const std::string& s) {
  return !s.empty() && s.size() < 10 && s.find_first_not_of("0123456789") == std::string::npos;
}

// VALUE as TOML ("[1,2,3]", "1e5", "true", "\"x\""); anything that is not is taken as a bare string.
Value override_value(const std::string& text) {
  // The same byte checks as a scene file: toml11 reads past the end of an unterminated string that holds bad
  // UTF-8 (found by tests/fuzz/fuzz_scene_set; tests/fuzz_regressions/scene_set).
  check_text(text, "--set");
  std::istringstream in("v = " + text);
  try {
    Value t = toml::parse<toml::discard_comments, std::map, std::vector>(in, "--set");
    if (t.is_table() && t.as_table().size() == 1 && t.as_table().count("v")) return t.as_table().at("v");
  } catch (const std::exception&) {
  }
  return Value(text);
}

void apply_override(Value& root, const std::string& item) {
  auto eq = item.find('=');
  if (eq == std::string::npos) throw InputError("--set", item, "expected KEY=VALUE");
  std::string key = item.substr(0, eq);
  key.erase(0, key.find_first_not_of(" \t"));
  key.erase(key.find_last_not_of(" \t") + 1);
  if (key.empty()) throw InputError("--set", item, "empty key, expected KEY=VALUE");
  std::vector<std::string> parts;
  for (std::size_t b = 0;;) {
    auto e = key.find('.', b);
    parts.push_back(key.substr(b, e - b));
    if (parts.back().empty()) throw InputError("--set", key, "empty part in the dotted key");
    if (e == std::string::npos) break;
    b = e + 1;
  }
  Value value = override_value(item.substr(eq + 1));

  Value* node = &root;
  std::string walked;  // the dotted path so far, for messages
  for (std::size_t i = 0; i < parts.size(); ++i) {
    const std::string& p = parts[i];
    if (node->is_array()) {
      auto& a = node->as_array();
      if (!is_index(p))
        throw InputError("--set", key, fmt::format("{} is an array: expected an index, got \"{}\"", walked, p));
      std::size_t k = std::stoul(p);
      if (k >= a.size())
        throw InputError("--set", key, fmt::format("{} has {} element(s), no index {}", walked, a.size(), k));
      node = &a[k];
    } else if (node->is_table()) {
      auto& t = node->as_table();
      auto it = t.find(p);
      if (it == t.end()) {
        if (i + 1 == parts.size()) {
          t.emplace(p, value);
          return;
        }
        // A missing intermediate is a new table; an index into a missing array is a mistake.
        if (is_index(parts[i + 1]))
          throw InputError("--set", key, fmt::format("{} does not exist", walked.empty() ? p : walked + "." + p));
        it = t.emplace(p, Value(Table{})).first;
      }
      node = &it->second;
    } else {
      throw InputError("--set", key, fmt::format("{} is {}, not a table", walked, type_name(*node)));
    }
    walked += (walked.empty() ? "" : ".") + p;
  }
  *node = value;
}

// ---- validation ----

// One TOML table of the scene and its dotted path: typed getters that name the key in every error.
class Section {
public:
  Section(const std::string& file, const Value& v, std::string path) : file_(file), path_(std::move(path)) {
    if (!v.is_table()) throw InputError(file_, path_, std::string("expected a table, got ") + type_name(v));
    table_ = &v.as_table();
  }

  std::string key(const std::string& k) const { return path_.empty() ? k : path_ + "." + k; }
  const std::string& path() const { return path_; }
  const std::string& file() const { return file_; }
  [[noreturn]] void fail(const std::string& k, const std::string& problem) const {
    throw InputError(file_, key(k), problem);
  }
  bool has(const std::string& k) const { return table_->count(k) != 0; }
  const Value& get(const std::string& k) const { return table_->at(k); }

  // Unknown keys are errors (a typo must not silently fall back to a default).
  void allow(std::initializer_list<const char*> keys) const {
    for (const auto& kv : *table_) {
      bool known = false;
      for (const char* k : keys) known = known || kv.first == k;
      if (!known) {
        std::vector<std::string> names(keys.begin(), keys.end());
        fail(kv.first, "unknown key (known here: " + join(names) + ")");
      }
    }
  }
  void require(const std::string& k, const std::string& why = "") const {
    if (!has(k)) fail(k, "missing" + (why.empty() ? std::string() : " (" + why + ")"));
  }

  std::optional<double> number(const std::string& k) const {
    if (!has(k)) return std::nullopt;
    return to_number(get(k), k, "expected a number");
  }
  std::optional<long> integer(const std::string& k) const {
    if (!has(k)) return std::nullopt;
    const Value& v = get(k);
    if (!v.is_integer()) fail(k, std::string("expected an integer, got ") + type_name(v));
    return static_cast<long>(v.as_integer());
  }
  std::optional<bool> boolean(const std::string& k) const {
    if (!has(k)) return std::nullopt;
    const Value& v = get(k);
    if (!v.is_boolean()) fail(k, std::string("expected true or false, got ") + type_name(v));
    return v.as_boolean();
  }
  std::optional<std::string> string(const std::string& k) const {
    if (!has(k)) return std::nullopt;
    const Value& v = get(k);
    if (!v.is_string()) fail(k, std::string("expected a string, got ") + type_name(v));
    return v.as_string().str;
  }
  // A string from a fixed list of names.
  std::optional<std::string> choice(const std::string& k, const std::vector<std::string>& names) const {
    auto s = string(k);
    if (s && std::find(names.begin(), names.end(), *s) == names.end())
      fail(k, fmt::format("unknown value \"{}\" (one of: {})", *s, join(names)));
    return s;
  }
  std::optional<Vec3> vec3(const std::string& k) const {
    if (!has(k)) return std::nullopt;
    const Value& v = get(k);
    const char* want = "expected an array of 3 numbers";
    if (!v.is_array() || v.as_array().size() != 3) fail(k, std::string(want) + ", got " + describe(v));
    Vec3 x;
    for (int a = 0; a < 3; ++a) x[a] = to_number(v.as_array()[a], k, want);
    return x;
  }
  std::optional<std::array<long, 3>> int3(const std::string& k) const {
    if (!has(k)) return std::nullopt;
    const Value& v = get(k);
    const char* want = "expected an array of 3 integers";
    if (!v.is_array() || v.as_array().size() != 3) fail(k, std::string(want) + ", got " + describe(v));
    std::array<long, 3> x;
    for (int a = 0; a < 3; ++a) {
      const Value& e = v.as_array()[a];
      if (!e.is_integer()) fail(k, std::string(want) + ", element " + std::to_string(a) + " is " + type_name(e));
      x[a] = static_cast<long>(e.as_integer());
    }
    return x;
  }
  std::optional<std::vector<std::string>> strings(const std::string& k) const {
    if (!has(k)) return std::nullopt;
    const Value& v = get(k);
    if (!v.is_array()) fail(k, std::string("expected an array of strings, got ") + type_name(v));
    std::vector<std::string> out;
    for (const auto& e : v.as_array()) {
      if (!e.is_string()) fail(k, std::string("expected an array of strings, an element is ") + type_name(e));
      out.push_back(e.as_string().str);
    }
    return out;
  }
  Section table(const std::string& k) const { return Section(file_, get(k), key(k)); }
  // [[k]]: an array of tables, each named k[i] in messages.
  std::vector<Section> tables(const std::string& k) const {
    std::vector<Section> out;
    if (!has(k)) return out;
    const Value& v = get(k);
    if (!v.is_array()) fail(k, fmt::format("expected an array of tables ([[{}]]), got {}", k, type_name(v)));
    const auto& a = v.as_array();
    for (std::size_t i = 0; i < a.size(); ++i) out.emplace_back(file_, a[i], fmt::format("{}[{}]", key(k), i));
    return out;
  }

  // Range checks, each naming the key and the value.
  void positive(const std::string& k, double x) const {
    if (!(x > 0)) fail(k, fmt::format("must be > 0, got {}", x));
  }
  void non_negative(const std::string& k, double x) const {
    if (!(x >= 0)) fail(k, fmt::format("must be >= 0, got {}", x));
  }
  void at_least(const std::string& k, long x, long min) const {
    if (x < min) fail(k, fmt::format("must be >= {}, got {}", min, x));
  }
  void positive3(const std::string& k, const Vec3& x) const {
    for (double c : x)
      if (!(c > 0)) fail(k, fmt::format("every component must be > 0, got [{}, {}, {}]", x[0], x[1], x[2]));
  }

private:
  double to_number(const Value& v, const std::string& k, const char* want) const {
    double x;
    if (v.is_floating())
      x = v.as_floating();
    else if (v.is_integer())
      x = static_cast<double>(v.as_integer());
    else
      fail(k, std::string(want) + ", got " + type_name(v));
    if (!std::isfinite(x)) fail(k, fmt::format("must be finite, got {}", x));
    return x;
  }
  static std::string describe(const Value& v) {
    return v.is_array() ? fmt::format("{} elements", v.as_array().size()) : type_name(v);
  }

  std::string file_, path_;
  const Table* table_ = nullptr;
};

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
void read_material(const Section& s, std::string& material, double& E, double& density) {
  material = s.choice("material", material_names()).value_or("custom");
  const TissuePreset* preset = material == "custom" ? nullptr : find_tissue(material);
  auto e = s.number("youngs_modulus");
  if (!e && !preset) s.fail("youngs_modulus", "missing (required with material = \"custom\")");
  E = e ? *e : preset->youngs_modulus;
  s.positive("youngs_modulus", E);
  density = s.number("density").value_or(preset ? preset->density : 1000.0);
  s.positive("density", density);
}

// shape = "mesh": a Gmsh file, its physical volumes as regions (by name). The file is read with the body.
BodySpec read_mesh_body(const Section& s, BodySpec b) {
  s.allow({"shape", "file", "topology", "material", "youngs_modulus", "density", "offset", "region", "radius",
           "calibration", "seed", "interior_molecules", "mesh_size"});
  s.require("file", "the Gmsh mesh (.msh) or geometry (.geo) of the body");
  b.file = *s.string("file");
  if (b.file.empty()) s.fail("file", "empty path");
  namespace fs = std::filesystem;
  if (fs::path(b.file).is_relative()) b.file = (fs::path(s.file()).parent_path() / b.file).lexically_normal().string();
  std::error_code ec;
  if (!fs::is_regular_file(b.file, ec)) s.fail("file", fmt::format("cannot open \"{}\": no such file", b.file));
  // A .geo is meshed at run time (io/gmsh_mesh.hpp); mesh_size (m) caps its elements' size, over the .geo's own.
  if (s.has("mesh_size") && fs::path(b.file).extension() != ".geo")
    s.fail("mesh_size", "only a .geo geometry is meshed at run time; a mesh file is used as it is");
  b.mesh_size = s.number("mesh_size").value_or(0.0);
  if (s.has("mesh_size")) s.positive("mesh_size", b.mesh_size);
  // topology = "random": the mesh's boundary nodes and interior_molecules points at random inside it, Delaunay
  // (src/model/mesh_cloud.hpp); "mesh": the mesh's own tetrahedra.
  b.topology = s.choice("topology", {"mesh", "random"}).value_or("mesh");
  for (const char* k : {"seed", "interior_molecules"})
    if (s.has(k) && b.topology != "random") s.fail(k, "only topology = \"random\" has it");
  b.seed = s.integer("seed").value_or(b.seed);
  if (b.topology == "random") {
    s.require("interior_molecules", "the number of molecules to sample inside the mesh's volume");
    b.interior_molecules = *s.integer("interior_molecules");
    s.at_least("interior_molecules", b.interior_molecules, 1);
    if (b.interior_molecules > 2000000000L)
      s.fail("interior_molecules", fmt::format("{} molecules, more than the 2e9 supported", b.interior_molecules));
  }
  read_material(s, b.material, b.youngs_modulus, b.density);
  b.offset = s.vec3("offset").value_or(b.offset);
  b.radius = s.number("radius");
  if (b.radius) s.positive("radius", *b.radius);
  for (const auto& r : s.tables("region")) {
    r.allow({"name", "material", "youngs_modulus", "density"});
    RegionSpec spec;
    r.require("name", "the physical volume of the mesh (a mesh's regions are named, not boxes)");
    spec.name = *r.string("name");
    read_material(r, spec.material, spec.youngs_modulus, spec.density);
    b.regions.push_back(spec);
  }
  return b;
}

BodySpec read_body(const Section& s) {
  BodySpec b;
  b.shape = s.string("shape").value_or("box");
  if (b.shape != "box" && b.shape != "mesh")
    s.fail("shape", fmt::format("unknown value \"{}\" (one of: box, mesh)", b.shape));
  if (b.shape == "mesh") return read_mesh_body(s, b);
  s.allow({"shape", "molecules", "spacing", "size", "topology", "material", "youngs_modulus", "density", "offset",
           "region", "radius", "calibration", "seed"});  // calibration: read by build_scene (read_calibration)

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
  if (s.has("seed") && b.topology != "random") s.fail("seed", "only topology = \"random\" has a seed");
  b.seed = s.integer("seed").value_or(b.seed);
  if (b.topology == "random" && !s.tables("region").empty())
    s.fail("region", "a random box has no regions yet (give the body one material)");
  read_material(s, b.material, b.youngs_modulus, b.density);
  b.offset = s.vec3("offset").value_or(b.offset);
  b.radius = s.number("radius");
  if (b.radius) s.positive("radius", *b.radius);

  for (const auto& r : s.tables("region")) {
    r.allow({"lo", "hi", "material", "youngs_modulus", "density"});
    RegionSpec spec;
    r.require("lo");
    r.require("hi");
    spec.lo = *r.vec3("lo");
    spec.hi = *r.vec3("hi");
    for (int a = 0; a < 3; ++a)
      if (spec.lo[a] > spec.hi[a])
        r.fail("hi", fmt::format("hi[{}] = {} is below lo[{}] = {}", a, spec.hi[a], a, spec.lo[a]));
    read_material(r, spec.material, spec.youngs_modulus, spec.density);
    b.regions.push_back(spec);
  }
  return b;
}

// The connection classes a topology uses, from a one-cell body (exact for any registered topology).
std::set<std::string> classes_of(const std::string& topology) {
  if (topology == "mesh" || topology == "random") return {"edge"};  // tetrahedron edges, one class
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
  if (style.wrap_solver && nbodies > 1)
    s.fail("method", fmt::format("{} fits C by a tension test of the whole scene: not available with several "
                                 "bodies ({} here); find C with the body alone in a one-body scene, then give it "
                                 "calibration = {{ method = \"divided\", divisor = C }}", c.method, nbodies));
  if (!body) return c;
  if (c.method == "manual") {
    s.require("stiffness", "method = \"manual\" needs stiffness = { edge = ..., ... } in N/m");
    for (const auto& cls : classes_of(body->topology))
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
  s.allow({"kind", "tolerance", "time_step", "steps", "max_iterations", "load_steps", "allow_unstable_time_step"});
  v.kind = s.choice("kind", solver_names()).value_or(v.kind);
  v.tolerance = s.number("tolerance").value_or(v.tolerance);
  if (!(v.tolerance > 0 && v.tolerance < 1))
    s.fail("tolerance", fmt::format("must be in (0, 1), got {}", v.tolerance));
  v.time_step = s.number("time_step");
  if (v.time_step) s.positive("time_step", *v.time_step);
  v.steps = s.integer("steps").value_or(v.steps);
  s.at_least("steps", v.steps, 0);
  v.max_iterations = s.integer("max_iterations").value_or(v.max_iterations);
  s.at_least("max_iterations", v.max_iterations, 0);
  v.load_steps = s.integer("load_steps").value_or(v.load_steps);
  s.at_least("load_steps", v.load_steps, 1);
  v.allow_unstable_time_step = s.boolean("allow_unstable_time_step").value_or(false);
  return v;
}

ObstacleSpec read_obstacle(const Section& s) {
  ObstacleSpec o;
  s.require("kind", "plane or sphere");
  o.kind = *s.choice("kind", {"plane", "sphere"});
  if (o.kind == "plane") {
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
  s.allow({"directory", "snapshot_every", "checkpoint_every", "fields", "progress"});
  o.directory = s.string("directory").value_or(o.directory);
  if (o.directory.empty()) s.fail("directory", "must not be empty");
  o.snapshot_every = s.integer("snapshot_every").value_or(o.snapshot_every);
  s.at_least("snapshot_every", o.snapshot_every, 0);
  o.checkpoint_every = s.integer("checkpoint_every").value_or(o.checkpoint_every);
  s.at_least("checkpoint_every", o.checkpoint_every, 0);
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
  }
  if (!default_used) read_calibration(calibration, nullptr, 0, nbodies);  // unused, but its keys must be valid
  scene.calibration = scene.calibrations[0];
  auto which_body = [&](const Section& t) {
    int b = static_cast<int>(t.integer("body").value_or(0));
    if (b < 0 || b >= nbodies)
      t.fail("body", fmt::format("no body {} (the scene has {} bod{})", b, nbodies, nbodies == 1 ? "y" : "ies"));
    return b;
  };

  // A face: x- .. z+ on a box, a physical surface's name on a mesh (checked against the file with the body).
  auto face_of = [&](const Section& t) {
    const int b = static_cast<int>(t.integer("body").value_or(0));
    if (scene.bodies[b].shape != "mesh") return *t.choice("face", face_names);
    auto name = t.string("face");
    if (name->empty()) t.fail("face", "empty: give the name of a physical surface of the mesh");
    return *name;
  };

  // Fixes: at most one per face of a body.
  std::map<std::pair<int, std::string>, std::string> fixed;  // (body, face) -> which fix[i]
  for (const auto& f : top.tables("fix")) {
    f.allow({"face", "mode", "body"});
    FixSpec spec;
    spec.body = which_body(f);
    f.require("face", "one of " + join(face_names));
    spec.face = face_of(f);
    if (f.choice("mode", {"clamped", "roller"}).value_or("clamped") == "roller") spec.mode = FixSpec::Mode::roller;
    auto [it, added] = fixed.emplace(std::make_pair(spec.body, spec.face), f.path());
    if (!added) f.fail("face", fmt::format("face {} is already fixed by {}", spec.face, it->second));
    scene.fixes.push_back(spec);
  }
  for (const auto& l : top.tables("load")) {
    l.allow({"face", "force", "distribution", "body", "period"});
    LoadSpec spec;
    spec.body = which_body(l);
    l.require("face", "one of " + join(face_names));
    spec.face = face_of(l);
    if (fixed.count({spec.body, spec.face}))
      l.fail("face", fmt::format("face {} is also fixed (a fixed face cannot be loaded)", spec.face));
    l.require("force", "[Fx, Fy, Fz] in N, the total over the face");
    spec.force = *l.vec3("force");
    if (spec.force[0] == 0 && spec.force[1] == 0 && spec.force[2] == 0) l.fail("force", "must not be zero");
    spec.distribution = l.choice("distribution", {"traction", "equal"}).value_or(spec.distribution);
    spec.period = l.number("period").value_or(0.0);
    if (l.has("period")) l.positive("period", spec.period);
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
  for (std::size_t i = 0; i < scene.loads.size(); ++i)
    if (scene.loads[i].period > 0 && !solver.integrates_time)
      throw InputError(file, fmt::format("load[{}].period", i),
                       "a cyclic load needs solver.kind = " + join(in_time, " or "));
  if (top.has("output")) scene.output = read_output(top.table("output"));
  if (top.has("partition")) {
    Section p = top.table("partition");
    p.allow({"method"});
    scene.partition.method = p.choice("method", {"metis", "ptscotch"}).value_or(scene.partition.method);
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
    if (scene.bodies[i].shape == "mesh")
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
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "", std::string("cannot open: ") + std::strerror(errno));
  auto size = std::filesystem::file_size(path, ec);
  if (!ec && size > max_scene_bytes)
    throw InputError(path, "",
                     fmt::format("not a scene: {} bytes (a scene is at most {})", size, max_scene_bytes));
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw InputError(path, "", std::string("cannot read: ") + std::strerror(errno));
  return parse_scene(text.str(), path, overrides);
}

}  // namespace tissue
