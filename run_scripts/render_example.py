# Renders an example's final state to a PNG with ParaView (pvbatch): molecules as spheres coloured by
# displacement magnitude, obstacles in translucent grey. Usage (absolute paths):
#   xvfb-run -a pvbatch run_scripts/render_example.py OUT_DIR/tissue.xdmf SCENE.toml IMAGE.png
import os
import sys
import tomllib

from paraview.simple import *  # noqa: F401,F403

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pv_common import colour_by_displacement, last_frame, title  # noqa: E402

xdmf, scene_path, image = sys.argv[1], sys.argv[2], sys.argv[3]
with open(scene_path, "rb") as f:
    scene = tomllib.load(f)
bodies = scene["body"] if isinstance(scene["body"], list) else [scene["body"]]

view, calc = last_frame(xdmf, [1000, 750])
spacing = min(min(b.get("spacing", [s / (n - 1) for s, n in zip(b.get("size", [1, 1, 1]), b["molecules"])]))
              for b in bodies)
glyph = Glyph(Input=calc, GlyphType="Sphere")
glyph.ScaleArray = ["POINTS", "No scale array"]
glyph.ScaleFactor = 0.9 * spacing
glyph.GlyphMode = "All Points"
glyph.GlyphType.ThetaResolution = 12
glyph.GlyphType.PhiResolution = 12
d = Show(glyph, view)
colour_by_displacement(d, view)
lines = Show(calc, view)  # the connections as thin lines
lines.SetRepresentationType("Wireframe")
lines.AmbientColor = lines.DiffuseColor = [0.3, 0.3, 0.3]
lines.Opacity = 0.25
lines.ColorArrayName = ["POINTS", ""]

for o in scene.get("obstacle", []):
    if o["kind"] == "sphere":
        src = Sphere(Center=o["center"], Radius=o["radius"], ThetaResolution=48, PhiResolution=48)
    else:
        n = o["normal"]
        p = o["point"]
        size = 1.5 * max(max(b.get("size", [1, 1, 1])) for b in bodies)
        b0 = bodies[0]
        ext = b0.get("size") or [h * (n - 1) for h, n in zip(b0["spacing"], b0["molecules"])]
        mid = [o_ + e / 2 for o_, e in zip(b0.get("offset", [0, 0, 0]), ext)]
        p = [mid[0], mid[1], p[2]]  # centred under the first body (planes normal to z)
        src = Plane()
        # a square of side `size` through p, normal n (built around z and rotated by ParaView's Plane normal)
        src.Origin = [p[0] - size / 2, p[1] - size / 2, p[2]]
        src.Point1 = [p[0] + size / 2, p[1] - size / 2, p[2]]
        src.Point2 = [p[0] - size / 2, p[1] + size / 2, p[2]]
        if abs(n[2]) < 0.99:
            src.Normal = n
    od = Show(src, view)
    od.AmbientColor = od.DiffuseColor = [0.6, 0.6, 0.6]
    od.Opacity = 0.35

title(scene.get("title", ""), view)
view.CameraPosition = [1, -1.6, 0.9]
view.CameraFocalPoint = [0, 0, 0]
view.CameraViewUp = [0, 0, 1]
view.ResetCamera()
cam = GetActiveCamera()
cam.Dolly(1.1)
Render(view)
SaveScreenshot(image, view, ImageResolution=[1000, 750])
