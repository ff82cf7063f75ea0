// The scene's TOML text before the schema sees it (internal to io/): the byte checks made on the raw text, so
// that the TOML parser never sees binary bytes, bad UTF-8, absurd size or nesting, and the parse itself, whose
// errors become one InputError line.
#pragma once
#include <cstddef>
#include <map>
#include <string>
#include <vector>

#include <toml.hpp>

namespace tissue::scene_reader {

// std::map tables keep the serialized text (Scene::text) in a fixed, sorted order.
using Value = toml::basic_value<toml::discard_comments, std::map, std::vector>;
using Table = Value::table_type;

inline constexpr std::size_t max_scene_bytes = 16u << 20;  // a scene is a page of text, not a data file

// "a boolean", "an integer", ... "a table": a value's type for messages.
const char* type_name(const Value& v);

// Throws InputError(file, "", ...) on what the TOML parser should never see: more than max_scene_bytes, a control
// byte, invalid UTF-8, brackets nested too deep.
void check_text(const std::string& text, const std::string& file);

// check_text, then the parse; a parse error becomes InputError(file, "", "not valid TOML, line N: ...").
Value parse_toml(const std::string& text, const std::string& file);

}  // namespace tissue::scene_reader
