# Renders a box lattice's last frame from lattice.xdmf (the structured-grid index, io/xdmf.hpp: no connection list)
# with ParaView (pvbatch): the deformed block's surface with its lattice lines, coloured by displacement magnitude
# (displacements magnified by WARP). The scene must write `displacements`.
# Usage (absolute paths):
#   xvfb-run -a pvbatch run_scripts/render_lattice.py OUT_DIR/lattice.xdmf TITLE IMAGE.png WARP
import os
import sys

from paraview.simple import *  # noqa: F401,F403

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pv_common import colour_by_displacement, last_frame, title  # noqa: E402

xdmf, title_text, image, warp = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
view, calc = last_frame(xdmf, [1000, 800])
# the positions are the deformed state: warp by (WARP - 1) u to magnify the displacements
deformed = WarpByVector(Input=calc, Vectors=["POINTS", "displacement"], ScaleFactor=warp - 1.0)
d = Show(deformed, view)
d.SetRepresentationType("Surface With Edges")
colour_by_displacement(d, view)
title(f"{title_text} (structured grid, displacements x {warp:g})", view)
view.CameraPosition = [1, -1.5, 0.8]
view.CameraFocalPoint = [0, 0, 0]
view.CameraViewUp = [0, 0, 1]
view.ResetCamera()
SaveScreenshot(image, view, ImageResolution=[1000, 800])
