# Renders a mesh body's final state to a PNG with ParaView (pvbatch): the connections of the deformed body
# (displacements magnified by WARP), coloured by displacement magnitude, over the rest shape in light grey.
# Usage (absolute paths):
#   xvfb-run -a pvbatch run_scripts/render_mesh.py OUT_DIR/tissue.xdmf TITLE IMAGE.png WARP
import sys

from paraview.simple import *  # noqa: F401,F403

xdmf, title, image, warp = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
reader = Xdmf3ReaderS(FileName=[xdmf])
reader.UpdatePipeline()
times = reader.TimestepValues
view = GetActiveViewOrCreate("RenderView")
view.ViewSize = [1200, 800]
view.Background = [1, 1, 1]
try:
    view.UseColorPaletteForBackground = 0
except AttributeError:
    pass
times = list(times) if hasattr(times, "__len__") else ([times] if times is not None else [])
if times:
    view.ViewTime = times[-1]
    GetAnimationScene().AnimationTime = times[-1]
calc = Calculator(Input=reader, ResultArrayName="|u| (m)", Function="mag(displacement)")
calc.AttributeType = "Point Data"
rest = Show(calc, view)  # the rest shape (positions minus displacements are not stored: warp back)
rest_warp = WarpByVector(Input=calc, Vectors=["POINTS", "displacement"], ScaleFactor=-1.0)
Hide(calc, view)
rest = Show(rest_warp, view)
rest.SetRepresentationType("Wireframe")
rest.AmbientColor = rest.DiffuseColor = [0.75, 0.75, 0.75]
rest.ColorArrayName = ["POINTS", ""]
rest.Opacity = 0.3
deformed = WarpByVector(Input=rest_warp, Vectors=["POINTS", "displacement"], ScaleFactor=warp)
d = Show(deformed, view)
d.SetRepresentationType("Wireframe")
ColorBy(d, ("POINTS", "|u| (m)"))
lut = GetColorTransferFunction("|u| (m)")
lut.ApplyPreset("Viridis (matplotlib)", True)
d.SetScalarBarVisibility(view, True)
bar = GetScalarBar(lut, view)
bar.TitleColor = [0, 0, 0]
bar.LabelColor = [0, 0, 0]
text = Text(Text=f"{title} (displacements x {warp:g})")
td = Show(text, view)
td.Color = [0, 0, 0]
td.FontSize = 14
td.WindowLocation = "Upper Center"
# Looking along the cylinder's axis (y), a little from the side and above: the arc and the layer's thickness.
view.CameraFocalPoint = [0, 0.01, 0.018]
view.CameraPosition = [0.02, -0.07, 0.05]
view.CameraViewUp = [0, 0, 1]
view.ResetCamera()
SaveScreenshot(image, view, ImageResolution=[1200, 800])
