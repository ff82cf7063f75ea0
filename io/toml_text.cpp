// The byte checks on a scene's raw text and its TOML parse (io/toml_text.hpp).
#include "io/toml_text.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cstring>
#include <sstream>

#include "src/model/scene.hpp"

namespace tissue::scene_reader {

namespace {

const int max_nesting = 64;  // deep [[[[ would overflow the recursive TOML parser

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

}  // namespace

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

}  // namespace tissue::scene_reader
