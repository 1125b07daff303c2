#!/usr/bin/env python3
"""Meshes STEP files with OpenCascade's BRepMesh (cadquery-ocp, from the
test venv), as FreeCAD and PrusaSlicer do, and says whether each mesh is
closed: edges used by one triangle (open) or by more than two, and its
connected pieces.

    .venv/bin/python scripts/step-mesh-check.py OUT/*.step [--deflections 0.1,0.05,0.01,0.005]
"""
import argparse
import pathlib
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests" / "python"))
from test_step_oracles import BRepMeshed  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("steps", nargs="+", type=pathlib.Path)
    parser.add_argument("--deflections", default="0.1,0.05,0.01,0.005")
    args = parser.parse_args()
    deflections = [float(d) for d in args.deflections.split(",")]
    closed_everywhere = True
    for step in args.steps:
        for deflection in deflections:
            start = time.monotonic()
            meshed = BRepMeshed(step, deflection)
            pieces = meshed.pieces()
            closed_everywhere &= meshed.closed
            verdict = "closed" if meshed.closed else "NOT closed"
            print(
                f"{step}  {deflection:g} mm: {verdict}, {meshed}, {pieces} pieces, "
                f"{len(meshed.mesh.faces)} triangles ({time.monotonic() - start:.1f} s)",
                flush=True,
            )
    return 0 if closed_everywhere else 1


if __name__ == "__main__":
    sys.exit(main())
