"""Open a piezodyn field file with ParaView's own XDMF readers and render it (run by pvpython, see
tests/test_paraview.py, which gives it a private Xvfb display): by hand,
``xvfb-run -a pvpython tests/paraview_open.py FILE.xdmf OUT.png``.

Prints one JSON object: the time values, for every reader (Xdmf3ReaderT, Xdmf3ReaderS and the
legacy XDMFReader) its blocks with their point, cell and field arrays, and after Warp By Vector
on ``displacement`` at the last time: the warped bounds, the potential's range on the warped FE
grid and the warped rigid-body positions. Renders the warped result coloured by potential to
OUT.png (rigid bodies as large points). An optional third argument picks the time (for a mode
file: the frequency [Hz]) shown and rendered instead of the last ("last" for the last); an optional fourth
names the point array to colour by instead of the potential (e.g. ``von_mises_Pa``). The report also holds
the range of every point array of the FE grid at the time shown (``fe_ranges``: the largest magnitude of a
vector or tensor array) and of the bodies' displacement (``body_displacement_range``), and for every region
indicator cell array (``region: <name>``) the cells and ``region`` tag range that Threshold (1 to 1) on the
warped grid keeps (``region_thresholds``). The modal tier's contact sites' companion
``<stem minus _fields>_contact_sites.xdmf`` (a point cloud with ``contact_pressure_Pa``), when it exists: per
reader its blocks at the last time and the point arrays' ranges at every time (``site_ranges``).

A bodies file given alone (``..._bodies.xdmf``, the lumped tier's) is read by the three readers, warped and
rendered coloured by ``body`` (:func:`main_bodies`).

A transient field file's companion ``<stem minus _fields>_bodies.xdmf`` (the rigid bodies with their shapes,
app/transient/fields.py) is opened with it when it exists: its blocks per reader, and after the same Warp By
Vector the warped bounds of each body's vertices (by the cell value ``body``), rendered with the FE grid."""

import json
import os
import sys

from paraview import servermanager as sm
from paraview.simple import (
    ColorBy,
    Delete,
    GetActiveCamera,
    GetActiveViewOrCreate,
    GetColorTransferFunction,
    Render,
    SaveScreenshot,
    Show,
    Text,
    Threshold,
    WarpByVector,
    Xdmf3ReaderS,
    Xdmf3ReaderT,
    XDMFReader,
)


def arrays(attributes):
    return [attributes.GetArrayName(i) for i in range(attributes.GetNumberOfArrays())]


def leaves(data, name="", out=None):
    """(name, dataset) of every leaf of a composite dataset."""
    out = [] if out is None else out
    if data.IsA("vtkMultiBlockDataSet") or data.IsA("vtkMultiPieceDataSet"):
        for i in range(data.GetNumberOfBlocks() if data.IsA("vtkMultiBlockDataSet") else data.GetNumberOfPieces()):
            meta = data.GetMetaData(i) if data.HasMetaData(i) else None
            child_name = meta.Get(data.NAME()) if meta is not None and meta.Has(data.NAME()) else f"{name}[{i}]"
            child = data.GetBlock(i) if data.IsA("vtkMultiBlockDataSet") else data.GetPiece(i)
            if child is not None:
                leaves(child, child_name, out)
    else:
        out.append((name, data))
    return out


def describe(data):
    return [{"name": name, "points": block.GetNumberOfPoints(), "cells": block.GetNumberOfCells(),
             "point_arrays": arrays(block.GetPointData()), "cell_arrays": arrays(block.GetCellData()),
             "field_arrays": arrays(block.GetFieldData())} for name, block in leaves(data)]


def body_bounds(data):
    """{body index: [xmin, xmax, ymin, ymax, zmin, zmax]} of the vertices of each body's triangles."""
    from vtkmodules.util.numpy_support import vtk_to_numpy

    out = {}
    for _, block in leaves(data):
        if block.GetNumberOfCells() == 0 or block.GetCellData().GetArray("body") is None:
            continue
        points = vtk_to_numpy(block.GetPoints().GetData())
        body = vtk_to_numpy(block.GetCellData().GetArray("body"))
        for index in sorted(set(body.tolist())):
            ids = set()
            for cell in (c for c in range(block.GetNumberOfCells()) if body[c] == index):
                pts = block.GetCell(cell).GetPointIds()
                ids.update(pts.GetId(k) for k in range(pts.GetNumberOfIds()))
            p = points[sorted(ids)]
            out[str(index)] = [v for axis in range(3) for v in (float(p[:, axis].min()), float(p[:, axis].max()))]
    return out


def companion(path, kind="bodies"):
    """The rigid bodies' (``kind`` "bodies") or contact sites' ("contact_sites") file written next to a transient
    field file, or None."""
    folder, name = os.path.split(path)
    if not name.endswith("_fields.xdmf"):
        return None
    other = os.path.join(folder, name[:-len("_fields.xdmf")] + f"_{kind}.xdmf")
    return other if os.path.isfile(other) else None


def point_ranges(block):
    """{array: [min, max]} of a block's point arrays (a vector's or tensor's magnitude, as ParaView's -1)."""
    data = block.GetPointData()
    return {data.GetArrayName(i): list(data.GetArray(i).GetRange(-1 if data.GetArray(i).GetNumberOfComponents() > 1
                                                                    else 0))
            for i in range(data.GetNumberOfArrays())}


def main_bodies(path, png, at=None):
    """A bodies file alone (the lumped tier's ``transient_bodies.xdmf``): per reader its times and blocks, the
    bodies' bounds at the time shown before and after Warp By Vector (scaled so the largest displacement shows as
    5 % of the scene), rendered coloured by ``body``."""
    report = {}
    readers = {"Xdmf3ReaderT": Xdmf3ReaderT(FileName=[path]), "Xdmf3ReaderS": Xdmf3ReaderS(FileName=[path]),
               "XDMFReader": XDMFReader(FileNames=[path])}
    for name, reader in readers.items():
        reader.UpdatePipelineInformation()
        times = list(reader.TimestepValues) if reader.TimestepValues else [0.0]
        reader.UpdatePipeline(times[-1])
        report[name] = {"times": times, "blocks": describe(sm.Fetch(reader))}
    reader = readers["Xdmf3ReaderT"]
    times = report["Xdmf3ReaderT"]["times"]
    show = times[-1] if at is None else min(times, key=lambda t: abs(t - at))
    reader.UpdatePipeline(show)
    data = sm.Fetch(reader)
    block = [blk for _, blk in leaves(data) if blk.GetNumberOfCells()][0]
    u_max = max(block.GetPointData().GetArray("displacement").GetRange(-1)[1], 1e-300)
    b = block.GetBounds()
    size = max(b[1] - b[0], b[3] - b[2], b[5] - b[4])
    scale = 0.05 * size / u_max
    warp = WarpByVector(Input=reader)
    warp.Vectors = ["POINTS", "displacement"]
    warp.ScaleFactor = scale
    warp.UpdatePipeline(show)
    report["body_bounds_before"] = body_bounds(data)
    report["warped"] = {"time": show, "scale": scale, "u_max": u_max, "body_bounds": body_bounds(sm.Fetch(warp))}
    view = GetActiveViewOrCreate("RenderView")
    view.ViewSize = [500, 900]
    view.ViewTime = show
    view.OrientationAxesVisibility = 0
    display = Show(warp, view)
    ColorBy(display, ("CELLS", "body"))
    display.RescaleTransferFunctionToDataRange(True, False)
    Show(Text(Text=f"{path.rsplit('/', 1)[-1]}: t = {show * 1e3:.4g} ms, displacement x {scale:.3g}"), view)
    view.ResetCamera()
    camera = GetActiveCamera()
    centre = [(b[0] + b[1]) / 2, (b[2] + b[3]) / 2, (b[4] + b[5]) / 2]
    camera.SetFocalPoint(*centre)
    camera.SetPosition(centre[0] + 1.5 * size, centre[1] - 1.5 * size, centre[2] + 0.4 * size)
    camera.SetViewUp(0.0, 0.0, 1.0)
    view.ResetCamera()
    Render(view)
    SaveScreenshot(png, view, ImageResolution=[500, 900])
    print("PIEZODYN-REPORT " + json.dumps(report))


def main(path, png, at=None, colour="potential"):
    if path.endswith("_bodies.xdmf"):
        return main_bodies(path, png, at)
    report = {}
    readers = {"Xdmf3ReaderT": Xdmf3ReaderT(FileName=[path]), "Xdmf3ReaderS": Xdmf3ReaderS(FileName=[path]),
               "XDMFReader": XDMFReader(FileNames=[path])}
    for name, reader in readers.items():
        reader.UpdatePipelineInformation()
        times = list(reader.TimestepValues) if reader.TimestepValues else [0.0]
        reader.UpdatePipeline(times[-1])
        report[name] = {"times": times, "blocks": describe(sm.Fetch(reader))}
    bodies_path = companion(path)
    body_readers = {}
    if bodies_path is not None:
        body_readers = {"Xdmf3ReaderT": Xdmf3ReaderT(FileName=[bodies_path]),
                        "Xdmf3ReaderS": Xdmf3ReaderS(FileName=[bodies_path]),
                        "XDMFReader": XDMFReader(FileNames=[bodies_path])}
        for name, reader in body_readers.items():
            reader.UpdatePipelineInformation()
            times = list(reader.TimestepValues) if reader.TimestepValues else [0.0]
            reader.UpdatePipeline(times[-1])
            report[name]["body_times"] = times
            report[name]["body_blocks"] = describe(sm.Fetch(reader))
    sites_path = companion(path, "contact_sites")
    if sites_path is not None:          # the modal tier's contact sites: a point cloud with their pressure
        for name, site_reader in (("Xdmf3ReaderT", Xdmf3ReaderT(FileName=[sites_path])),
                                  ("Xdmf3ReaderS", Xdmf3ReaderS(FileName=[sites_path])),
                                  ("XDMFReader", XDMFReader(FileNames=[sites_path]))):
            site_reader.UpdatePipelineInformation()
            times = list(site_reader.TimestepValues) if site_reader.TimestepValues else [0.0]
            report[name]["site_times"] = times
            report[name]["site_ranges"] = {}
            for t in times:             # each frame's pressure range, as this reader reads it
                site_reader.UpdatePipeline(t)
                blocks = [blk for _, blk in leaves(sm.Fetch(site_reader)) if blk.GetNumberOfPoints()]
                report[name]["site_blocks"] = describe(sm.Fetch(site_reader))
                report[name]["site_ranges"][repr(t)] = point_ranges(blocks[0])
            Delete(site_reader)
    reader = readers["Xdmf3ReaderT"]
    times = report["Xdmf3ReaderT"]["times"]
    show = times[-1] if at is None else min(times, key=lambda t: abs(t - at))
    reader.UpdatePipeline(show)
    frequency = None
    raw = leaves(sm.Fetch(reader))
    for _, block in raw:
        f = block.GetFieldData().GetArray("frequency_Hz")
        if f is not None:
            frequency = f.GetValue(0)
    if frequency is None and path.rsplit("/", 1)[-1].startswith("modes_"):
        frequency = show                                # a mode file's time value is the mode's frequency [Hz]
    # Warp by the displacement, scaled so the largest displacement shows as 10 % of the model size
    fe = max(raw, key=lambda item: item[1].GetNumberOfPoints())[1]
    u_max = max(fe.GetPointData().GetArray("displacement").GetRange(-1)[1], 1e-300)
    b = fe.GetBounds()
    size = max(b[1] - b[0], b[3] - b[2], b[5] - b[4])
    scale = 0.1 * size / u_max
    warp = WarpByVector(Input=reader)
    warp.Vectors = ["POINTS", "displacement"]
    warp.ScaleFactor = scale
    warp.UpdatePipeline(show)
    warped = leaves(sm.Fetch(warp))
    bodies = {}
    for name, block in warped:
        if block.GetNumberOfPoints() == 1:
            bodies[name] = list(block.GetPoint(0))
    fe_warped = max(warped, key=lambda item: item[1].GetNumberOfPoints())[1]
    potential = fe_warped.GetPointData().GetArray("potential")
    report["fe_ranges"] = point_ranges(fe)
    report["warped"] = {"scale": scale, "u_max": u_max, "fe_bounds_before": list(b),
                        "fe_bounds_after": list(fe_warped.GetBounds()),
                        "potential_range": list(potential.GetRange()) if potential is not None else None,
                        "region_range": list(fe_warped.GetCellData().GetArray("region").GetRange()),
                        "bodies": bodies, "frequency_Hz": frequency, "time": show}
    # the regions by name: Threshold on each ``region: <name>`` indicator (1 in the region) of the warped grid
    report["region_thresholds"] = {}
    for index in range(fe_warped.GetCellData().GetNumberOfArrays()):
        indicator = fe_warped.GetCellData().GetArrayName(index)
        if not indicator.startswith("region: "):
            continue
        threshold = Threshold(Input=warp)
        threshold.Scalars = ["CELLS", indicator]
        threshold.LowerThreshold = 1
        threshold.UpperThreshold = 1
        threshold.UpdatePipeline(show)
        blocks = [blk for _, blk in leaves(sm.Fetch(threshold)) if blk.GetNumberOfCells()]
        report["region_thresholds"][indicator] = {
            "cells": sum(blk.GetNumberOfCells() for blk in blocks),
            "region_range": [min(blk.GetCellData().GetArray("region").GetRange()[0] for blk in blocks),
                             max(blk.GetCellData().GetArray("region").GetRange()[1] for blk in blocks)]
            if blocks else None,
            "warped_bounds": list(blocks[0].GetBounds()) if blocks else None}
        Delete(threshold)
    body_warp = None
    if body_readers:
        body_readers["Xdmf3ReaderT"].UpdatePipeline(show)
        report["body_bounds_before"] = body_bounds(sm.Fetch(body_readers["Xdmf3ReaderT"]))
        body_warp = WarpByVector(Input=body_readers["Xdmf3ReaderT"])
        body_warp.Vectors = ["POINTS", "displacement"]
        body_warp.ScaleFactor = scale
        body_warp.UpdatePipeline(show)
        report["warped"]["body_bounds"] = body_bounds(sm.Fetch(body_warp))
        body_blocks = [blk for _, blk in leaves(sm.Fetch(body_readers["Xdmf3ReaderT"])) if blk.GetNumberOfCells()]
        report["body_displacement_range"] = (point_ranges(body_blocks[0]).get("displacement") if body_blocks
                                             else None)
    view = GetActiveViewOrCreate("RenderView")
    view.ViewSize = [900, 700]
    view.ViewTime = show
    view.OrientationAxesVisibility = 0
    display = Show(warp, view)
    ColorBy(display, ("POINTS", colour))
    display.RescaleTransferFunctionToDataRange(True, False)
    display.SetScalarBarVisibility(view, True)
    display.PointSize = 14
    display.RenderPointsAsSpheres = 1
    GetColorTransferFunction(colour).NanColor = [0.85, 0.2, 0.1]     # the rigid bodies (no such array)
    if body_warp is not None:
        body_display = Show(body_warp, view)
        ColorBy(body_display, ("CELLS", "body"))                        # each body its own grey
        body_colours = GetColorTransferFunction("body")
        body_colours.ApplyPreset("Grayscale", True)
        n_bodies = max(len(report.get("body_bounds_before", {})), 1)
        body_colours.RescaleTransferFunction(-1.5, float(n_bodies))    # light greys, none black
        if b[5] - b[4] > 1e-9:
            body_display.Opacity = 0.45                 # a 3D rotor over the stator: see the contact through it
    label = (f"mode at {frequency:.1f} Hz" if frequency is not None else f"t = {show * 1e3:.4g} ms")
    units = "potential [V]" if colour == "potential" else colour
    Show(Text(Text=f"{path.rsplit('/', 1)[-1]}: {label}, displacement x {scale:.3g}, colour: {units}"), view)
    view.ResetCamera()
    if b[5] - b[4] > 1e-9:                              # a 3D body: an oblique view from above, z up
        centre = [(b[0] + b[1]) / 2, (b[2] + b[3]) / 2, (b[4] + b[5]) / 2]
        camera = GetActiveCamera()
        camera.SetFocalPoint(*centre)
        camera.SetPosition(centre[0] + 1.3 * size, centre[1] - 1.6 * size, centre[2] + 1.5 * size)
        camera.SetViewUp(0.0, 0.0, 1.0)
        view.ResetCamera()
    GetActiveCamera().Zoom(0.8)
    Render(view)
    SaveScreenshot(png, view, ImageResolution=[900, 700])
    print("PIEZODYN-REPORT " + json.dumps(report))


if __name__ == "__main__":
    when = sys.argv[3] if len(sys.argv) > 3 else "last"
    main(sys.argv[1], sys.argv[2], None if when == "last" else float(when),
         sys.argv[4] if len(sys.argv) > 4 else "potential")
