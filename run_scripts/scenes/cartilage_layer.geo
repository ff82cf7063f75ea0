// A curved cartilage-like layer: an 84-degree arc of a cylindrical shell (a femoral condyle's cartilage),
// inner radius R on the bone, thickness t, width W, in two zones: "deep" (bone side) and "superficial".
// Named faces: "bone" (the inner surface, held) and "articular" (the outer surface, loaded).
// Mesh (run_scripts/cartilage_example.sh does it): gmsh -3 -format msh41 -setnumber h 0.0008 cartilage_layer.geo -o cartilage_layer.msh
// h = 0.0008 gives about 4,300 molecules, 0.00025 about 100,000.
SetFactory("OpenCASCADE");
R = 0.020; t = 0.0025; W = 0.020; a = 0.015; e = 1e-6;  // e: OpenCASCADE's bounding boxes are loose by about 2e-7
If (!Exists(h))
  h = 0.0008;
EndIf
Cylinder(1) = {0, 0, 0, 0, W, 0, R + t};
Cylinder(2) = {0, 0, 0, 0, W, 0, R + t / 2};
Cylinder(3) = {0, 0, 0, 0, W, 0, R};
Box(4) = {-a, -1, 0.005, 2 * a, W + 2, 1};
BooleanDifference(10) = { Volume{1}; Delete; }{ Volume{2}; };
BooleanDifference(11) = { Volume{2}; Delete; }{ Volume{3}; Delete; };
BooleanIntersection(12) = { Volume{10}; Delete; }{ Volume{4}; };
BooleanIntersection(13) = { Volume{11}; Delete; }{ Volume{4}; Delete; };
BooleanFragments{ Volume{12}; Delete; }{ Volume{13}; Delete; }
deep() = {}; superficial() = {};
v() = Volume{:};
For i In {0 : #v() - 1}
  bb() = BoundingBox Volume{v(i)};
  If (Fabs(bb(5) - R - t) < e)
    superficial() += v(i);
  Else
    deep() += v(i);
  EndIf
EndFor
bone() = {}; articular() = {};
s() = Surface{:};
For i In {0 : #s() - 1}
  bb() = BoundingBox Surface{s(i)};
  // The curved faces span the width and more than a third of the arc (OpenCASCADE splits a cylinder at its seam).
  If (bb(3) - bb(0) > a / 2 && Fabs(bb(1)) < e && Fabs(bb(4) - W) < e)
    If (Fabs(bb(5) - R) < e)
      bone() += s(i);
    EndIf
    If (Fabs(bb(5) - R - t) < e)
      articular() += s(i);
    EndIf
  EndIf
EndFor
Physical Volume("deep") = deep();
Physical Volume("superficial") = superficial();
Physical Surface("bone") = bone();
Physical Surface("articular") = articular();
Mesh.CharacteristicLengthMax = h;
Mesh.Binary = 0;
