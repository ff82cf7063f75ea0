// The --set override engine (io/scene_overrides.hpp).
#include "io/scene_overrides.hpp"

#include <fmt/format.h>

#include <sstream>
#include <vector>

#include "src/model/scene.hpp"

namespace tissue::scene_reader {

namespace {

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

}  // namespace

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

}  // namespace tissue::scene_reader
