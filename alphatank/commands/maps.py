"""``alphatank maps``: list shipped maps, or check and print given ones."""

from __future__ import annotations

import argparse

from alphatank.sim.mapspec import MapError, load_map, map_text, shipped_maps


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("maps", nargs="*", metavar="MAP",
                   help="map names or .txt paths to validate and print (default: list all)")


def run(args: argparse.Namespace) -> int:
    if not args.maps:
        print(f"{'name':14s} {'size':>7s} {'spawns':>6s}  description")
        for name in shipped_maps():
            spec = load_map(name)
            print(f"{name:14s} {spec.cols:>3d}x{spec.rows:<3d} {len(spec.spawns):>6d}  "
                  f"{spec.description}")
        return 0
    status = 0
    for name in args.maps:
        try:
            spec = load_map(name)
        except MapError as err:
            print(f"error: {err}")
            status = 1
            continue
        print(f"{spec.source}: ok, {spec.cols}x{spec.rows} cells of {spec.cell:g} px, "
              f"{len(spec.wall_rects)} wall boxes")
        print(map_text(spec))
    return status
