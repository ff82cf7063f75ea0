// The mesh the tests use (tests/mesh_test.cpp): a 1 x 1 x 0.5 m slab of two layers, "deep" (z < 0.25) and
// "surface", with its bottom and top faces named. Regenerate: gmsh -3 -format msh41 two_layers.geo -o two_layers.msh
SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, 1, 1, 0.25};
Box(2) = {0, 0, 0.25, 1, 1, 0.25};
BooleanFragments{ Volume{1}; Delete; }{ Volume{2}; Delete; }
e = 1e-6;
Physical Volume("deep") = Volume In BoundingBox{-e, -e, -e, 1 + e, 1 + e, 0.25 + e};
Physical Volume("surface") = Volume In BoundingBox{-e, -e, 0.25 - e, 1 + e, 1 + e, 0.5 + e};
Physical Surface("bottom") = Surface In BoundingBox{-e, -e, -e, 1 + e, 1 + e, e};
Physical Surface("top") = Surface In BoundingBox{-e, -e, 0.5 - e, 1 + e, 1 + e, 0.5 + e};
Physical Surface("west") = Surface In BoundingBox{-e, -e, -e, e, 1 + e, 0.5 + e};
Mesh.CharacteristicLengthMax = 0.2;
Mesh.Binary = 0;
