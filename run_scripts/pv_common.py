# What the pvbatch renderers (render_example.py, render_mesh.py) share: a white view on an output's last frame,
# the displacement magnitude, a Viridis colour bar and a title. Imported by them, not run on its own.
from paraview.simple import *  # noqa: F401,F403


def last_frame(xdmf, size):
    """Opens tissue.xdmf at its last time and returns (view, calculator giving '|u| (m)')."""
    reader = Xdmf3ReaderS(FileName=[xdmf])
    reader.UpdatePipeline()
    times = reader.TimestepValues
    view = GetActiveViewOrCreate("RenderView")
    view.ViewSize = size
    view.Background = [1, 1, 1]
    try:
        view.UseColorPaletteForBackground = 0
    except AttributeError:  # older ParaView: the background is always the one given
        pass
    times = list(times) if hasattr(times, "__len__") else ([times] if times is not None else [])
    if times:  # the last frame of a series (snapshots + final)
        view.ViewTime = times[-1]
        GetAnimationScene().AnimationTime = times[-1]
    calc = Calculator(Input=reader, ResultArrayName="|u| (m)", Function="mag(displacement)")
    calc.AttributeType = "Point Data"
    return view, calc


def colour_by_displacement(display, view):
    ColorBy(display, ("POINTS", "|u| (m)"))
    lut = GetColorTransferFunction("|u| (m)")
    lut.ApplyPreset("Viridis (matplotlib)", True)
    display.SetScalarBarVisibility(view, True)
    bar = GetScalarBar(lut, view)
    bar.TitleColor = [0, 0, 0]
    bar.LabelColor = [0, 0, 0]


def title(text, view):
    td = Show(Text(Text=text), view)
    td.Color = [0, 0, 0]
    td.FontSize = 14
    td.WindowLocation = "Upper Center"
