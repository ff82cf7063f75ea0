// The scene reader: a TOML file (or text, with --set overrides) into the Scene of src/model/scene.hpp, checked
// once here against the schema of ../shared/interface.md so that the rest of the program trusts it.
#pragma once
#include <string>
#include <vector>

#include "src/model/scene.hpp"

namespace tissue {

// Reads and validates a scene. `overrides` are --set "dotted.key=VALUE" strings (VALUE in TOML syntax, a bare
// word taken as a string). Throws InputError naming file and key for any problem: unreadable file, not TOML,
// unknown key, wrong type, value out of range, unknown face/topology/method/material/solver.
Scene read_scene(const std::string& path, const std::vector<std::string>& overrides = {});
// The same from text already in memory (checkpoints keep the scene text); `name` is used in messages.
Scene parse_scene(const std::string& text, const std::string& name,
                  const std::vector<std::string>& overrides = {});

}  // namespace tissue
