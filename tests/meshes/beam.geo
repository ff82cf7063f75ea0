// The cantilever the locking test meshes (tests/poisson_mesh_test.cpp, PoissonMesh.CantileverDoesNotLock): a
// 10 x 1 x 1 beam along x, faces named x- .. z+ (clamped x-, tip load on x+). Element size h (-setnumber h 0.34).
// Regenerate: gmsh -3 -format msh41 -setnumber h 0.34 beam.geo -o beam_h0.34.msh
SetFactory("OpenCASCADE");
If (!Exists(h))
  h = 0.34;
EndIf
Box(1) = {0, 0, 0, 10, 1, 1};
e = 1e-6;
Physical Volume("beam") = {1};
Physical Surface("x-") = Surface In BoundingBox{-e, -e, -e, e, 1 + e, 1 + e};
Physical Surface("x+") = Surface In BoundingBox{10 - e, -e, -e, 10 + e, 1 + e, 1 + e};
Physical Surface("y-") = Surface In BoundingBox{-e, -e, -e, 10 + e, e, 1 + e};
Physical Surface("y+") = Surface In BoundingBox{-e, 1 - e, -e, 10 + e, 1 + e, 1 + e};
Physical Surface("z-") = Surface In BoundingBox{-e, -e, -e, 10 + e, 1 + e, e};
Physical Surface("z+") = Surface In BoundingBox{-e, -e, 1 - e, 10 + e, 1 + e, 1 + e};
MeshSize{ PointsOf{ Volume{1}; } } = h;
Mesh.CharacteristicLengthMax = h;
Mesh.Binary = 0;
