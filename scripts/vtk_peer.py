#!/usr/bin/python3
"""Renders an hpray volume scene with one of VTK's unstructured-grid volume mappers, for
side-by-side benchmarks (scripts/bench_peers.sh); needs python3-vtk9 and an X server
(run it under `xvfb-run -a`).

The scene's camera and transfer functions are given to VTK as its own terms:
- camera: position, focal point = look_at, view up, view angle = fov_y (vertical);
- colour: a vtkColorTransferFunction through the scene's color_tf points (RGB);
- extinction: a vtkPiecewiseFunction through the extinction_tf points with the scalar
  opacity unit distance 1, so VTK's attenuation coefficient (opacity / unit distance, as
  vtkUnstructuredGridLinearRayIntegrator reads it) is the scene's extinction per world
  unit. The linear ray integrator then computes the same emission-absorption integral as
  hpray's `glow: williams-max` (colour times extinction, attenuated), to its own accuracy;
  the pre-integration table and projected tetrahedra approximate it.
The image is rendered over a black background with alpha planes, so the 8-bit RGB read
back is the premultiplied colour and A the opacity, comparable with hpray's rgba.npy
(linear, premultiplied; VTK applies no gamma). Cells other than tetrahedra are split into
tetrahedra first (vtkDataSetTriangleFilter), as these mappers require.

Usage: vtk_peer.py MAPPER SCENE_JSON OUT_NPY [--frames N]
  MAPPER: raycast-linear | raycast-preint | projected-tetrahedra
  SCENE_JSON: {"mesh", "field", "color_tf", "extinction_tf", "camera": {...}}
Prints one JSON line: load, set-up and first-frame seconds, and each later frame's
seconds (the camera turned by 1 degree per frame, so every frame renders anew).
"""
import argparse
import json
import time

import numpy as np
import vtk
from vtk.util.numpy_support import vtk_to_numpy


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mapper", choices=["raycast-linear", "raycast-preint",
                                       "projected-tetrahedra"])
    ap.add_argument("scene")
    ap.add_argument("out")
    ap.add_argument("--frames", type=int, default=3, help="later frames to time")
    args = ap.parse_args()
    scene = json.loads(args.scene)
    cam = scene["camera"]
    width, height = int(cam["width"]), int(cam["height"])

    t0 = time.perf_counter()
    reader = vtk.vtkXMLUnstructuredGridReader()
    reader.SetFileName(scene["mesh"])
    reader.Update()
    grid = reader.GetOutput()
    grid.GetPointData().SetActiveScalars(scene["field"])
    # Only tetrahedra for these mappers.
    types = vtk.vtkCellTypes()
    grid.GetCellTypes(types)
    if any(types.GetCellType(i) != vtk.VTK_TETRA for i in range(types.GetNumberOfTypes())):
        tets = vtk.vtkDataSetTriangleFilter()
        tets.SetInputData(grid)
        tets.TetrahedraOnlyOn()
        tets.Update()
        grid = tets.GetOutput()
        grid.GetPointData().SetActiveScalars(scene["field"])
    load = time.perf_counter() - t0

    color = vtk.vtkColorTransferFunction()
    color.SetColorSpaceToRGB()
    for s, r, g, b in scene["color_tf"]:
        color.AddRGBPoint(s, r, g, b)
    opacity = vtk.vtkPiecewiseFunction()
    for s, sigma in scene["extinction_tf"]:
        opacity.AddPoint(s, sigma)
    prop = vtk.vtkVolumeProperty()
    prop.SetColor(color)
    prop.SetScalarOpacity(opacity)
    prop.SetScalarOpacityUnitDistance(1.0)
    prop.ShadeOff()
    prop.SetInterpolationTypeToLinear()

    if args.mapper == "projected-tetrahedra":
        mapper = vtk.vtkProjectedTetrahedraMapper()
    else:
        mapper = vtk.vtkUnstructuredGridVolumeRayCastMapper()
        # One ray per pixel, always (by default it may sample coarser to keep frame rates).
        mapper.AutoAdjustSampleDistancesOff()
        mapper.SetImageSampleDistance(1.0)
        mapper.SetRayIntegrator(vtk.vtkUnstructuredGridLinearRayIntegrator()
                                if args.mapper == "raycast-linear"
                                else vtk.vtkUnstructuredGridPreIntegration())
    mapper.SetInputData(grid)
    mapper.SetScalarModeToUsePointFieldData()
    mapper.SelectScalarArray(scene["field"])
    volume = vtk.vtkVolume()
    volume.SetMapper(mapper)
    volume.SetProperty(prop)

    renderer = vtk.vtkRenderer()
    renderer.SetBackground(0, 0, 0)
    renderer.SetBackgroundAlpha(0)
    renderer.AddVolume(volume)
    window = vtk.vtkRenderWindow()
    window.SetOffScreenRendering(1)
    window.SetAlphaBitPlanes(1)
    window.SetMultiSamples(0)
    window.SetSize(width, height)
    window.AddRenderer(renderer)
    camera = renderer.GetActiveCamera()
    camera.SetPosition(*cam["position"])
    camera.SetFocalPoint(*cam["look_at"])
    camera.SetViewUp(*cam.get("up", [0, 1, 0]))
    camera.SetViewAngle(cam["fov_y"])
    # Measured: without it VTK's picture sits half a pixel up and to the right of the
    # pixel centres hpray samples (docs/contracts.md, Camera); shifting the projection
    # centre by half a pixel (1/W of the [-1, 1] viewport) aligns the two.
    camera.SetWindowCenter(1.0 / width, 1.0 / height)
    renderer.ResetCameraClippingRange()

    t1 = time.perf_counter()
    window.Render()
    grab = vtk.vtkWindowToImageFilter()
    grab.SetInput(window)
    grab.SetInputBufferTypeToRGBA()
    grab.ReadFrontBufferOff()
    grab.Update()
    first = time.perf_counter() - t1
    image = grab.GetOutput()
    pixels = vtk_to_numpy(image.GetPointData().GetScalars()).reshape(height, width, 4)
    rgba = pixels[::-1].astype(np.float64) / 255.0  # VTK's first row is the bottom one
    np.save(args.out, rgba)

    later = []
    for _ in range(args.frames):
        camera.Azimuth(1.0)
        renderer.ResetCameraClippingRange()
        t = time.perf_counter()
        window.Render()
        grab.Modified()
        grab.Update()
        later.append(time.perf_counter() - t)
    print(json.dumps({"mapper": args.mapper, "load_s": load, "first_render_s": first,
                      "later_s": later}))


if __name__ == "__main__":
    main()
