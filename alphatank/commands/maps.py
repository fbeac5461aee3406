"""``alphatank maps``: list shipped maps (and the map folders ``train/``, ``test/``), or
check and print given ones."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from alphatank.sim.mapspec import (
    MapError,
    load_map,
    map_text,
    shipped_map_folders,
    shipped_maps,
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("maps", nargs="*", metavar="MAP",
                   help="map names, .txt paths or folders (a shipped one like 'train', or a "
                        "path) to validate and print (default: list all)")


def _expand(items: list[str]) -> list[str]:
    """Folders (paths or shipped folder names) expand to their maps; the rest stay."""
    out: list[str] = []
    for item in items:
        path = Path(item)
        if item and path.is_dir():  # not '': Path('') is the current folder
            found = sorted(str(f) for f in path.glob("*.txt"))
            if not found:
                raise MapError("folder holds no .txt maps", item)
            out += found
        elif item.strip("/") in shipped_map_folders():
            out += shipped_maps(item.strip("/"))
        else:
            out.append(item)
    return out


def run(args: argparse.Namespace) -> int:
    if not args.maps:
        folders = shipped_map_folders()
        names = shipped_maps() + [m for f in folders for m in shipped_maps(f)]
        width = max(len(name) for name in names)  # train_d8/... names are the longest
        print(f"{'name':{width}s} {'rows x cols':11s} {'spawns':>6s}  description")
        for name in names:
            spec = load_map(name)  # ROWSxCOLS, as tools/mapgen.py --size takes it
            print(f"{name:{width}s} {spec.rows:>4d} x {spec.cols:<4d} {len(spec.spawns):>6d}  "
                  f"{spec.description}")
        for folder in folders:
            print(f"folder {folder}/: {len(shipped_maps(folder))} maps (a scenario's "
                  f"map = \"{folder}\" draws one per episode)")
        return 0
    status = 0
    for name in _expand(args.maps):
        try:
            spec = load_map(name)
        except MapError as err:  # bad input, as everywhere: one line each, exit 2
            print(f"alphatank maps: error: {err}", file=sys.stderr)
            status = 2
            continue
        print(f"{spec.source}: ok, {spec.rows} rows x {spec.cols} cols of {spec.cell:g} px, "
              f"{len(spec.wall_rects)} wall boxes")
        print(map_text(spec))
    return status
