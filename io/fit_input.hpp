// `tissue fit FIT.toml`: the experiment's scene plus a [fit] table (../shared/interface.md, "Fitting material
// parameters to a measured curve"), read and checked here, before any forward run: the measured CSV, the
// history.csv columns it matches, and the scene keys to fit with their bounds.
#pragma once
#include <string>
#include <vector>

namespace tissue {

struct FitParameter {
  std::string key;             // a dotted scene key, as --set takes it ("body.viscoelastic.tau.0")
  double lower, upper, start;  // bounds; start: the scene's value
};

struct FitInput {
  std::string file;               // FIT.toml
  std::string scene_text;         // the scene after --set, without [fit]
  std::string data_path;          // the measured CSV
  std::string x;                  // its x column, and the history.csv column it matches
  std::vector<std::string> y;     // its y columns (one, or several fitted together), history.csv columns too
  std::vector<double> data_x;                  // the measured curve, x strictly increasing
  std::vector<std::vector<double>> data_y;     // per y column, aligned with data_x
  std::vector<FitParameter> parameters;
};

// Throws InputError naming the file and key: FIT.toml unreadable or not a scene, no [fit], an unknown [fit] key,
// a CSV that cannot be read or lacks the named columns, x not strictly increasing, a y that is not a history.csv
// column, a parameter key that is not a number in the scene, bounds that do not hold its value.
FitInput read_fit_input(const std::string& path, const std::vector<std::string>& overrides);

// The scene with the parameters set to `values` (one per FitInput::parameters, in order): TOML text that
// parse_scene reads as is (fitted.toml), and the --set items that give the same scene from scene_text.
std::string fitted_scene_text(const FitInput& input, const std::vector<double>& values);
std::vector<std::string> fit_overrides(const FitInput& input, const std::vector<double>& values);

// The columns x and y[k] of a history.csv (rows with an empty cell skipped); empty vectors when the file has no
// rows. Throws std::runtime_error when it cannot be read or lacks a column.
void read_history_columns(const std::string& path, const std::string& x, const std::vector<std::string>& y,
                          std::vector<double>& xs, std::vector<std::vector<double>>& ys);

}  // namespace tissue
