// A 1 m cube for the accuracy study (run_scripts/random_accuracy.py): gmsh's tetrahedra, faces named as a box
// lattice's (x- .. z+) so the same fixes and loads apply. Mesh: gmsh -3 -format msh41 -setnumber h 0.12 cube_mesh.geo
SetFactory("OpenCASCADE");
If (!Exists(h))
  h = 0.12;
EndIf
Box(1) = {0, 0, 0, 1, 1, 1};
Physical Volume("cube") = {1};
Physical Surface("x-") = {1};
Physical Surface("x+") = {2};
Physical Surface("y-") = {3};
Physical Surface("y+") = {4};
Physical Surface("z-") = {5};
Physical Surface("z+") = {6};
Mesh.CharacteristicLengthMax = h;
Mesh.Binary = 0;
