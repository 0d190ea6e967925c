#!/usr/bin/env python3
"""Reads a .pvti (ParaView parallel image data) with VTK's own reader (Debian python3-vtk9) and
writes what a ParaView user would load: the whole grid's first point array as float32 raw, x
fastest, and its dimensions on stdout. tests/tools/test_mpi_cli.cpp compares the values with the
field one process wrote.

usage: pvti_with_vtk.py FILE.pvti OUT.raw
"""
import sys

import vtk  # noqa: F401  (the package the test checks for)
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkIOXML import vtkXMLPImageDataReader


def main():
    reader = vtkXMLPImageDataReader()
    reader.SetFileName(sys.argv[1])
    reader.Update()
    image = reader.GetOutput()
    array = image.GetPointData().GetArray(0)
    if array is None:
        sys.exit("no point array (a piece could not be read)")
    vtk_to_numpy(array).astype("<f4").tofile(sys.argv[2])
    print(*image.GetDimensions())


if __name__ == "__main__":
    main()
