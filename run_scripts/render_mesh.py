# Renders a mesh body's final state to a PNG with ParaView (pvbatch): the connections of the deformed body
# (displacements magnified by WARP), coloured by displacement magnitude, over the rest shape in light grey.
# Usage (absolute paths):
#   xvfb-run -a pvbatch run_scripts/render_mesh.py OUT_DIR/tissue.xdmf TITLE IMAGE.png WARP
import os
import sys

from paraview.simple import *  # noqa: F401,F403

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pv_common import colour_by_displacement, last_frame, title  # noqa: E402

xdmf, title_text, image, warp = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
view, calc = last_frame(xdmf, [1200, 800])
# the rest shape (positions minus displacements are not stored: warp back)
rest_warp = WarpByVector(Input=calc, Vectors=["POINTS", "displacement"], ScaleFactor=-1.0)
rest = Show(rest_warp, view)
rest.SetRepresentationType("Wireframe")
rest.AmbientColor = rest.DiffuseColor = [0.75, 0.75, 0.75]
rest.ColorArrayName = ["POINTS", ""]
rest.Opacity = 0.3
deformed = WarpByVector(Input=rest_warp, Vectors=["POINTS", "displacement"], ScaleFactor=warp)
d = Show(deformed, view)
d.SetRepresentationType("Wireframe")
colour_by_displacement(d, view)
title(f"{title_text} (displacements x {warp:g})", view)
# Looking along the cylinder's axis (y), a little from the side and above: the arc and the layer's thickness.
view.CameraFocalPoint = [0, 0.01, 0.018]
view.CameraPosition = [0.02, -0.07, 0.05]
view.CameraViewUp = [0, 0, 1]
view.ResetCamera()
SaveScreenshot(image, view, ImageResolution=[1200, 800])
