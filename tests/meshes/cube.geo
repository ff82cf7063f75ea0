// The unit cube the Poisson tests mesh (tests/poisson_mesh_test.cpp): faces named x- .. z+ so that rollers, loads
// and the lateral Poisson faces find them. Element size h (-setnumber h 0.25).
// Regenerate: gmsh -3 -format msh41 -setnumber h 0.25 cube.geo -o cube_h0.25.msh
SetFactory("OpenCASCADE");
If (!Exists(h))
  h = 0.25;
EndIf
Box(1) = {0, 0, 0, 1, 1, 1};
e = 1e-6;
Physical Volume("cube") = {1};
Physical Surface("x-") = Surface In BoundingBox{-e, -e, -e, e, 1 + e, 1 + e};
Physical Surface("x+") = Surface In BoundingBox{1 - e, -e, -e, 1 + e, 1 + e, 1 + e};
Physical Surface("y-") = Surface In BoundingBox{-e, -e, -e, 1 + e, e, 1 + e};
Physical Surface("y+") = Surface In BoundingBox{-e, 1 - e, -e, 1 + e, 1 + e, 1 + e};
Physical Surface("z-") = Surface In BoundingBox{-e, -e, -e, 1 + e, 1 + e, e};
Physical Surface("z+") = Surface In BoundingBox{-e, -e, 1 - e, 1 + e, 1 + e, 1 + e};
MeshSize{ PointsOf{ Volume{1}; } } = h;
Mesh.CharacteristicLengthMax = h;
Mesh.Binary = 0;
