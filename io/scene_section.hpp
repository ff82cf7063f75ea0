// The generic section reader (internal to io/): one TOML table of the scene and its dotted path, with typed
// getters and range checks that name the file and the key in every InputError. The schema (io/scene.cpp) is
// written in its terms.
#pragma once
#include <array>
#include <initializer_list>
#include <optional>
#include <string>
#include <vector>

#include "io/toml_text.hpp"
#include "src/model/scene.hpp"

namespace tissue::scene_reader {

// "a, b, c": names for messages.
std::string join(const std::vector<std::string>& names, const char* separator = ", ");

// One TOML table of the scene and its dotted path: typed getters that name the key in every error.
class Section {
public:
  Section(const std::string& file, const Value& v, std::string path);

  std::string key(const std::string& k) const { return path_.empty() ? k : path_ + "." + k; }
  const std::string& path() const { return path_; }
  const std::string& file() const { return file_; }
  [[noreturn]] void fail(const std::string& k, const std::string& problem) const {
    throw InputError(file_, key(k), problem);
  }
  bool has(const std::string& k) const { return table_->count(k) != 0; }
  const Value& get(const std::string& k) const { return table_->at(k); }

  // Unknown keys are errors (a typo must not silently fall back to a default).
  void allow(std::initializer_list<const char*> keys) const;
  void require(const std::string& k, const std::string& why = "") const;

  // Typed getters: nothing when the key is absent, an error when it has another type.
  std::optional<double> number(const std::string& k) const;  // an integer or a float, finite
  std::optional<long> integer(const std::string& k) const;
  std::optional<bool> boolean(const std::string& k) const;
  std::optional<std::string> string(const std::string& k) const;
  // A string from a fixed list of names.
  std::optional<std::string> choice(const std::string& k, const std::vector<std::string>& names) const;
  std::optional<Vec3> vec3(const std::string& k) const;
  std::optional<std::array<long, 3>> int3(const std::string& k) const;
  std::optional<std::vector<std::string>> strings(const std::string& k) const;
  Section table(const std::string& k) const { return Section(file_, get(k), key(k)); }
  // [[k]]: an array of tables, each named k[i] in messages.
  std::vector<Section> tables(const std::string& k) const;

  // Range checks, each naming the key and the value.
  void positive(const std::string& k, double x) const;
  void non_negative(const std::string& k, double x) const;
  void at_least(const std::string& k, long x, long min) const;
  void positive3(const std::string& k, const Vec3& x) const;

private:
  double to_number(const Value& v, const std::string& k, const char* want) const;
  static std::string describe(const Value& v);

  std::string file_, path_;
  const Table* table_ = nullptr;
};

}  // namespace tissue::scene_reader
