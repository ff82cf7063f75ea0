#include "io/fit_input.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <regex>
#include <sstream>

#include "io/scene.hpp"
#include "io/scene_overrides.hpp"
#include "io/toml_text.hpp"
#include "src/model/scene.hpp"

namespace tissue {

using scene_reader::Value;

namespace {

std::string read_text(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw InputError(path, "", "is a directory, not a file");
  if (std::filesystem::is_character_file(path, ec) || std::filesystem::is_block_file(path, ec))
    throw InputError(path, "", "a device, not a file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "", std::string("cannot open: ") + std::strerror(errno));
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

std::vector<std::string> split_csv_line(const std::string& line) {
  std::vector<std::string> cells;
  std::string cell;
  std::istringstream in(line);
  while (std::getline(in, cell, ',')) {
    while (!cell.empty() && (cell.back() == '\r' || cell.back() == ' ')) cell.pop_back();
    while (!cell.empty() && cell.front() == ' ') cell.erase(cell.begin());
    cells.push_back(cell);
  }
  if (!line.empty() && line.back() == ',') cells.emplace_back();
  return cells;
}

// Columns x and y of a CSV with a header line; `key` names the [fit] key that named the file, for messages.
void read_columns(const std::string& path, const std::string& x, const std::vector<std::string>& y,
                  std::vector<double>& xs, std::vector<std::vector<double>>& ys, bool input_error) {
  auto fail = [&](const std::string& key, const std::string& problem) {
    if (input_error) throw InputError(path, key, problem);
    throw std::runtime_error(path + ": " + (key.empty() ? "" : key + ": ") + problem);
  };
  std::ifstream in(path);
  if (!in) fail("", std::string("cannot open: ") + std::strerror(errno));
  std::string line;
  if (!std::getline(in, line)) fail("", "empty: a header line is needed");
  const std::vector<std::string> header = split_csv_line(line);
  const auto header_fields = std::count(line.begin(), line.end(), ',') + 1;
  auto column = [&](const std::string& name) {
    for (std::size_t i = 0; i < header.size(); ++i)
      if (header[i] == name) return static_cast<int>(i);
    fail(name, "no such column (the header has: " + line + ")");
    return -1;
  };
  std::vector<int> c{column(x)};
  for (const auto& name : y) c.push_back(column(name));
  const int width = static_cast<int>(c.size());
  ys.assign(y.size(), {});
  long row = 1;
  while (std::getline(in, line)) {
    ++row;
    if (line.empty() || line == "\r") continue;
    const auto cells = split_csv_line(line);
    // (a row cut short is a damaged file, not cells left empty: refused, never dropped)
    const auto fields = std::count(line.begin(), line.end(), ',') + 1;
    if (fields < header_fields)
      fail(fmt::format("line {}", row), fmt::format("{} cells, the header has {}", fields, header_fields));
    std::vector<double> v(width);
    bool skip = false;
    for (int k = 0; k < width; ++k) {
      const std::string& s = c[k] < static_cast<int>(cells.size()) ? cells[c[k]] : std::string();
      if (s.empty()) {  // history.csv leaves a cell empty where it does not apply (elongation of a free body)
        skip = true;
        continue;
      }
      char* end = nullptr;
      v[k] = std::strtod(s.c_str(), &end);
      if (end == s.c_str() || *end != '\0' || !std::isfinite(v[k]))
        fail(fmt::format("line {}", row), fmt::format("\"{}\" is not a finite number", s));
    }
    if (skip) continue;
    xs.push_back(v[0]);
    for (int k = 1; k < width; ++k) ys[k - 1].push_back(v[k]);
  }
}

// The value at a dotted key ("body.viscoelastic.tau.0") of a TOML tree, or nullptr.
const Value* find_key(const Value& root, const std::string& key) {
  const Value* v = &root;
  std::istringstream parts(key);
  std::string part;
  while (std::getline(parts, part, '.')) {
    if (v->is_table()) {
      const auto& t = v->as_table();
      auto it = t.find(part);
      if (it == t.end()) return nullptr;
      v = &it->second;
    } else if (v->is_array()) {
      char* end = nullptr;
      const long i = std::strtol(part.c_str(), &end, 10);
      if (part.empty() || *end != '\0' || i < 0 || i >= static_cast<long>(v->as_array().size())) return nullptr;
      v = &v->as_array()[i];
    } else {
      return nullptr;
    }
  }
  return v;
}

// What history.csv has (../shared/interface.md): the fixed columns and one reaction triple per [[fix]].
bool history_column(const std::string& name) {
  static const std::regex columns(
      "step|time|force_[xyz]|elongation|kinetic_energy|reaction[0-9]+_[xyz]|lateral_strain");
  return std::regex_match(name, columns);
}

std::string number(double v) { return fmt::format("{:.17g}", v); }

}  // namespace

FitInput read_fit_input(const std::string& path, const std::vector<std::string>& overrides) {
  FitInput in;
  in.file = path;
  Value root = scene_reader::parse_toml(read_text(path), path);
  for (const auto& o : overrides) scene_reader::apply_override(root, o);
  if (!root.is_table() || !root.as_table().count("fit"))
    throw InputError(path, "fit", "missing: a fit needs a [fit] table (data, x, y, parameters)");
  const Value fit = root.as_table().at("fit");
  root.as_table().erase("fit");
  if (!fit.is_table()) throw InputError(path, "fit", "must be a table");
  for (const auto& [k, v] : fit.as_table())
    if (k != "data" && k != "x" && k != "y" && k != "parameters")
      throw InputError(path, "fit." + k, "unknown key (fit has data, x, y, parameters)");
  auto text = [&](const char* key) {
    auto it = fit.as_table().find(key);
    if (it == fit.as_table().end()) throw InputError(path, std::string("fit.") + key, "missing");
    if (!it->second.is_string() || it->second.as_string().str.empty())
      throw InputError(path, std::string("fit.") + key, "must be a non-empty string");
    return std::string(it->second.as_string().str);
  };
  in.data_path = text("data");
  in.x = text("x");
  // y: one column name, or several fitted together (e.g. ["elongation", "lateral_strain"]).
  {
    const Value& y = fit.as_table().count("y") ? fit.as_table().at("y") : Value();
    if (y.is_array()) {
      for (const auto& v : y.as_array()) {
        if (!v.is_string() || v.as_string().str.empty())
          throw InputError(path, "fit.y", "must be a column name or a list of column names");
        in.y.push_back(v.as_string().str);
      }
      if (in.y.empty()) throw InputError(path, "fit.y", "is an empty list");
    } else {
      in.y.push_back(text("y"));
    }
  }
  if (std::filesystem::path(in.data_path).is_relative())
    in.data_path = (std::filesystem::path(path).parent_path() / in.data_path).lexically_normal().string();
  if (in.data_path.empty() || std::filesystem::is_directory(in.data_path))
    throw InputError(path, "fit.data", "\"" + in.data_path + "\" is not a file");
  if (!std::ifstream(in.data_path))
    throw InputError(path, "fit.data", "\"" + in.data_path + "\": cannot open: " + std::strerror(errno));
  if (!history_column(in.x)) throw InputError(path, "fit.x", "\"" + in.x + "\" is not a history.csv column");
  for (std::size_t k = 0; k < in.y.size(); ++k) {
    if (!history_column(in.y[k])) throw InputError(path, "fit.y", "\"" + in.y[k] + "\" is not a history.csv column");
    if (in.y[k] == in.x) throw InputError(path, "fit.y", "\"" + in.y[k] + "\" is the same column as fit.x");
    for (std::size_t l = 0; l < k; ++l)
      if (in.y[l] == in.y[k]) throw InputError(path, "fit.y", "\"" + in.y[k] + "\" is listed twice");
  }

  // The scene itself must be valid before any forward run.
  in.scene_text = toml::format(root, std::numeric_limits<std::size_t>::max());
  parse_scene(in.scene_text, path);

  auto pit = fit.as_table().find("parameters");
  if (pit == fit.as_table().end() || !pit->second.is_table() || pit->second.as_table().empty())
    throw InputError(path, "fit.parameters", "missing: a table of \"scene.key\" = [lower, upper]");
  for (const auto& [key, bounds] : pit->second.as_table()) {
    const std::string name = "fit.parameters." + key;
    auto num = [](const Value& v, double& out) {
      if (v.is_floating()) return out = v.as_floating(), true;
      if (v.is_integer()) return out = static_cast<double>(v.as_integer()), true;
      return false;
    };
    FitParameter p{key, 0, 0, 0};
    if (!bounds.is_array() || bounds.as_array().size() != 2 || !num(bounds.as_array()[0], p.lower) ||
        !num(bounds.as_array()[1], p.upper))
      throw InputError(path, name, "must be [lower, upper], two numbers");
    if (!std::isfinite(p.lower) || !std::isfinite(p.upper) || !(p.lower < p.upper))
      throw InputError(path, name, "needs finite lower < upper");
    const Value* v = find_key(root, key);
    if (!v) throw InputError(path, name, "\"" + key + "\" is not a key of the scene (give it a start value there)");
    if (!num(*v, p.start)) throw InputError(path, name, "\"" + key + "\" is not a number in the scene");
    if (p.start < p.lower || p.start > p.upper)
      throw InputError(path, name, fmt::format("the scene's value {} is outside [{}, {}]", number(p.start),
                                               number(p.lower), number(p.upper)));
    in.parameters.push_back(p);
  }
  // Every parameter must reach the scene: set each to its bounds and to a value between them that is no whole
  // number, and read the scene (a key the schema does not know, a value it refuses at a bound, or a key that takes
  // whole numbers only, which no fit moves continuously, is bad input now, not failed forward runs later).
  for (std::size_t i = 0; i < in.parameters.size(); ++i)
    for (double b : {in.parameters[i].lower, in.parameters[i].upper,
                     in.parameters[i].lower + 0.3819660112501051 * (in.parameters[i].upper - in.parameters[i].lower)}) {
      std::vector<double> values;
      for (const auto& p : in.parameters) values.push_back(p.start);
      values[i] = b;
      try {
        parse_scene(in.scene_text, path, fit_overrides(in, values));
      } catch (const InputError& e) {
        throw InputError(path, "fit.parameters." + in.parameters[i].key,
                         fmt::format("the scene refuses the value {} in its bounds: {}", number(b), e.what()));
      }
    }

  read_columns(in.data_path, in.x, in.y, in.data_x, in.data_y, /*input_error=*/true);
  if (in.data_x.size() < in.parameters.size() + 1)
    throw InputError(in.data_path, "",
                     fmt::format("{} rows: fitting {} parameters needs more", in.data_x.size(), in.parameters.size()));
  for (std::size_t i = 1; i < in.data_x.size(); ++i)
    if (!(in.data_x[i] > in.data_x[i - 1]))
      throw InputError(in.data_path, in.x,
                       fmt::format("not strictly increasing (row {}: {} after {})", i + 1, number(in.data_x[i]),
                                   number(in.data_x[i - 1])));
  return in;
}

std::vector<std::string> fit_overrides(const FitInput& input, const std::vector<double>& values) {
  std::vector<std::string> set;
  for (std::size_t i = 0; i < input.parameters.size(); ++i)
    set.push_back(input.parameters[i].key + "=" + number(values[i]));
  return set;
}

std::string fitted_scene_text(const FitInput& input, const std::vector<double>& values) {
  return parse_scene(input.scene_text, input.file, fit_overrides(input, values)).text;
}

void read_history_columns(const std::string& path, const std::string& x, const std::vector<std::string>& y,
                          std::vector<double>& xs, std::vector<std::vector<double>>& ys) {
  xs.clear(), ys.clear();
  read_columns(path, x, y, xs, ys, /*input_error=*/false);
}

}  // namespace tissue
