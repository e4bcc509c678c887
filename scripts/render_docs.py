"""Render the docs' pictures: each shipped scene a page shows, run and drawn as its result.

Each picture runs a shipped scene (configs/, one rank, in this process, through the command
line's own entry), reads its result file with h5py (or, for the guide's ParaView section, its
XDMF file through VTK's XDMF reader, the one ParaView uses), and draws with VTK off screen the
deformed mesh (displacements scaled up to be seen) colored by a field, with a color bar, into
docs/img/scenes/NAME.png. scripts/docs.sh runs it before building the site; the PNGs are
committed too, so the pages show them without a build.

    python scripts/render_docs.py              # every picture (about 30 s on one core)
    python scripts/render_docs.py kirsch ...   # some of them
    python scripts/render_docs.py --out DIR    # elsewhere (the tests)
    python scripts/render_docs.py --result kirsch.h5 --field fields/stress --component 0 \
        --png kirsch.png                       # your own result (any parsolve result file)
"""
from __future__ import annotations

import argparse
import contextlib
import io
import os
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
IMAGES = ROOT / "docs" / "img" / "scenes"
SIZE = (900, 520)
# VTK cell types of the meshio names parsolve writes (meshio's node order is VTK's)
VTK_CELLS = {"line": 3, "triangle": 5, "quad": 9, "tetra": 10, "hexahedron": 12, "wedge": 13,
             "triangle6": 22, "quad8": 23, "tetra10": 24, "quad9": 28, "hexahedron27": 29}
CELL_DIM = {"line": 1, "triangle": 2, "quad": 2, "triangle6": 2, "quad8": 2, "quad9": 2,
            "tetra": 3, "hexahedron": 3, "wedge": 3, "tetra10": 3, "hexahedron27": 3}


@dataclass(frozen=True)
class Picture:
    name: str            # the PNG's name, docs/img/scenes/<name>.png
    scene: str           # the shipped scene, configs/<scene>.toml
    field: str           # "fields/<name>" or "cell_fields/<name>"
    component: int | str  # a component index, or "magnitude"
    label: str           # the color bar's title
    step: int = -1       # the saved step shown
    warp: float = 0.05   # the largest displacement drawn as this fraction of the model's size
    factor: float | None = None   # or drawn × this factor (1: as computed)
    view: str = "xy"     # "xy" (2D, from +z) or "iso" (3D)
    xdmf: bool = False   # read through the XDMF file (VTK's reader) instead of h5py
    box: tuple | None = None   # 2D: the part shown, (xmin, xmax, ymin, ymax); None: all


PICTURES = [
    Picture("kirsch", "kirsch", "fields/stress", 0, "stress xx (traction 1 along x)",
            box=(0.0, 5.0, 0.0, 3.0)),
    Picture("cantilever_3d", "cantilever_3d", "fields/displacement", "magnitude",
            "displacement magnitude", warp=0.08, view="iso"),
    Picture("plate_hole_control", "plate_hole_control", "cell_fields/damage", 0,
            "Mazars damage D (last step)", warp=0.0),
    Picture("contact_ironing_2d", "contact_ironing_2d", "fields/stress", 1,
            "stress yy (last step)", factor=1.0, box=(-0.1, 4.1, -0.05, 1.5)),
    Picture("solubility_two_regions", "solubility_two_regions", "fields/c_s", 0,
            "dissolved concentration c_s, step 50 (c_sat 1 for x < 0.5, 0.5 beyond)", step=49, warp=0.0,
            box=(0.0, 1.0, -0.02, 0.07)),
    Picture("controlled_bar", "controlled_bar", "fields/displacement", 0,
            "displacement x (mean end displacement controlled)", warp=0.0),
    Picture("kirsch_xdmf", "kirsch", "fields/displacement", "magnitude",
            "displacement magnitude (read from kirsch.xdmf)", xdmf=True),
    Picture("periodic_shear_laminate", "periodic_shear_laminate", "fields/stress", 2,
            "stress xy (uniform: periodic shear)", warp=0.15),
    Picture("axisym_thick_cylinder", "axisym_thick_cylinder", "fields/stress", 3,
            "hoop stress (theta theta)", warp=0.08),
    Picture("thick_cylinder_pressure", "thick_cylinder_pressure", "fields/displacement",
            "magnitude", "displacement magnitude (pressure on the curved bore)", warp=0.0),
]


def run_scene(scene: str, folder: Path) -> Path:
    """The shipped scene run in this process, one rank; its result file."""
    from parsolve.cli import main

    out = folder / f"{scene}.h5"
    with contextlib.redirect_stdout(io.StringIO()):
        status = main(["run", str(ROOT / "configs" / f"{scene}.toml"), "-o", str(out)])
    if status != 0:
        raise SystemExit(f"render_docs: configs/{scene}.toml: parsolve run exited {status}")
    return out


def read_h5(path: Path, picture: Picture):
    """(points (n, 3), [(cell type, connectivity)], values per point or cell, per-point
    displacement (n, 3) or None) of one saved step."""
    import h5py

    with h5py.File(path, "r") as f:
        points = np.asarray(f["mesh/points"], dtype=float)
        cells = [(name, np.asarray(f["mesh/cells"][name])) for name in f["mesh/cells"]]
        data = np.asarray(f[picture.field][picture.step])
        u = np.asarray(f["fields/displacement"][picture.step]) if "displacement" in f["fields"] \
            else None
    pad = lambda a: np.hstack([a, np.zeros((len(a), 3 - a.shape[1]))])   # noqa: E731
    return pad(points), cells, _scalar(data, picture.component), None if u is None else pad(u)


def _scalar(data: np.ndarray, component) -> np.ndarray:
    if component == "magnitude":
        return np.linalg.norm(data, axis=1)
    return data[:, component]


def unstructured(points: np.ndarray, cells: list, values: np.ndarray):
    """A vtkUnstructuredGrid of the highest-dimension cells, values on points or cells."""
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray

    top = max(CELL_DIM[name] for name, _ in cells)
    kept = [(name, conn) for name, conn in cells if CELL_DIM[name] == top]
    grid = vtk.vtkUnstructuredGrid()
    vpoints = vtk.vtkPoints()
    vpoints.SetData(numpy_to_vtk(np.ascontiguousarray(points), deep=True))
    grid.SetPoints(vpoints)
    types = np.concatenate([np.full(len(c), VTK_CELLS[n], dtype=np.uint8) for n, c in kept])
    offsets = np.concatenate([[0], np.cumsum([c.shape[1] for _, c in kept for _ in range(len(c))])])
    conn = np.concatenate([c.ravel() for _, c in kept]).astype(np.int64)
    cell_array = vtk.vtkCellArray()
    cell_array.SetData(numpy_to_vtkIdTypeArray(offsets.astype(np.int64), deep=True),
                       numpy_to_vtkIdTypeArray(conn, deep=True))
    grid.SetCells(numpy_to_vtk(types, deep=True, array_type=vtk.VTK_UNSIGNED_CHAR), cell_array)
    ncells = sum(len(c) for _, c in kept)
    array = numpy_to_vtk(np.ascontiguousarray(values, dtype=float), deep=True)
    array.SetName("value")
    if len(values) == len(points):
        grid.GetPointData().SetScalars(array)
    else:                                  # cell values in /mesh/cells order: the kept cells
        first = sum(len(c) for n, c in cells if CELL_DIM[n] != top and n < kept[0][0])
        array = numpy_to_vtk(np.ascontiguousarray(values[first:first + ncells], dtype=float),
                             deep=True)
        array.SetName("value")
        grid.GetCellData().SetScalars(array)
    return grid


def read_xdmf(xdmf: Path, picture: Picture):
    """The grid of the last step as VTK's XDMF reader (ParaView's) gives it, warped, with the
    picture's scalar."""
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk, vtk_to_numpy

    reader = vtk.vtkXdmfReader()
    reader.SetFileName(str(xdmf))
    reader.UpdateInformation()
    steps = reader.GetOutputInformation(0).Get(vtk.vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    if steps:
        reader.UpdateTimeStep(steps[picture.step])
    reader.Update()
    data = reader.GetOutputDataObject(0)
    if data.IsA("vtkMultiBlockDataSet"):
        data = data.GetBlock(0)
    name = picture.field.split("/", 1)[1]
    block = data.GetPointData().GetArray(name)
    if block is None:
        raise SystemExit(f"render_docs: {xdmf.name}: no point array {name!r}")
    values = _scalar(vtk_to_numpy(block).reshape(data.GetNumberOfPoints(), -1), picture.component)
    grid = vtk.vtkUnstructuredGrid()
    grid.DeepCopy(data)
    array = numpy_to_vtk(np.ascontiguousarray(values), deep=True)
    array.SetName("value")
    grid.GetPointData().SetScalars(array)
    u = grid.GetPointData().GetArray("displacement")
    return grid, None if u is None else vtk_to_numpy(u).reshape(-1, 3)


def warp(grid, u: np.ndarray | None, fraction: float, factor: float | None = None) -> float:
    """Move the points by s·u, s = ``factor`` or the one making the largest displacement
    ``fraction`` of the model's size (0: undeformed); returns s."""
    from vtk.util.numpy_support import numpy_to_vtk, vtk_to_numpy

    if u is None or fraction == 0.0:
        return 0.0
    points = vtk_to_numpy(grid.GetPoints().GetData()).copy()
    size = float(np.max(np.ptp(points, axis=0)))
    umax = float(np.max(np.linalg.norm(u, axis=1)))
    if umax == 0.0:
        return 0.0
    scale = factor if factor is not None else fraction * size / umax
    grid.GetPoints().SetData(numpy_to_vtk(points + scale * u, deep=True))
    return scale


def draw(grid, picture: Picture, scale: float, out: Path) -> None:
    """The grid's outer surface colored by its scalar, edges on coarse meshes, a color bar and a
    title, written as a PNG."""
    import vtk

    surface = vtk.vtkDataSetSurfaceFilter()
    surface.SetInputData(grid)
    surface.SetNonlinearSubdivisionLevel(2)     # curved P2 edges drawn as such
    surface.Update()
    low, high = grid.GetPointData().GetScalars().GetRange() if grid.GetPointData().GetScalars() \
        else grid.GetCellData().GetScalars().GetRange()
    if high - low < 1e-12 * max(1.0, abs(high)):     # a uniform field: widen around it
        low, high = low - 0.5 * max(abs(low), 1e-12), high + 0.5 * max(abs(high), 1e-12)
    table = vtk.vtkLookupTable()
    table.SetHueRange(0.667, 0.0)                  # blue (low) to red (high)
    table.SetTableRange(low, high)
    table.Build()
    mapper = vtk.vtkDataSetMapper()
    mapper.SetInputConnection(surface.GetOutputPort())
    mapper.SetLookupTable(table)
    mapper.SetScalarRange(low, high)
    mapper.SetScalarModeToDefault()
    actor = vtk.vtkActor()
    actor.SetMapper(mapper)
    renderer = vtk.vtkRenderer()
    renderer.SetBackground(1.0, 1.0, 1.0)
    renderer.AddActor(actor)
    if grid.GetNumberOfCells() <= 2500:             # the mesh's edges where they can be seen
        edges = vtk.vtkExtractEdges()
        edges.SetInputData(grid)
        edge_mapper = vtk.vtkPolyDataMapper()
        edge_mapper.SetInputConnection(edges.GetOutputPort())
        edge_mapper.ScalarVisibilityOff()
        edge_actor = vtk.vtkActor()
        edge_actor.SetMapper(edge_mapper)
        edge_actor.GetProperty().SetColor(0.15, 0.15, 0.15)
        edge_actor.GetProperty().SetOpacity(0.5)
        renderer.AddActor(edge_actor)
    bar = vtk.vtkScalarBarActor()
    bar.SetLookupTable(table)
    bar.SetTitle(picture.label)
    bar.SetNumberOfLabels(5)
    bar.SetLabelFormat("%-#9.3g")
    bar.SetOrientationToHorizontal()
    bar.SetPosition(0.2, 0.02)
    bar.SetWidth(0.6)
    bar.SetHeight(0.14)
    for prop in (bar.GetTitleTextProperty(), bar.GetLabelTextProperty()):
        prop.SetColor(0.0, 0.0, 0.0)
        prop.ShadowOff()
        prop.ItalicOff()
        prop.BoldOff()
        prop.SetFontSize(14)
    title = vtk.vtkTextActor()
    deformed = f", displacements × {scale:.3g}" if scale else ""
    source = picture.scene if picture.scene.endswith(".h5") else f"configs/{picture.scene}.toml"
    title.SetInput(f"{source}{deformed}")
    title.GetTextProperty().SetColor(0.0, 0.0, 0.0)
    title.GetTextProperty().SetFontSize(16)
    title.SetPosition(10, SIZE[1] - 28)
    camera = renderer.GetActiveCamera()
    if picture.view == "iso":
        camera.SetPosition(1.0, -1.6, 1.2)
        camera.SetViewUp(0.0, 0.0, 1.0)
    else:
        camera.SetPosition(0.0, 0.0, 1.0)
        camera.SetViewUp(0.0, 1.0, 0.0)
        camera.ParallelProjectionOn()
    camera.SetFocalPoint(0.0, 0.0, 0.0)
    renderer.SetViewport(0.0, 0.2, 1.0, 0.94)
    renderer.ResetCamera()
    if picture.box is not None:                   # the part of interest, filling the height
        x0, x1, y0, y1 = picture.box
        aspect = SIZE[0] / (0.74 * SIZE[1])
        camera.SetFocalPoint(0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0)
        camera.SetPosition(0.5 * (x0 + x1), 0.5 * (y0 + y1), 10.0 * max(x1 - x0, y1 - y0))
        camera.SetParallelScale(0.5 * max(y1 - y0, (x1 - x0) / aspect))
        renderer.ResetCameraClippingRange()
    else:
        camera.Zoom(1.05)
    window = vtk.vtkRenderWindow()
    window.SetOffScreenRendering(1)
    window.SetSize(*SIZE)
    window.AddRenderer(renderer)
    background = vtk.vtkRenderer()                # the white margins around the viewport
    background.SetBackground(1.0, 1.0, 1.0)
    background.SetLayer(0)
    renderer.SetLayer(1)
    window.SetNumberOfLayers(2)
    window.AddRenderer(background)
    background.AddViewProp(title)
    background.AddViewProp(bar)
    window.Render()
    shot = vtk.vtkWindowToImageFilter()
    shot.SetInput(window)
    shot.ReadFrontBufferOff()
    shot.Update()
    writer = vtk.vtkPNGWriter()
    writer.SetFileName(str(out))
    writer.SetInputConnection(shot.GetOutputPort())
    writer.Write()


def render(picture: Picture, folder: Path, results: dict[str, Path], out_dir: Path) -> Path:
    if picture.scene not in results:
        results[picture.scene] = run_scene(picture.scene, folder)
    return draw_result(results[picture.scene], picture, out_dir / f"{picture.name}.png")


def draw_result(result: Path, picture: Picture, out: Path) -> Path:
    """One picture of a result file (h5py, or its XDMF through VTK's reader)."""
    if picture.xdmf:
        grid, u = read_xdmf(result.with_suffix(".xdmf"), picture)
    else:
        points, cells, values, u = read_h5(result, picture)
        grid = unstructured(points, cells, values)
    scale = warp(grid, u, picture.warp, picture.factor)
    draw(grid, picture, scale, out)
    return out


def own_result(args) -> int:
    """--result: a picture of the user's own result file."""
    import h5py

    result = args.result
    with h5py.File(result, "r") as f:
        if args.field not in f:
            known = [f"{g}/{n}" for g in ("fields", "cell_fields") for n in f.get(g, {})]
            raise SystemExit(f"render_docs: {result}: no {args.field!r} (known: {', '.join(known)})")
        ncomp = f[args.field].shape[2]
    component = "magnitude" if args.component == "magnitude" else int(args.component)
    if component != "magnitude" and not 0 <= component < ncomp:
        raise SystemExit(f"render_docs: --component: {component} out of 0..{ncomp - 1}")
    label = args.field.split("/", 1)[1] + (f" [{component}]" if ncomp > 1 else "")
    picture = Picture(args.png.stem, result.name, args.field, component, label, step=args.step,
                      warp=args.warp, view="iso" if args.iso else "xy")
    out = draw_result(result, picture, args.png)
    print(f"render_docs: {out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="pictures to make (default: all)")
    parser.add_argument("--out", type=Path, default=IMAGES, help="folder of the PNGs")
    own = parser.add_argument_group("your own result (instead of the docs' pictures)")
    own.add_argument("--result", type=Path, help="a parsolve result file (RESULT.h5)")
    own.add_argument("--field", default="fields/displacement",
                     help="fields/NAME or cell_fields/NAME (default fields/displacement)")
    own.add_argument("--component", default="magnitude", help="an index or 'magnitude'")
    own.add_argument("--step", type=int, default=-1, help="saved step (default the last)")
    own.add_argument("--warp", type=float, default=0.05,
                     help="largest displacement drawn as this fraction of the size (0: none)")
    own.add_argument("--iso", action="store_true", help="3D view (default: 2D, from +z)")
    own.add_argument("--png", type=Path, default=Path("result.png"), help="the picture")
    args = parser.parse_args(argv)
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    if args.result is not None:
        return own_result(args)
    known = {p.name: p for p in PICTURES}
    unknown = [n for n in args.names if n not in known]
    if unknown:
        parser.error(f"unknown picture(s) {', '.join(unknown)} (known: {', '.join(known)})")
    # VTK's off-screen window without an X server (EGL), and quiet about the X one it lacks
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    args.out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    results: dict[str, Path] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for picture in [known[n] for n in args.names] or PICTURES:
            out = render(picture, Path(tmp), results, args.out)
            print(f"render_docs: {out.relative_to(ROOT) if out.is_relative_to(ROOT) else out}")
    print(f"render_docs: {len(results)} scenes run, {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
