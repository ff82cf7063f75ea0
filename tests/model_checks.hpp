// What the model builders' tests compare (tests/lattice_model_test.cpp, tests/explicit_model_test.cpp): a rank's
// model and what calibration reads of it, against the whole-body reference (tests/whole_body.hpp).
#pragma once
#include <gtest/gtest.h>

#include "partition/calibration_inputs.hpp"
#include "partition/local_model.hpp"

namespace tissue {

// A model and what calibration reads of it.
struct Built {
  LocalModel model;
  CalibrationInputs inputs;
};

// The same counts, the same molecules (ids, PETSc blocks, positions, masses, moduli, degrees, bodies, first
// connections) and the same connection ends, exactly.
inline void expect_same_molecules(const Built& bx, const Built& by) {
  const LocalModel &x = bx.model, &y = by.model;
  EXPECT_EQ(x.global_molecules, y.global_molecules);
  EXPECT_EQ(x.global_connections, y.global_connections);
  EXPECT_EQ(x.partition.edge_cut, y.partition.edge_cut);
  EXPECT_EQ(x.owned, y.owned);
  EXPECT_EQ(x.local, y.local);
  EXPECT_EQ(x.first_block, y.first_block);
  EXPECT_EQ(x.id, y.id);
  EXPECT_EQ(x.block, y.block);
  EXPECT_EQ(x.rest, y.rest);
  EXPECT_EQ(x.mass, y.mass);
  EXPECT_EQ(bx.inputs.youngs_modulus, by.inputs.youngs_modulus);
  EXPECT_EQ(bx.inputs.degree, by.inputs.degree);
  EXPECT_EQ(x.body, y.body);
  EXPECT_EQ(x.end_a, y.end_a);
  EXPECT_EQ(x.end_b, y.end_b);
  EXPECT_EQ(x.first_connection, y.first_connection);
  EXPECT_EQ(x.connection_class, y.connection_class);
  EXPECT_EQ(x.written_count, y.written_count);
}

}  // namespace tissue
