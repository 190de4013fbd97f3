#!/usr/bin/env python3
"""Decode a MATLAB level-5 MAT file with scipy (an independent reader) and print every numeric
array of every top-level struct (and nested 1x1 struct) as JSON: path, dimensions and the values
in column-major order, NaN as null. Character arrays are printed as strings.

Usage: read_mat.py FILE.mat
"""
import json
import math
import sys

import numpy as np
import scipy.io


def walk(prefix, value, out):
    if isinstance(value, np.ndarray) and value.dtype.names is not None:
        if value.size != 1:
            out["unsupported"].append(prefix)
            return
        record = value.reshape(-1)[0]
        for name in value.dtype.names:
            walk(f"{prefix}.{name}" if prefix else name, record[name], out)
    elif isinstance(value, np.ndarray) and value.dtype.kind in "fiub":
        flat = value.astype(np.float64).flatten(order="F")
        out["numeric"][prefix] = {
            "dims": list(value.shape),
            "values": [None if math.isnan(x) else x for x in flat.tolist()],
        }
    elif isinstance(value, np.ndarray) and value.dtype.kind == "U":
        out["char"][prefix] = "".join(value.flatten(order="F").tolist())
    else:
        out["unsupported"].append(prefix)


def main():
    m = scipy.io.loadmat(sys.argv[1], squeeze_me=False, struct_as_record=True)
    out = {"header": m["__header__"].decode("latin-1"), "numeric": {}, "char": {}, "unsupported": []}
    for name, value in m.items():
        if not name.startswith("__"):
            walk(name, value, out)
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
