# The fibre field of a run's last frame (docs/anisotropy.md) with ParaView (pvbatch): an arrow per molecule along
# its deformed fibre direction, coloured by the fibre stretch, over the body's connections. Usage (absolute paths):
#   xvfb-run -a pvbatch run_scripts/render_fibres.py OUT_DIR/tissue.xdmf IMAGE.png SPACING
import os
import sys

from paraview.simple import *  # noqa: F401,F403

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pv_common import last_frame  # noqa: E402

xdmf, image, spacing = sys.argv[1], sys.argv[2], float(sys.argv[3])
view, calc = last_frame(xdmf, [1100, 650])
glyph = Glyph(Input=calc, GlyphType="Arrow")
glyph.OrientationArray = ["POINTS", "fibre_direction"]
glyph.ScaleArray = ["POINTS", "No scale array"]
glyph.ScaleFactor = 0.8 * spacing
glyph.GlyphMode = "All Points"
glyph.UpdatePipeline()
d = Show(glyph, view)
ColorBy(d, ("POINTS", "fibre_stretch"))
lut = GetColorTransferFunction("fibre_stretch")
lut.ApplyPreset("Viridis (matplotlib)", True)
d.RescaleTransferFunctionToDataRange(True, False)
bar = GetScalarBar(lut, view)
bar.Title = "fibre stretch"
bar.ComponentTitle = ""
bar.TitleColor = bar.LabelColor = [0, 0, 0]
d.SetScalarBarVisibility(view, True)
lines = Show(calc, view)
lines.SetRepresentationType("Wireframe")
lines.AmbientColor = lines.DiffuseColor = [0.3, 0.3, 0.3]
lines.Opacity = 0.15
lines.ColorArrayName = ["POINTS", ""]
text = Text(Text="Ligament strip: fibres along the axis, margins fanned by 15 degrees (arrows: deformed fibre direction)")
t = Show(text, view)
t.Color = [0, 0, 0]
t.FontSize = 14
t.WindowLocation = "Upper Center"
# From above (+z): the fibres lie in the x-y plane.
view.CameraPosition = [0.0052, 0.002, 0.04]
view.CameraFocalPoint = [0.0052, 0.002, 0.001]
view.CameraViewUp = [0, 1, 0]
view.ResetCamera()
view.CameraParallelProjection = 1
view.OrientationAxesVisibility = 0
Render(view)
SaveScreenshot(image + ".tmp.png", view, ImageResolution=[1100, 650])
os.replace(image + ".tmp.png", image)
