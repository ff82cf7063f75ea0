// The scene reader: every field of a full scene, size -> spacing, presets, --set overrides, the text round
// trip, and a table of malformed scenes that must each give one InputError naming the right key.
#include "io/scene.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "src/model/material.hpp"

using namespace tissue;

namespace {

// The smallest valid scene; the malformed cases below add to it or break it.
const std::string base = R"(
[body]
molecules = [3, 3, 3]
spacing = [0.1, 0.1, 0.1]
youngs_modulus = 1e5

[[fix]]
face = "z+"
)";

const std::string full = R"(
title = "Table 2: 10 x 10 x 10 box, face diagonals"

[body]
shape = "box"
molecules = [10, 11, 12]
spacing = [0.111111, 0.111111, 0.0955556]
topology = "body-diagonals"
material = "custom"
youngs_modulus = 1.0e5
density = 1200
offset = [1, -2.5, 3]

[[body.region]]
lo = [0, 0, 0]
hi = [0.5, 0.5, 0.5]
material = "cartilage"
youngs_modulus = 2e6

[[body.region]]
lo = [0.1, 0.2, 0.3]
hi = [0.4, 0.5, 0.6]
youngs_modulus = 7e4
density = 900.5

[calibration]
method = "manual"
divisor = 3.75
stiffness = { edge = 1.0, face = 0.5, body = 0.25 }
tolerance = 1e-4
max_updates = 20

[[fix]]
face = "z+"
mode = "clamped"

[[fix]]
face = "x-"
mode = "roller"

[[load]]
face = "z-"
force = [0.0, 0.0, -1000.0]
distribution = "traction"

[[load]]
face = "y+"
force = [1, 2, 3]
distribution = "equal"

[physics]
gravity = [0.0, 0.0, -9.81]
viscosity = 0.5

[solver]
kind = "relaxation"
tolerance = 1e-9
time_step = 1e-4
steps = 500
max_iterations = 20000
load_steps = 4
allow_unstable_time_step = true

[[obstacle]]
kind = "plane"
point = [0.0, 0.0, -0.01]
normal = [0.0, 0.0, 1.0]

[[obstacle]]
kind = "sphere"
center = [0.5, 0.5, 2]
radius = 0.25
stiffness = 1e3

[output]
directory = "out/table2"
snapshot_every = 10
checkpoint_every = 100
fields = ["positions", "velocities", "connection_strain"]
progress = false
)";

void expect_vec(const Vec3& got, const Vec3& want) {
  for (int a = 0; a < 3; ++a) EXPECT_DOUBLE_EQ(got[a], want[a]) << "component " << a;
}

// Every field of two scenes, exactly (the text round trip must be bit for bit).
void expect_same(const Scene& a, const Scene& b) {
  EXPECT_EQ(a.title, b.title);
  EXPECT_EQ(a.body.shape, b.body.shape);
  EXPECT_EQ(a.body.molecules, b.body.molecules);
  EXPECT_EQ(a.body.spacing, b.body.spacing);
  EXPECT_EQ(a.body.topology, b.body.topology);
  EXPECT_EQ(a.body.material, b.body.material);
  EXPECT_EQ(a.body.youngs_modulus, b.body.youngs_modulus);
  EXPECT_EQ(a.body.density, b.body.density);
  EXPECT_EQ(a.body.offset, b.body.offset);
  ASSERT_EQ(a.body.regions.size(), b.body.regions.size());
  for (std::size_t i = 0; i < a.body.regions.size(); ++i) {
    EXPECT_EQ(a.body.regions[i].lo, b.body.regions[i].lo);
    EXPECT_EQ(a.body.regions[i].hi, b.body.regions[i].hi);
    EXPECT_EQ(a.body.regions[i].material, b.body.regions[i].material);
    EXPECT_EQ(a.body.regions[i].youngs_modulus, b.body.regions[i].youngs_modulus);
    EXPECT_EQ(a.body.regions[i].density, b.body.regions[i].density);
  }
  EXPECT_EQ(a.calibration.method, b.calibration.method);
  EXPECT_EQ(a.calibration.divisor, b.calibration.divisor);
  EXPECT_EQ(a.calibration.stiffness, b.calibration.stiffness);
  EXPECT_EQ(a.calibration.tolerance, b.calibration.tolerance);
  EXPECT_EQ(a.calibration.max_updates, b.calibration.max_updates);
  ASSERT_EQ(a.fixes.size(), b.fixes.size());
  for (std::size_t i = 0; i < a.fixes.size(); ++i) {
    EXPECT_EQ(a.fixes[i].face, b.fixes[i].face);
    EXPECT_EQ(a.fixes[i].mode, b.fixes[i].mode);
  }
  ASSERT_EQ(a.loads.size(), b.loads.size());
  for (std::size_t i = 0; i < a.loads.size(); ++i) {
    EXPECT_EQ(a.loads[i].face, b.loads[i].face);
    EXPECT_EQ(a.loads[i].force, b.loads[i].force);
    EXPECT_EQ(a.loads[i].distribution, b.loads[i].distribution);
  }
  EXPECT_EQ(a.physics.gravity, b.physics.gravity);
  EXPECT_EQ(a.physics.viscosity, b.physics.viscosity);
  ASSERT_EQ(a.obstacles.size(), b.obstacles.size());
  for (std::size_t i = 0; i < a.obstacles.size(); ++i) {
    EXPECT_EQ(a.obstacles[i].kind, b.obstacles[i].kind);
    EXPECT_EQ(a.obstacles[i].point, b.obstacles[i].point);
    EXPECT_EQ(a.obstacles[i].normal, b.obstacles[i].normal);
    EXPECT_EQ(a.obstacles[i].center, b.obstacles[i].center);
    EXPECT_EQ(a.obstacles[i].radius, b.obstacles[i].radius);
    EXPECT_EQ(a.obstacles[i].stiffness, b.obstacles[i].stiffness);
  }
  EXPECT_EQ(a.solver.kind, b.solver.kind);
  EXPECT_EQ(a.solver.tolerance, b.solver.tolerance);
  EXPECT_EQ(a.solver.time_step, b.solver.time_step);
  EXPECT_EQ(a.solver.steps, b.solver.steps);
  EXPECT_EQ(a.solver.max_iterations, b.solver.max_iterations);
  EXPECT_EQ(a.solver.load_steps, b.solver.load_steps);
  EXPECT_EQ(a.output.directory, b.output.directory);
  EXPECT_EQ(a.output.snapshot_every, b.output.snapshot_every);
  EXPECT_EQ(a.output.checkpoint_every, b.output.checkpoint_every);
  EXPECT_EQ(a.output.fields, b.output.fields);
  EXPECT_EQ(a.output.progress, b.output.progress);
}

// The message of the InputError that parsing throws ("" when nothing is thrown).
std::string error_of(const std::string& text, const std::vector<std::string>& overrides = {}) {
  try {
    parse_scene(text, "scene.toml", overrides);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(Scene, FullSceneEveryField) {
  Scene s = parse_scene(full, "full.toml");
  EXPECT_EQ(s.file, "full.toml");
  EXPECT_EQ(s.title, "Table 2: 10 x 10 x 10 box, face diagonals");
  EXPECT_EQ(s.body.shape, BodySpec::Shape::box);
  EXPECT_EQ(s.body.molecules, (std::array<long, 3>{10, 11, 12}));
  expect_vec(s.body.spacing, {0.111111, 0.111111, 0.0955556});
  EXPECT_EQ(s.body.topology, "body-diagonals");
  EXPECT_EQ(s.body.material, "custom");
  EXPECT_DOUBLE_EQ(s.body.youngs_modulus, 1e5);
  EXPECT_DOUBLE_EQ(s.body.density, 1200);
  expect_vec(s.body.offset, {1, -2.5, 3});
  ASSERT_EQ(s.body.regions.size(), 2u);
  expect_vec(s.body.regions[0].lo, {0, 0, 0});
  expect_vec(s.body.regions[0].hi, {0.5, 0.5, 0.5});
  EXPECT_EQ(s.body.regions[0].material, "cartilage");
  EXPECT_DOUBLE_EQ(s.body.regions[0].youngs_modulus, 2e6);
  EXPECT_DOUBLE_EQ(s.body.regions[0].density, find_tissue("cartilage")->density);
  expect_vec(s.body.regions[1].lo, {0.1, 0.2, 0.3});
  expect_vec(s.body.regions[1].hi, {0.4, 0.5, 0.6});
  EXPECT_EQ(s.body.regions[1].material, "custom");
  EXPECT_DOUBLE_EQ(s.body.regions[1].youngs_modulus, 7e4);
  EXPECT_DOUBLE_EQ(s.body.regions[1].density, 900.5);

  EXPECT_EQ(s.calibration.method, "manual");
  EXPECT_DOUBLE_EQ(s.calibration.divisor, 3.75);
  EXPECT_EQ(s.calibration.stiffness,
            (std::map<std::string, double>{{"edge", 1.0}, {"face", 0.5}, {"body", 0.25}}));
  EXPECT_DOUBLE_EQ(s.calibration.tolerance, 1e-4);
  EXPECT_EQ(s.calibration.max_updates, 20);

  ASSERT_EQ(s.fixes.size(), 2u);
  EXPECT_EQ(s.fixes[0].face, "z+");
  EXPECT_EQ(s.fixes[0].mode, FixSpec::Mode::clamped);
  EXPECT_EQ(s.fixes[1].face, "x-");
  EXPECT_EQ(s.fixes[1].mode, FixSpec::Mode::roller);
  ASSERT_EQ(s.loads.size(), 2u);
  EXPECT_EQ(s.loads[0].face, "z-");
  expect_vec(s.loads[0].force, {0, 0, -1000});
  EXPECT_EQ(s.loads[0].distribution, LoadSpec::Distribution::traction);
  EXPECT_EQ(s.loads[1].face, "y+");
  expect_vec(s.loads[1].force, {1, 2, 3});
  EXPECT_EQ(s.loads[1].distribution, LoadSpec::Distribution::equal);

  ASSERT_TRUE(s.physics.gravity);
  expect_vec(*s.physics.gravity, {0, 0, -9.81});
  ASSERT_TRUE(s.physics.viscosity);
  EXPECT_DOUBLE_EQ(*s.physics.viscosity, 0.5);

  EXPECT_EQ(s.solver.kind, "relaxation");
  EXPECT_DOUBLE_EQ(s.solver.tolerance, 1e-9);
  ASSERT_TRUE(s.solver.time_step);
  EXPECT_DOUBLE_EQ(*s.solver.time_step, 1e-4);
  EXPECT_EQ(s.solver.steps, 500);
  EXPECT_EQ(s.solver.max_iterations, 20000);
  EXPECT_EQ(s.solver.load_steps, 4);
  EXPECT_TRUE(s.solver.allow_unstable_time_step);

  ASSERT_EQ(s.obstacles.size(), 2u);
  EXPECT_EQ(s.obstacles[0].kind, ObstacleSpec::Kind::plane);
  expect_vec(s.obstacles[0].point, {0, 0, -0.01});
  expect_vec(s.obstacles[0].normal, {0, 0, 1});
  EXPECT_DOUBLE_EQ(s.obstacles[0].stiffness, 0.0);
  EXPECT_EQ(s.obstacles[1].kind, ObstacleSpec::Kind::sphere);
  expect_vec(s.obstacles[1].center, {0.5, 0.5, 2});
  EXPECT_DOUBLE_EQ(s.obstacles[1].radius, 0.25);
  EXPECT_DOUBLE_EQ(s.obstacles[1].stiffness, 1e3);

  EXPECT_EQ(s.output.directory, "out/table2");
  EXPECT_EQ(s.output.snapshot_every, 10);
  EXPECT_EQ(s.output.checkpoint_every, 100);
  EXPECT_EQ(s.output.fields, (std::vector<std::string>{"positions", "velocities", "connection_strain"}));
  EXPECT_FALSE(s.output.progress);
}

TEST(Scene, Defaults) {
  Scene s = parse_scene(base, "base.toml");
  EXPECT_EQ(s.title, "");
  EXPECT_EQ(s.body.shape, BodySpec::Shape::box);
  EXPECT_EQ(s.body.topology, "face-diagonals");
  EXPECT_EQ(s.body.material, "custom");
  EXPECT_DOUBLE_EQ(s.body.density, 1000.0);
  expect_vec(s.body.offset, {0, 0, 0});
  EXPECT_TRUE(s.body.regions.empty());
  EXPECT_EQ(s.calibration.method, "linear");
  EXPECT_TRUE(s.calibration.stiffness.empty());
  EXPECT_EQ(s.fixes[0].mode, FixSpec::Mode::clamped);
  EXPECT_TRUE(s.loads.empty());
  EXPECT_FALSE(s.physics.gravity);
  EXPECT_FALSE(s.physics.viscosity);
  EXPECT_TRUE(s.obstacles.empty());
  EXPECT_EQ(s.solver.kind, "static");
  EXPECT_FALSE(s.solver.time_step);
  EXPECT_EQ(s.solver.load_steps, 1);
  EXPECT_FALSE(s.solver.allow_unstable_time_step);
  EXPECT_EQ(s.output.directory, "out");
  EXPECT_TRUE(s.output.progress);
  // A dynamic run may leave everything free.
  Scene d = parse_scene(
      "[body]\nmolecules = [2,2,2]\nsize = [1,1,1]\nyoungs_modulus = 1\n[solver]\nkind = \"dynamic\"", "d.toml");
  EXPECT_TRUE(d.fixes.empty());
}

TEST(Scene, SizeGivesSpacing) {
  Scene s = parse_scene(
      "[body]\nmolecules = [10, 5, 2]\nsize = [1, 2.0, 0.86]\nyoungs_modulus = 1e5\n"
      "[[fix]]\nface = \"x-\"\n",
      "size.toml");
  EXPECT_DOUBLE_EQ(s.body.spacing[0], 1.0 / 9);
  EXPECT_DOUBLE_EQ(s.body.spacing[1], 0.5);
  EXPECT_DOUBLE_EQ(s.body.spacing[2], 0.86);
}

TEST(Scene, PresetDefaultsAndOverrides) {
  const std::string body = "[body]\nmolecules = [3,3,3]\nspacing = [1,1,1]\nmaterial = \"tendon\"\n";
  const std::string fix = "[[fix]]\nface = \"x-\"\n";
  const TissuePreset* tendon = find_tissue("tendon");
  ASSERT_NE(tendon, nullptr);
  Scene s = parse_scene(body + fix, "preset.toml");
  EXPECT_EQ(s.body.material, "tendon");
  EXPECT_DOUBLE_EQ(s.body.youngs_modulus, tendon->youngs_modulus);
  EXPECT_DOUBLE_EQ(s.body.density, tendon->density);
  Scene e = parse_scene(body + "youngs_modulus = 123\n" + fix, "preset.toml");
  EXPECT_DOUBLE_EQ(e.body.youngs_modulus, 123);
  EXPECT_DOUBLE_EQ(e.body.density, tendon->density);
  Scene r = parse_scene(body + "density = 987\n" + fix, "preset.toml");
  EXPECT_DOUBLE_EQ(r.body.youngs_modulus, tendon->youngs_modulus);
  EXPECT_DOUBLE_EQ(r.body.density, 987);
  // A preset given by --set.
  Scene o = parse_scene(base, "base.toml", {"body.material=liver"});
  EXPECT_EQ(o.body.material, "liver");
  EXPECT_DOUBLE_EQ(o.body.youngs_modulus, 1e5);
  EXPECT_DOUBLE_EQ(o.body.density, find_tissue("liver")->density);
}

TEST(Scene, SetOverrides) {
  const std::string scene = base + "[[load]]\nface = \"z-\"\nforce = [0, 0, -1]\n";
  Scene s = parse_scene(scene, "base.toml",
                        {"body.youngs_modulus=2.5e6",        // scalar
                         "body.molecules=[20,21,22]",        // array
                         "solver.kind=relaxation",           // bare string
                         "output.directory=\"quoted dir\"",  // TOML string
                         "physics.gravity=[0,0,-9.81]",      // a new table
                         "calibration.stiffness.edge=2",     // nested new tables
                         "load.0.force=[0,0,-5]",            // an element of [[load]]
                         "fix.0.mode=roller", "title=with = sign"});
  EXPECT_DOUBLE_EQ(s.body.youngs_modulus, 2.5e6);
  EXPECT_EQ(s.body.molecules, (std::array<long, 3>{20, 21, 22}));
  EXPECT_EQ(s.solver.kind, "relaxation");
  EXPECT_EQ(s.output.directory, "quoted dir");
  ASSERT_TRUE(s.physics.gravity);
  expect_vec(*s.physics.gravity, {0, 0, -9.81});
  EXPECT_DOUBLE_EQ(s.calibration.stiffness.at("edge"), 2.0);
  expect_vec(s.loads[0].force, {0, 0, -5});
  EXPECT_EQ(s.fixes[0].mode, FixSpec::Mode::roller);
  EXPECT_EQ(s.title, "with = sign");
  // Later overrides win; the text keeps the overridden values.
  Scene t = parse_scene(scene, "base.toml", {"solver.steps=5", "solver.steps=7"});
  EXPECT_EQ(t.solver.steps, 7);
  EXPECT_EQ(parse_scene(t.text, "again").solver.steps, 7);
}

TEST(Scene, RoundTripThroughText) {
  for (const auto& text : {full, base}) {
    Scene a =
        parse_scene(text, "a.toml", {"body.youngs_modulus=0.1", "body.offset=[0.3, 1e-17, 2.000000000000001]"});
    Scene b = parse_scene(a.text, "b.toml");
    expect_same(a, b);
    EXPECT_EQ(a.text, b.text);
    EXPECT_EQ(b.body.youngs_modulus, 0.1);
    EXPECT_EQ(b.body.offset[2], 2.000000000000001);
  }
}

TEST(Scene, Faces) {
  int axis = -1, side = -1;
  EXPECT_TRUE(parse_face("x-", axis, side));
  EXPECT_EQ(axis, 0);
  EXPECT_EQ(side, 0);
  EXPECT_TRUE(parse_face("z+", axis, side));
  EXPECT_EQ(axis, 2);
  EXPECT_EQ(side, 1);
  EXPECT_TRUE(parse_face("y+", axis, side));
  EXPECT_EQ(axis, 1);
  for (const char* bad : {"", "x", "w+", "x*", "x+ ", "X+", "z--"})
    EXPECT_FALSE(parse_face(bad, axis, side)) << bad;
}

// Malformed scenes: each must throw InputError whose one-line message names the key.
struct Bad {
  std::string text;
  std::string key;  // what the message must contain
  std::vector<std::string> overrides = {};
};

TEST(Scene, MalformedInputs) {
  const std::string body_head = "[body]\nmolecules = [3,3,3]\nspacing = [1,1,1]\n";
  const std::string fix = "[[fix]]\nface = \"z+\"\n";
  const std::vector<Bad> cases = {
      // not TOML / structure
      {"this is not toml", "not valid TOML"},
      {"[body\nmolecules = [3,3,3]", "line 1"},
      {"a = 1\na = 2\n" + base, "not valid TOML"},
      {"x = [" + std::string(1000, '[') + std::string(1001, ']'), "nested"},
      {std::string("title = \"a\0b\"\n", 14) + base, "control byte"},
      {"title = \"\xff\xfe\"\n" + base, "UTF-8"},
      {"", "body"},
      {"# only a comment\n", "body"},
      {"title = 1\n" + base, "title"},
      {"bogus = 1\n" + base, "bogus"},
      {"body = 5\n", "body"},
      // body
      {"[body]\nshape = \"mesh\"\n", "body.file"},
      {"[body]\nshape = \"mesh\"\nfile = \"no_such.msh\"\n", "body.file"},
      {body_head + "youngs_modulus = 1\nseed = 3\n" + fix, "body.seed"},
      {"[body]\nshape = \"ball\"\n", "body.shape"},
      {body_head + "youngs_modulus = 1\ncolour = \"red\"\n" + fix, "body.colour"},
      {"[body]\nspacing = [1,1,1]\nyoungs_modulus = 1\n" + fix, "body.molecules"},
      {"[body]\nmolecules = [0,3,3]\nspacing = [1,1,1]\nyoungs_modulus = 1\n" + fix, "body.molecules"},
      {"[body]\nmolecules = [1,3,3]\nspacing = [1,1,1]\nyoungs_modulus = 1\n" + fix, "body.molecules"},
      {"[body]\nmolecules = [3,3]\nspacing = [1,1,1]\nyoungs_modulus = 1\n" + fix, "body.molecules"},
      {"[body]\nmolecules = [3,3,3.5]\nspacing = [1,1,1]\nyoungs_modulus = 1\n" + fix, "body.molecules"},
      {"[body]\nmolecules = \"3x3x3\"\nspacing = [1,1,1]\nyoungs_modulus = 1\n" + fix, "body.molecules"},
      {"[body]\nmolecules = [2000,2000,2000]\nspacing = [1,1,1]\nyoungs_modulus = 1\n" + fix, "body.molecules"},
      {"[body]\nmolecules = [3,3,3]\nyoungs_modulus = 1\n" + fix, "body.spacing"},
      {"[body]\nmolecules = [3,3,3]\nspacing = [1,0,1]\nyoungs_modulus = 1\n" + fix, "body.spacing"},
      {"[body]\nmolecules = [3,3,3]\nspacing = [1,1,nan]\nyoungs_modulus = 1\n" + fix, "body.spacing"},
      {"[body]\nmolecules = [3,3,3]\nsize = [1,1,inf]\nyoungs_modulus = 1\n" + fix, "body.size"},
      {"[body]\nmolecules = [3,3,3]\nsize = [1,1,-1]\nyoungs_modulus = 1\n" + fix, "body.size"},
      {"[body]\nmolecules = [3,3,3]\nsize = [1,1,1]\nspacing = [1,1,1]\nyoungs_modulus = 1\n" + fix, "body.size"},
      {body_head + "youngs_modulus = 1\ntopology = \"hexagonal\"\n" + fix, "body.topology"},
      {body_head + fix, "body.youngs_modulus"},
      {body_head + "youngs_modulus = -5\n" + fix, "body.youngs_modulus"},
      {body_head + "youngs_modulus = \"soft\"\n" + fix, "body.youngs_modulus"},
      {body_head + "youngs_modulus = nan\n" + fix, "body.youngs_modulus"},
      {body_head + "youngs_modulus = 1\ndensity = 0\n" + fix, "body.density"},
      {body_head + "material = \"unobtainium\"\n" + fix, "body.material"},
      {body_head + "youngs_modulus = 1\noffset = [0, 0]\n" + fix, "body.offset"},
      {base + "[[body.region]]\nlo = [0,0,0]\nhi = [1,1,1]\n", "body.region[0].youngs_modulus"},
      {base + "[[body.region]]\nlo = [0,0,0]\nhi = [1,1,1]\nyoungs_modulus = 1\n"
              "[[body.region]]\nlo = [0,0,0]\nhi = [1,-1,1]\nyoungs_modulus = 1\n",
       "body.region[1].hi"},
      {base + "[[body.region]]\nhi = [1,1,1]\nyoungs_modulus = 1\n", "body.region[0].lo"},
      {base + "[[body.region]]\nlo = [0,0,0]\nhi = [1,1,1]\nmaterial = \"tendon\"\nE = 1\n", "body.region[0].E"},
      // calibration
      {base + "[calibration]\nmethod = \"guess\"\n", "calibration.method"},
      {base + "[calibration]\nmethod = 3\n", "calibration.method"},
      {base + "[calibration]\ndivisor = 0\n", "calibration.divisor"},
      {base + "[calibration]\ntolerance = -1\n", "calibration.tolerance"},
      {base + "[calibration]\nmax_updates = 0\n", "calibration.max_updates"},
      {base + "[calibration]\nmethod = \"manual\"\n", "calibration.stiffness"},
      {base + "[calibration]\nmethod = \"manual\"\nstiffness = { edge = 1 }\n", "calibration.stiffness.face"},
      {base + "[calibration]\nstiffness = { edge = 1, tet = 2 }\n", "calibration.stiffness.tet"},
      {base + "[calibration]\nstiffness = { edge = -1 }\n", "calibration.stiffness.edge"},
      {base + "[calibration]\nextra = 1\n", "calibration.extra"},
      // fixes and loads
      {base + "[[fix]]\nface = \"w+\"\n", "fix[1].face"},
      {base + "[[fix]]\nmode = \"roller\"\n", "fix[1].face"},
      {base + "[[fix]]\nface = \"x-\"\nmode = \"glued\"\n", "fix[1].mode"},
      {base + "[[fix]]\nface = \"z+\"\n", "fix[1].face"},
      {base + "[fix]\nface = \"z+\"\n", "fix"},
      {base + "[[load]]\nface = \"z+\"\nforce = [0,0,-1]\n", "load[0].face"},
      {base + "[[load]]\nface = \"z-\"\nforce = [0,0,0]\n", "load[0].force"},
      {base + "[[load]]\nface = \"z-\"\n", "load[0].force"},
      {base + "[[load]]\nface = \"z-\"\nforce = [0,0,\"a\"]\n", "load[0].force"},
      {base + "[[load]]\nface = \"z-\"\nforce = [0,0,-1]\ndistribution = \"lumped\"\n", "load[0].distribution"},
      {base + "[[load]]\nface = \"z-\"\nforce = [0,0,-1]\n[[load]]\nface = \"y-\"\nforce = [0,0,-inf]\n",
       "load[1].force"},
      // physics and obstacles
      {base + "[physics]\ngravity = [0, 0]\n", "physics.gravity"},
      {base + "[physics]\nviscosity = -1\n", "physics.viscosity"},
      {base + "[physics]\nmagnetism = true\n", "physics.magnetism"},
      {base + "[[obstacle]]\nkind = \"cube\"\n", "obstacle[0].kind"},
      {base + "[[obstacle]]\nkind = \"plane\"\npoint = [0,0,0]\nnormal = [0,0,0]\n", "obstacle[0].normal"},
      {base + "[[obstacle]]\nkind = \"plane\"\npoint = [0,0,0]\n", "obstacle[0].normal"},
      {base + "[[obstacle]]\nkind = \"sphere\"\ncenter = [0,0,0]\nradius = 0\n", "obstacle[0].radius"},
      {base + "[[obstacle]]\nkind = \"sphere\"\ncenter = [0,0,0]\nradius = 1\nnormal = [0,0,1]\n",
       "obstacle[0].normal"},
      {base + "[[obstacle]]\nkind = \"sphere\"\ncenter = [0,0,0]\nradius = 1\nstiffness = -3\n",
       "obstacle[0].stiffness"},
      // solver
      {base + "[solver]\nkind = \"quasi\"\n", "solver.kind"},
      {base + "[solver]\ntolerance = 1\n", "solver.tolerance"},
      {base + "[solver]\ntolerance = 0\n", "solver.tolerance"},
      {base + "[solver]\ntime_step = 0\n", "solver.time_step"},
      {base + "[solver]\nsteps = -1\n", "solver.steps"},
      {base + "[solver]\nsteps = 1.5\n", "solver.steps"},
      {base + "[solver]\nmax_iterations = -1\n", "solver.max_iterations"},
      {base + "[solver]\nload_steps = 0\n", "solver.load_steps"},
      {base + "[solver]\nallow_unstable_time_step = 1\n", "solver.allow_unstable_time_step"},
      {base + "[solver]\nallow_unstable_time_step = \"yes\"\n", "solver.allow_unstable_time_step"},
      {base + "[solver]\nallow_unstable_timestep = true\n", "solver.allow_unstable_timestep"},
      {"[body]\nmolecules = [3,3,3]\nspacing = [1,1,1]\nyoungs_modulus = 1\n", "solver.kind"},
      {"[body]\nmolecules = [3,3,3]\nspacing = [1,1,1]\nyoungs_modulus = 1\n[solver]\nkind = \"relaxation\"\n",
       "solver.kind"},
      // output
      {base + "[output]\ndirectory = \"\"\n", "output.directory"},
      {base + "[output]\nsnapshot_every = -1\n", "output.snapshot_every"},
      {base + "[output]\ncheckpoint_every = -2\n", "output.checkpoint_every"},
      {base + "[output]\nfields = [\"positions\", \"temperature\"]\n", "output.fields"},
      {base + "[output]\nfields = \"positions\"\n", "output.fields"},
      {base + "[output]\nprogress = \"yes\"\n", "output.progress"},
      // --set
      {base, "--set", {"body.youngs_modulus"}},
      {base, "--set", {"=5"}},
      {base, "--set", {"body..density=5"}},
      {base, "body.foo", {"body.foo=1"}},
      {base, "body.molecules", {"body.molecules=[20,20"}},
      {base, "solver.kind", {"solver.kind=[1,2]"}},
      {base, "--set", {"load.0.force=[0,0,1]"}},
      {base, "--set", {"fix.3.face=x-"}},
      {base, "--set", {"body.molecules.x=3"}},
      {base, "physics.gravity", {"physics.gravity=down"}},
  };
  ASSERT_GE(cases.size(), 40u);
  for (const auto& c : cases) {
    std::string msg = error_of(c.text, c.overrides);
    EXPECT_NE(msg, "") << "no error for:\n" << c.text;
    EXPECT_NE(msg.find(c.key), std::string::npos) << "message \"" << msg << "\" lacks \"" << c.key << "\" for:\n"
                                                  << c.text;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << "not one line: " << msg;
  }
}

TEST(Scene, ReadFileErrors) {
  namespace fs = std::filesystem;
  fs::path dir = fs::temp_directory_path() / ("scene_test_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  auto message = [](const std::string& path) -> std::string {
    try {
      read_scene(path);
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  };
  std::string missing = (dir / "missing.toml").string();
  EXPECT_NE(message(missing).find(missing), std::string::npos);
  EXPECT_NE(message(dir.string()).find("directory"), std::string::npos);
  // Binary garbage: every byte value.
  std::string garbage = (dir / "garbage.toml").string();
  {
    std::ofstream out(garbage, std::ios::binary);
    for (int i = 0; i < 4096; ++i) out.put(static_cast<char>((i * 7919 + 13) & 0xff));
  }
  std::string msg = message(garbage);
  EXPECT_NE(msg.find(garbage), std::string::npos) << msg;
  EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  // A good file reads, and remembers its path.
  std::string good = (dir / "good.toml").string();
  std::ofstream(good) << base;
  Scene s = read_scene(good, {"solver.kind=relaxation"});
  EXPECT_EQ(s.file, good);
  EXPECT_EQ(s.solver.kind, "relaxation");
  fs::remove_all(dir);
}

// Several bodies, the body key of fixes and loads, cyclic loads, molecule radius and contact keys.
TEST(Scene, SeveralBodiesAndPhysicsKeys) {
  const std::string two = R"(
[[body]]
molecules = [3, 3, 3]
spacing = [0.1, 0.1, 0.1]
youngs_modulus = 1e5
radius = 0.04
[[body]]
molecules = [2, 4, 3]
spacing = [0.2, 0.1, 0.1]
material = "cartilage"
offset = [1, 0, 0]
[physics]
contact = true
contact_stiffness = 1e3
contact_skin = 0.01
[[fix]]
face = "z+"
[[fix]]
face = "z+"
body = 1
[[load]]
face = "z-"
body = 1
force = [0, 0, -1]
period = 0.5
[solver]
kind = "dynamic"
)";
  Scene s = parse_scene(two, "two.toml");
  ASSERT_EQ(s.bodies.size(), 2u);
  EXPECT_EQ(s.body.youngs_modulus, 1e5);  // scene.body is the first body
  EXPECT_EQ(*s.bodies[0].radius, 0.04);
  EXPECT_FALSE(s.bodies[1].radius.has_value());
  EXPECT_EQ(s.bodies[1].youngs_modulus, 10e6);
  EXPECT_EQ(s.bodies[1].offset, (Vec3{1, 0, 0}));
  EXPECT_EQ(s.fixes[1].body, 1);
  EXPECT_EQ(s.fixes[0].body, 0);
  EXPECT_EQ(s.loads[0].body, 1);
  EXPECT_EQ(s.loads[0].period, 0.5);
  EXPECT_TRUE(s.physics.contact);
  EXPECT_EQ(s.physics.contact_stiffness, 1e3);
  EXPECT_EQ(s.physics.contact_skin, 0.01);
  // the text round trip keeps the array of bodies
  Scene again = parse_scene(s.text, "again");
  ASSERT_EQ(again.bodies.size(), 2u);
  EXPECT_EQ(again.bodies[1].spacing, s.bodies[1].spacing);
  // --set reaches a body of the array by index
  Scene set = parse_scene(two, "two.toml", {"body.1.youngs_modulus=2e6"});
  EXPECT_EQ(set.bodies[1].youngs_modulus, 2e6);
  // a single [body] is one body, as before
  Scene one = parse_scene(base, "one.toml");
  ASSERT_EQ(one.bodies.size(), 1u);
  EXPECT_EQ(one.bodies[0].molecules, one.body.molecules);

  auto error = [](const std::string& text, const std::vector<std::string>& set = {}) {
    try {
      parse_scene(text, "bad.toml", set);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(error(two, {"fix.1.body=2"}).find("fix[1].body"), std::string::npos);
  EXPECT_NE(error(two, {"load.0.body=-1"}).find("load[0].body"), std::string::npos);
  EXPECT_NE(error(two, {"load.0.period=0"}).find("load[0].period"), std::string::npos);
  EXPECT_NE(error(two, {"solver.kind=static"}).find("load[0].period"), std::string::npos);
  EXPECT_NE(error(two, {"body.0.radius=-1"}).find("body[0].radius"), std::string::npos);
  EXPECT_NE(error(two, {"physics.contact=1"}).find("physics.contact"), std::string::npos);
  EXPECT_NE(error(two, {"physics.contact_skin=-1"}).find("physics.contact_skin"), std::string::npos);
  EXPECT_NE(error(two, {"load.0.face=z+"}).find("load[0].face"), std::string::npos);  // fixed on body 1
  EXPECT_EQ(error(two, {"load.0.body=0", "load.0.face=z-"}), "");                        // z- of body 0 is free
  // a top-level method is checked against every body that uses it (both have face-diagonals here)
  EXPECT_EQ(error(two, {"calibration.method=homogenized"}), "");
  EXPECT_NE(error(two, {"calibration.method=lloyd"}).find("calibration.method"), std::string::npos);
  EXPECT_NE(error("body = []\n").find("body"), std::string::npos);
  // relaxation may rest on an obstacle instead of a fix; static may not
  const std::string resting = "[body]\nmolecules = [3,3,3]\nspacing = [1,1,1]\nyoungs_modulus = 1\n"
                              "[[obstacle]]\nkind = \"plane\"\npoint = [0,0,0]\nnormal = [0,0,1]\n";
  EXPECT_EQ(error(resting + "[solver]\nkind = \"relaxation\"\n"), "");
  EXPECT_NE(error(resting + "[solver]\nkind = \"static\"\n").find("solver.kind"), std::string::npos);
}

// Per-body calibration: a body's own calibration table ([body.calibration], [[body]] then [body.calibration], or
// an inline calibration = { ... }) replaces the top-level [calibration] for that body; the others keep it.
TEST(Scene, PerBodyCalibration) {
  const std::string head = R"(
[[body]]
molecules = [3, 3, 3]
spacing = [0.1, 0.1, 0.1]
youngs_modulus = 1e5
calibration = { method = "homogenized" }
[[body]]
molecules = [3, 3, 3]
spacing = [0.1, 0.1, 0.1]
topology = "tetrahedral"
youngs_modulus = 1e5
offset = [1, 0, 0]
[body.calibration]
method = "lloyd"
[[body]]
molecules = [2, 2, 2]
spacing = [0.1, 0.1, 0.1]
topology = "rectangular"
youngs_modulus = 1e5
offset = [2, 0, 0]
)";
  const std::string tail = R"(
[[fix]]
face = "z+"
[[fix]]
face = "z+"
body = 1
[[fix]]
face = "z+"
body = 2
)";
  const std::string three = head + "[calibration]\nmethod = \"divided\"\ndivisor = 2.5\n" + tail;
  Scene s = parse_scene(three, "three.toml");
  ASSERT_EQ(s.calibrations.size(), 3u);
  EXPECT_EQ(s.calibrations[0].method, "homogenized");
  EXPECT_EQ(s.calibrations[0].key, "body[0].calibration");
  EXPECT_EQ(s.calibrations[0].divisor, 1.0);  // a body's own table is whole: nothing comes from [calibration]
  EXPECT_EQ(s.calibrations[1].method, "lloyd");  // [body.calibration] after [[body]]: the last body's
  EXPECT_EQ(s.calibrations[1].key, "body[1].calibration");
  EXPECT_EQ(s.calibrations[2].method, "divided");  // no table of its own: the top-level one
  EXPECT_EQ(s.calibrations[2].divisor, 2.5);
  EXPECT_EQ(s.calibrations[2].key, "calibration");
  EXPECT_EQ(s.calibration.method, "homogenized");  // scene.calibration is body 0's
  // the text round trip and --set keep and reach the per-body tables
  Scene again = parse_scene(s.text, "again");
  ASSERT_EQ(again.calibrations.size(), 3u);
  for (int b = 0; b < 3; ++b) {
    EXPECT_EQ(again.calibrations[b].method, s.calibrations[b].method);
    EXPECT_EQ(again.calibrations[b].divisor, s.calibrations[b].divisor);
  }
  Scene set = parse_scene(three, "three.toml", {"body.2.calibration.method=manual",
                                                "body.2.calibration.stiffness.edge=7"});
  EXPECT_EQ(set.calibrations[2].method, "manual");
  EXPECT_EQ(set.calibrations[2].stiffness.at("edge"), 7.0);
  EXPECT_EQ(set.calibrations[1].method, "lloyd");
  // no top-level [calibration]: the bodies without a table of their own are linear
  Scene plain = parse_scene(head + tail, "plain.toml");
  EXPECT_EQ(plain.calibrations[2].method, "linear");
  // the single-table form: [body.calibration] is the body's (and wins over a top-level [calibration])
  const std::string single = R"(
[body]
molecules = [3, 3, 3]
spacing = [0.1, 0.1, 0.1]
youngs_modulus = 1e5
[body.calibration]
method = "divided"
divisor = 3.75
[calibration]
method = "statistical"
[[fix]]
face = "z+"
)";
  Scene one = parse_scene(single, "one.toml");
  ASSERT_EQ(one.calibrations.size(), 1u);
  EXPECT_EQ(one.calibration.method, "divided");
  EXPECT_EQ(one.calibration.divisor, 3.75);
  EXPECT_EQ(one.calibration.key, "body.calibration");

  auto error = [](const std::string& text, const std::vector<std::string>& set = {}) {
    try {
      parse_scene(text, "bad.toml", set);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  auto names = [&](const std::string& text, const std::vector<std::string>& set, const std::string& key) {
    const std::string e = error(text, set);
    EXPECT_NE(e.find(key), std::string::npos) << "expected " << key << " in: " << e;
  };
  // a method that needs a topology, checked per body and naming that body's key
  names(three, {"body.0.calibration.method=tetrahedral"}, "bad.toml: body[0].calibration.method: tetrahedral needs");
  names(three, {"body.1.calibration.method=homogenized"}, "body[1].calibration.method: homogenized needs");
  names(three, {"calibration.method=lloyd"}, "calibration.method: lloyd needs");  // body 2 uses it
  EXPECT_NE(error(three, {"calibration.method=lloyd"}).find("body 2 has \"rectangular\""), std::string::npos);
  names(single, {"body.calibration.method=lloyd"}, "body.calibration.method: lloyd needs");
  // iterative: one body only (it fits C by the scene's tension test)
  names(three, {"body.1.calibration.method=iterative"}, "body[1].calibration.method: iterative fits C");
  names(three, {"calibration.method=iterative"}, "calibration.method: iterative fits C");
  EXPECT_EQ(error(single, {"body.calibration.method=iterative"}), "");
  // a top-level table no body uses is still checked
  names(head + "[calibration]\nmethod = \"guess\"\n" + tail, {"body.2.calibration.method=linear"},
        "calibration.method");
  names(head + "[calibration]\ncolour = 1\n" + tail, {"body.2.calibration.method=linear"}, "calibration.colour");
  // the body's own table is validated like the top-level one
  names(three, {"body.0.calibration.method=guess"}, "body[0].calibration.method");
  names(three, {"body.0.calibration.divisor=0"}, "body[0].calibration.divisor");
  names(three, {"body.0.calibration.extra=1"}, "body[0].calibration.extra");
  names(three, {"body.0.calibration=3"}, "body[0].calibration");
  names(three, {"body.2.calibration.method=manual"}, "body[2].calibration.stiffness");
  names(three, {"body.2.calibration.method=manual", "body.2.calibration.stiffness.edge=-1"},
        "body[2].calibration.stiffness.edge");
  // manual stiffness against the body's own topology: body 0 has face diagonals, body 2 has none
  names(three, {"body.0.calibration.method=manual", "body.0.calibration.stiffness.edge=1"},
        "body[0].calibration.stiffness.face");
  EXPECT_EQ(error(three, {"body.2.calibration.method=manual", "body.2.calibration.stiffness.edge=1"}), "");
  names(single, {"body.calibration.max_updates=0"}, "body.calibration.max_updates");
}
