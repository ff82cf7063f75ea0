# Renders the cell term's volume ratio J of a run's last frame to a PNG with ParaView (pvbatch): the XDMF's "cells"
# grid (hexahedra or tetrahedra, docs/poisson.md) coloured by its cell attribute volume_ratio, displacements
# magnified by WARP, over the rest shape's outline. Usage (absolute paths):
#   xvfb-run -a pvbatch --force-offscreen-rendering run_scripts/render_cells.py OUT/tissue.xdmf TITLE IMAGE.png WARP
import os
import sys

from paraview.simple import *  # noqa: F401,F403

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pv_common import title  # noqa: E402

xdmf, title_text, image, warp = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
# Xdmf3ReaderT keeps the XDMF's two grids apart (cells, connections) where Xdmf3ReaderS joins them as pieces.
reader = Xdmf3ReaderT(FileName=[xdmf])
times = reader.TimestepValues
last = times[-1] if hasattr(times, "__len__") else times
view = GetActiveViewOrCreate("RenderView")
view.ViewSize = [1200, 800]
view.Background = [1, 1, 1]
try:
    view.UseColorPaletteForBackground = 0
except AttributeError:  # older ParaView
    pass
if last is not None:
    view.ViewTime = last
    GetAnimationScene().AnimationTime = last
# the cells: the only grid with volume_ratio (the connections' grid has none, so the threshold drops it)
cells = Threshold(Input=reader, Scalars=["CELLS", "volume_ratio"], LowerThreshold=0.0, UpperThreshold=1e30)
merged = MergeBlocks(Input=cells)
rest = WarpByVector(Input=merged, Vectors=["POINTS", "displacement"], ScaleFactor=-1.0)
outline = Show(rest, view)
outline.SetRepresentationType("Outline")
outline.AmbientColor = outline.DiffuseColor = [0.4, 0.4, 0.4]
outline.ColorArrayName = ["POINTS", ""]
deformed = WarpByVector(Input=rest, Vectors=["POINTS", "displacement"], ScaleFactor=warp)
d = Show(deformed, view)
d.SetRepresentationType("Surface With Edges")
d.EdgeColor = [0.2, 0.2, 0.2]
ColorBy(d, ("CELLS", "volume_ratio"))
lut = GetColorTransferFunction("volume_ratio")
lut.ApplyPreset("Cool to Warm", True)
d.RescaleTransferFunctionToDataRange(False, True)
d.SetScalarBarVisibility(view, True)
bar = GetScalarBar(lut, view)
bar.Title = "J = det F"
bar.ComponentTitle = ""
bar.TitleColor = [0, 0, 0]
bar.LabelColor = [0, 0, 0]
bar.RangeLabelFormat = "%-#6.4f"
title(f"{title_text} (displacements x {warp:g})", view)
view.CameraPosition = [1, -1.6, 1.1]
view.CameraFocalPoint = [0, 0, 0]
view.CameraViewUp = [0, 0, 1]
view.ResetCamera()
GetActiveCamera().Dolly(1.3)
Render(view)
SaveScreenshot(image, view, ImageResolution=[1200, 800])
