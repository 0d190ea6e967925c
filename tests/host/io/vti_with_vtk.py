#!/usr/bin/env python3
"""Reads a .vti file with VTK's own reader (Debian python3-vtk9) and prints what a ParaView user
would see of it as JSON: dimensions, origin, spacing, the point arrays' values at given points and
the field-data arrays. tests/host/io/test_formats_netcdf.cpp compares this with what tfmatch wrote.

usage: vti_with_vtk.py FILE.vti ARRAY [I,J,K ...]
"""
import json
import sys

import vtk  # noqa: F401  (the package the test checks for)
from vtkmodules.vtkIOXML import vtkXMLImageDataReader


def main():
    path, array = sys.argv[1], sys.argv[2]
    reader = vtkXMLImageDataReader()
    reader.SetFileName(path)
    reader.Update()
    image = reader.GetOutput()
    dims = image.GetDimensions()
    values = image.GetPointData().GetArray(array)
    points = {}
    for text in sys.argv[3:]:
        i, j, k = (int(t) for t in text.split(","))
        points[text] = values.GetValue(i + dims[0] * (j + dims[1] * k))
    fields = {}
    fd = image.GetFieldData()
    for a in range(fd.GetNumberOfArrays()):
        arr = fd.GetArray(a)
        fields[arr.GetName()] = [arr.GetValue(t) for t in range(arr.GetNumberOfTuples())]
    print(json.dumps({"dims": list(dims), "origin": list(image.GetOrigin()), "spacing": list(image.GetSpacing()),
                      "points": points, "field_data": fields}))


if __name__ == "__main__":
    main()
