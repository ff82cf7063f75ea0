// The --set override engine (internal to io/): "dotted.key=VALUE" strings applied to the parsed scene before the
// schema reads it.
#pragma once
#include <string>

#include "io/toml_text.hpp"

namespace tissue::scene_reader {

// Sets the dotted key of `item` ("body.molecules=[4,4,4]", "load.0.force=[0,0,1]") in `root`: VALUE in TOML syntax,
// anything that is not TOML taken as a bare string; a missing table on the way is created, an array is walked by
// index. Throws InputError("--set", key, ...) on a malformed item or a path that does not fit the scene.
void apply_override(Value& root, const std::string& item);

}  // namespace tissue::scene_reader
