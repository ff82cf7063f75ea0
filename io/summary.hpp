// summary.json: one JSON object per run, written by rank 0 atomically (temporary name, then rename). Keys per
// ../shared/interface.md; a key that does not apply to the scene is null; floats round-trip (17 digits).
#pragma once
#include <nlohmann/json.hpp>
#include <string>

namespace tissue {

// Writes `summary` to path through path + ".tmp" and a rename. Throws OutputError on failure (io/atomic_file.hpp).
void write_json_atomically(const std::string& path, const nlohmann::json& summary);

// Peak resident memory of this process in bytes (getrusage).
long peak_memory_bytes();

}  // namespace tissue
