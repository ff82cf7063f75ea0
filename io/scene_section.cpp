// The generic section reader (io/scene_section.hpp).
#include "io/scene_section.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace tissue::scene_reader {

std::string join(const std::vector<std::string>& names, const char* separator) {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : separator) + n;
  return s;
}

Section::Section(const std::string& file, const Value& v, std::string path) : file_(file), path_(std::move(path)) {
  if (!v.is_table()) throw InputError(file_, path_, std::string("expected a table, got ") + type_name(v));
  table_ = &v.as_table();
}

void Section::allow(std::initializer_list<const char*> keys) const {
  for (const auto& kv : *table_) {
    bool known = false;
    for (const char* k : keys) known = known || kv.first == k;
    if (!known) {
      std::vector<std::string> names(keys.begin(), keys.end());
      fail(kv.first, "unknown key (known here: " + join(names) + ")");
    }
  }
}

void Section::require(const std::string& k, const std::string& why) const {
  if (!has(k)) fail(k, "missing" + (why.empty() ? std::string() : " (" + why + ")"));
}

std::optional<double> Section::number(const std::string& k) const {
  if (!has(k)) return std::nullopt;
  return to_number(get(k), k, "expected a number");
}

std::optional<long> Section::integer(const std::string& k) const {
  if (!has(k)) return std::nullopt;
  const Value& v = get(k);
  if (!v.is_integer()) fail(k, std::string("expected an integer, got ") + type_name(v));
  return static_cast<long>(v.as_integer());
}

std::optional<bool> Section::boolean(const std::string& k) const {
  if (!has(k)) return std::nullopt;
  const Value& v = get(k);
  if (!v.is_boolean()) fail(k, std::string("expected true or false, got ") + type_name(v));
  return v.as_boolean();
}

std::optional<std::string> Section::string(const std::string& k) const {
  if (!has(k)) return std::nullopt;
  const Value& v = get(k);
  if (!v.is_string()) fail(k, std::string("expected a string, got ") + type_name(v));
  return v.as_string().str;
}

std::optional<std::string> Section::choice(const std::string& k, const std::vector<std::string>& names) const {
  auto s = string(k);
  if (s && std::find(names.begin(), names.end(), *s) == names.end())
    fail(k, fmt::format("unknown value \"{}\" (one of: {})", *s, join(names)));
  return s;
}

std::optional<Vec3> Section::vec3(const std::string& k) const {
  if (!has(k)) return std::nullopt;
  const Value& v = get(k);
  const char* want = "expected an array of 3 numbers";
  if (!v.is_array() || v.as_array().size() != 3) fail(k, std::string(want) + ", got " + describe(v));
  Vec3 x;
  for (int a = 0; a < 3; ++a) x[a] = to_number(v.as_array()[a], k, want);
  return x;
}

std::optional<std::array<long, 3>> Section::int3(const std::string& k) const {
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

std::optional<std::vector<std::string>> Section::strings(const std::string& k) const {
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

std::vector<Section> Section::tables(const std::string& k) const {
  std::vector<Section> out;
  if (!has(k)) return out;
  const Value& v = get(k);
  if (!v.is_array()) fail(k, fmt::format("expected an array of tables ([[{}]]), got {}", k, type_name(v)));
  const auto& a = v.as_array();
  for (std::size_t i = 0; i < a.size(); ++i) out.emplace_back(file_, a[i], fmt::format("{}[{}]", key(k), i));
  return out;
}

void Section::positive(const std::string& k, double x) const {
  if (!(x > 0)) fail(k, fmt::format("must be > 0, got {}", x));
}

void Section::non_negative(const std::string& k, double x) const {
  if (!(x >= 0)) fail(k, fmt::format("must be >= 0, got {}", x));
}

void Section::at_least(const std::string& k, long x, long min) const {
  if (x < min) fail(k, fmt::format("must be >= {}, got {}", min, x));
}

void Section::positive3(const std::string& k, const Vec3& x) const {
  for (double c : x)
    if (!(c > 0)) fail(k, fmt::format("every component must be > 0, got [{}, {}, {}]", x[0], x[1], x[2]));
}

double Section::to_number(const Value& v, const std::string& k, const char* want) const {
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

std::string Section::describe(const Value& v) {
  return v.is_array() ? fmt::format("{} elements", v.as_array().size()) : type_name(v);
}

}  // namespace tissue::scene_reader
