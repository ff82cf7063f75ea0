// A non-convex mesh for the random-in-mesh tests (tests/mesh_test.cpp): an L, the unit square in x, y without
// its quarter x > 0.5, y > 0.5, 0.4 m thick in z. Its Delaunay hull would fill the notch; carving must not.
// Faces: "x-" (x = 0) and "x+" (x = 1, 0 <= y <= 0.5), planes for rollers and loads.
// Regenerate: gmsh -3 -format msh41 l_shape.geo -o l_shape.msh
SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, 1, 0.5, 0.4};
Box(2) = {0, 0.5, 0, 0.5, 0.5, 0.4};
BooleanUnion(3) = { Volume{1}; Delete; }{ Volume{2}; Delete; };
e = 1e-6;
Physical Volume("L") = {3};
Physical Surface("x-") = Surface In BoundingBox{-e, -e, -e, e, 1 + e, 0.4 + e};
Physical Surface("x+") = Surface In BoundingBox{1 - e, -e, -e, 1 + e, 0.5 + e, 0.4 + e};
Mesh.CharacteristicLengthMax = 0.2;
Mesh.Binary = 0;
