"""Generate, validate, preview and edit AlphaTank maps (docs/mapgen.md).

    python tools/mapgen.py generate --size 11x11 --algorithm maze --symmetry mirror -o maps/new.txt
    python tools/mapgen.py batch --count 20 --seed 0 --out maps --split 0.8
    python tools/mapgen.py validate maps/*.txt maps/train
    python tools/mapgen.py variants maps/train --out maps/train_d8
    python tools/mapgen.py preview maps/new.txt --png new.png
    python tools/mapgen.py edit maps/new.txt

A thin command line over ``alphatank.mapgen`` (generators, warnings, editor model) and
``alphatank.mapgen.editor`` (the pygame editor). Validation is the game's own loader.
"""

from __future__ import annotations

import argparse
import os
import sys
from fractions import Fraction
from pathlib import Path

from alphatank.cli import Parser, broken_pipe_exit
from alphatank.commands.argtypes import given, in_range, int_in_range, scale
from alphatank.commands.argtypes import seed as seed_type
from alphatank.errors import InputError, one_line
from alphatank.files import check_folder, check_writable, write_atomic, write_text_atomic
from alphatank.mapgen import (
    ALGORITHMS,
    SYMMETRIES,
    EditorModel,
    GenOptions,
    MapGenError,
    ascii_art,
    check_map,
    check_name,
    describe,
    generate_from,
    map_variants,
    map_warnings,
)
from alphatank.mapgen.generate import MAX_SIZE, MAX_SPAWNS, MIN_SIZE
from alphatank.sim.mapspec import (
    MapError,
    MapSpec,
    load_map,
    map_text,
    parse_map,
    shipped_map_folders,
    shipped_maps,
)


def parse_size(text: str, low: int = MIN_SIZE) -> tuple[int, int]:
    """``--size``: ``"11x13"`` -> (11 rows, 13 cols); ``"11"`` -> (11, 11); each in
    [``low``, MAX_SIZE] (``edit`` makes blank maps down to 3 x 3)."""
    parts = text.lower().split("x")
    try:
        rows, cols = (int(parts[0]), int(parts[-1])) if len(parts) <= 2 else (0, 0)
    except ValueError:
        rows = cols = 0
    if not (low <= rows <= MAX_SIZE and low <= cols <= MAX_SIZE):
        raise argparse.ArgumentTypeError(f"--size must be ROWSxCOLS like 11x11, each in "
                                         f"[{low}, {MAX_SIZE}], got {text!r}")
    return rows, cols


def parse_density(text: str) -> float:
    """``--density``: a wall share in [0, 1)."""
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0.0 <= value < 1.0:
        raise argparse.ArgumentTypeError(f"must be a number in [0, 1), got {text!r}")
    return value


def parse_zones(text: str) -> tuple[int, int] | None:
    """``"2,2"`` -> (2 buff, 2 debuff); ``"3"`` -> (3, 3); ``"random"`` -> None."""
    if text == "random":
        return None
    try:
        nums = [int(p) for p in text.split(",")]
    except ValueError:
        nums = []
    if len(nums) not in (1, 2) or min(nums) < 0:
        raise argparse.ArgumentTypeError(
            f"zones must be BUFF,DEBUFF counts like 2,2 (or one count, or 'random'), got {text!r}")
    return (nums[0], nums[-1])


def parse_teams(text: str) -> str:
    """``--teams``: the team of each spawn slot, one letter or digit each (``AABB``); a
    match needs at least 2 tanks in at least 2 teams."""
    if len(set(text)) < 2 or not text.isalnum():
        raise argparse.ArgumentTypeError(
            f"must be the team of each slot, one letter or digit each, at least 2 teams "
            f"(like AB or AABB), got {text!r}")
    return text


def _split_list(text: str, allowed: tuple[str, ...], what: str) -> list[str]:
    items = [s.strip() for s in text.split(",") if s.strip()]
    bad = [s for s in items if s not in allowed]
    if bad or not items:
        raise argparse.ArgumentTypeError(f"{what} must be one or more of {list(allowed)} "
                                         f"(comma-separated), got {text!r}")
    return items


def one_value(text: str) -> str:
    """An option of ``generate`` that ``batch`` takes as a list: one value here."""
    if "," in text:
        raise argparse.ArgumentTypeError(f"takes one value in generate (comma-separated lists "
                                         f"are for batch), got {text!r}")
    return text


def map_name(text: str) -> str:
    """``--name``: what :func:`~alphatank.mapgen.generate.check_name` allows."""
    try:
        return check_name(text)
    except MapGenError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _add_gen_options(p: argparse.ArgumentParser, lists: bool) -> None:
    many = " (comma-separated list: cycled over the maps)" if lists else ""
    kind = str if lists else one_value
    p.add_argument("--size", type=kind, default="11x11", help=f"ROWSxCOLS (default 11x11){many}")
    p.add_argument("--algorithm", type=kind, default="maze",
                   help=f"one of {', '.join(ALGORITHMS)} (default maze){many}")
    p.add_argument("--density", type=parse_density, default=0.25,
                   help="target wall share of the interior, 0..1 (default 0.25; maze: fixed)")
    p.add_argument("--symmetry", type=kind, default="none",
                   help=f"one of {', '.join(SYMMETRIES)} (default none){many}")
    p.add_argument("--spawns", type=int_in_range(0, MAX_SPAWNS), default=2,
                   help=f"spawn slots 0..{MAX_SPAWNS} (default 2)")
    p.add_argument("--zones", type=parse_zones, default=(2, 2),
                   help="BUFF,DEBUFF zone cells, or 'random' (default 2,2)")
    p.add_argument("--loops", type=in_range(0.0, 1.0), default=0.1,
                   help="share of thin walls knocked out to make loops, 0..1 (default 0.1)")
    p.add_argument("--seed", type=seed_type, default=0, help="random seed (default 0)")
    p.add_argument("--force", action="store_true", help="overwrite existing files")


def options_from_args(args: argparse.Namespace, i: int = 0, seed: int | None = None
                      ) -> GenOptions:
    """Generator options for map ``i`` of a run (lists cycle over size x algorithm x symmetry)."""
    sizes = [parse_size(s) for s in args.size.split(",")]
    algs = _split_list(args.algorithm, ALGORITHMS, "--algorithm")
    syms = _split_list(args.symmetry, SYMMETRIES, "--symmetry")
    combos = [(s, a, y) for s in sizes for a in algs for y in syms]
    (rows, cols), alg, sym = combos[i % len(combos)]
    return GenOptions(rows, cols, alg, args.density, sym, args.spawns, args.zones, args.loops,
                      args.seed if seed is None else seed)


def _file_stem(spec: MapSpec, use: str) -> str:
    """The map's name as the stem of a file it names (``use``); MapGenError when it is not
    one plain file name (a ``name:`` header such as ``../x`` or ``a/b`` would put the file
    outside its folder)."""
    if spec.name in (".", "..") or any(ch in spec.name for ch in "/\\\0"):
        raise MapGenError(f"{spec.source}: map name {spec.name!r} cannot name {use}; give "
                          "the map a name: header without '/' or '\\' (and not '.' or '..')")
    return spec.name


def _write(spec: MapSpec, path: Path, force: bool) -> tuple[MapSpec, str]:
    """Write ``spec`` to ``path`` (a device such as /dev/stdout gets the text written into
    it); returns the map as the game's loader reads the file, and the file's text."""
    if path.is_file() and not force:
        raise FileExistsError(f"{path} exists (use --force to overwrite)")
    text = map_text(spec)
    written = parse_map(text, str(path), name=path.stem)  # what the loader makes of it
    write_text_atomic(path, text)
    return written, text


def cmd_generate(args: argparse.Namespace) -> int:
    opts = options_from_args(args)
    name = args.name or (Path(args.output).stem if args.output else None)
    spec = generate_from(opts, name)
    if args.output is None:
        sys.stdout.write(map_text(spec))
        for w in map_warnings(spec):
            print(w, file=sys.stderr)
        return 0
    check_writable(args.output, "--output")
    path = Path(args.output)
    written, text = _write(spec, path, args.force)
    print(f"wrote {path}: {describe(spec)}")
    for w in map_warnings(written, text):
        print(w)
    return 0


def cmd_batch(args: argparse.Namespace) -> int:
    if args.count < 1:
        raise MapGenError(f"--count must be >= 1, got {args.count}")
    check_folder(args.out, "--out")
    out = Path(args.out)
    test_share = None
    if args.split is not None:
        if not 0.0 < args.split <= 1.0:
            raise MapGenError(f"--split must be in (0, 1] (the train share), got {args.split}")
        test_share = 1 - Fraction(str(args.split))
        for part in ("train", "test"):  # a file of that name would stop the batch midway
            check_folder(out / part, "--out")
    batch = []
    for i in range(args.count):
        opts = options_from_args(args, i, args.seed + i)
        spec = generate_from(opts)
        folder = out
        if test_share is not None:  # every k-th map is held out, spread over the batch
            held_out = int((i + 1) * test_share) > int(i * test_share)
            folder = out / ("test" if held_out else "train")
        batch.append((opts, spec, folder / f"{spec.name}.txt"))
    taken = [str(path) for _, _, path in batch if path.exists()]
    if taken and not args.force:  # before writing any: no half-written batch
        raise FileExistsError(f"{taken[0]} exists ({len(taken)} of the batch's files do; use "
                              f"--force to overwrite)")
    for opts, spec, path in batch:
        _write(spec, path, args.force)
        n_warn = len(map_warnings(spec))
        print(f"{path}: {opts.algorithm} {opts.rows}x{opts.cols} {opts.symmetry}, "
              f"{n_warn} warning(s)")
    return 0


def cmd_variants(args: argparse.Namespace) -> int:
    check_folder(args.out, "--out")
    out = Path(args.out)
    made: dict[Path, tuple[str, MapSpec]] = {}  # every variant first: no half-written run
    for src in _map_sources(args.maps):
        try:
            spec = load_map(src)
        except MapError as err:
            print(err)
            return 1
        _file_stem(spec, "the variants' files in --out")
        for variant in map_variants(spec):
            path = out / f"{variant.name}.txt"
            if path in made:
                raise MapGenError(f"{src} and {made[path][0]} both make {path} (their maps "
                                  f"share the name {spec.name!r}); give them different "
                                  f"name: headers")
            made[path] = (src, variant)
    taken = [str(path) for path in made if path.exists()]
    if taken and not args.force:
        raise FileExistsError(f"{taken[0]} exists ({len(taken)} of the variants' files do; "
                              f"use --force to overwrite)")
    for path, (_, variant) in made.items():
        _write(variant, path, args.force)
    print(f"wrote {len(made)} maps to {out}")
    return 0


def _map_sources(items: list[str]) -> list[str]:
    """Files and shipped names as given; folders (paths, or shipped folder names such as
    ``train``, as ``alphatank maps`` takes them) expand to their .txt maps."""
    out: list[str] = []
    for item in items:
        p = Path(item)
        if item and p.is_dir():  # not '': Path('') is the current folder
            found = sorted(str(f) for f in p.glob("*.txt"))
            out += found or [item]
        elif item.strip("/") in shipped_map_folders():
            out += shipped_maps(item.strip("/"))
        else:
            out.append(item)
    return out


def cmd_validate(args: argparse.Namespace) -> int:
    status = 0
    for src in _map_sources(args.maps):
        if src and Path(src).is_dir():
            print(f"{src}: folder holds no .txt maps")
            status = 1
            continue
        try:
            spec, warnings = check_map(src, args.teams)
        except MapError as err:
            print(err)  # exactly the game's loader message
            status = 1
            continue
        print(f"{spec.source}: ok ({describe(spec)}), {len(warnings)} warning(s)")
        for w in warnings:
            print(w)
        if warnings and args.strict:
            status = 1
    return status


def _default_teams(n: int) -> list[str]:
    """Slots 1..n//2 team A, the rest team B (the symmetric generator's convention)."""
    return ["A"] * (n // 2) + ["B"] * (n - n // 2)


def render_png(spec: MapSpec, path: Path, teams: list[str] | None = None, seed: int = 0,
               scale: float = 1.0) -> None:
    """Draw the map with tanks on their spawns using the game's renderer; save a PNG."""
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    import pygame

    from alphatank.sim.config import game_config
    from alphatank.sim.match import Match
    from alphatank.ui.render import Renderer

    teams = teams or _default_teams(max(2, len(spec.spawns)))
    match = Match(game_config(), spec, teams, seed=seed)
    labels = [str(i + 1) for i in range(len(teams))]
    renderer = Renderer(None, overlays="none", hud=False, explosions=False, scale=scale,
                        labels=labels)
    surface = renderer.draw(match)  # pygame picks the format from the temporary's suffix
    write_atomic(path, lambda tmp: pygame.image.save(surface, str(tmp)), suffix=".png")


def cmd_preview(args: argparse.Namespace) -> int:
    if args.png and not args.no_png:
        check_writable(args.png, "--png")
        if not args.png.lower().endswith(".png"):  # pygame picks the format from the name
            raise InputError(f"--png: {args.png}: must name a .png file (another name got "
                             "TGA, JPEG or BMP bytes)")
    try:
        spec, warnings = check_map(args.map, args.teams)
    except MapError as err:
        print(err)
        return 1
    png, teams = None, []
    if not args.no_png:  # what the PNG needs is checked before anything is printed
        png = Path(args.png or f"{_file_stem(spec, 'the default PNG (or give --png)')}.png")
        teams = list(args.teams or _default_teams(max(2, len(spec.spawns))))
        room = spec.tank_room(len(teams))
        if room < len(teams):
            raise MapGenError(f"{spec.source}: room for {room} tank(s) (free floor reachable "
                              f"from the spawns), the PNG draws {len(teams)} on their "
                              "spawns; give --no-png for the text preview")
    print(describe(spec))
    print(ascii_art(spec, show_fire=args.fire))
    for w in warnings:
        print(w)
    if png is not None:
        render_png(spec, png, teams, args.seed, args.scale)
        print(f"wrote {png}")
    return 0


def cmd_edit(args: argparse.Namespace) -> int:
    from alphatank.mapgen.editor import MapEditor
    from alphatank.ui.render import DisplayUnavailable

    path = Path(args.map)
    if path.exists():
        model = EditorModel.from_file(path)
    else:
        rows, cols = parse_size(args.size, 3)
        model = EditorModel.blank(rows, cols, name=path.stem)
    if os.environ.get("SDL_VIDEODRIVER") == "dummy":  # no window would ever show: it waited
        raise InputError("edit needs a display for its window (SDL_VIDEODRIVER=dummy is set); "
                         "run it on a desktop session, or generate maps with generate/batch")
    try:
        editor = MapEditor(model, path, args.cell_px)
    except DisplayUnavailable as exc:
        raise InputError(f"edit needs a display for its window ({exc})") from None
    editor.run()
    editor.close()
    if editor.message:
        print(editor.message)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="mapgen.py", description=__doc__,
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)

    p = sub.add_parser("generate", help="write one seeded map")
    _add_gen_options(p, lists=False)
    p.add_argument("-o", "--output", type=given, help="map file to write (default: print the map)")
    p.add_argument("--name", type=map_name,
                   help="map name (default: the output file's stem)")
    p.set_defaults(run=cmd_generate)

    p = sub.add_parser("batch", help="write COUNT maps with consecutive seeds")
    _add_gen_options(p, lists=True)
    p.add_argument("--count", type=int, required=True, help="number of maps")
    p.add_argument("--out", type=given, required=True, help="folder to write into")
    p.add_argument("--split", type=float,
                   help="train share, e.g. 0.8: writes OUT/train and OUT/test (every 5th map "
                        "held out)")
    p.set_defaults(run=cmd_batch)

    p = sub.add_parser("variants", help="write every map with its turned and flipped images "
                                        "(data augmentation for training maps)")
    p.add_argument("maps", nargs="+", metavar="MAP", help="map files, folders or shipped names")
    p.add_argument("--out", type=given, required=True, help="folder to write into")
    p.add_argument("--force", action="store_true", help="overwrite existing files")
    p.set_defaults(run=cmd_variants)

    p = sub.add_parser("validate", help="check maps with the game's loader, plus warnings")
    p.add_argument("maps", nargs="+", metavar="MAP", help="map files, folders or shipped names")
    p.add_argument("--strict", action="store_true", help="exit 1 on warnings too")
    p.add_argument("--teams", type=parse_teams,
                   help="team of each slot, e.g. AABB: line-of-fire warnings only between "
                        "enemies")
    p.set_defaults(run=cmd_validate)

    p = sub.add_parser("preview", help="print the map and draw it to a PNG")
    p.add_argument("map", help="map file or shipped name")
    p.add_argument("--png", type=given,
                   help="PNG to write (default: NAME.png in the current folder)")
    p.add_argument("--no-png", action="store_true", help="ASCII only")
    p.add_argument("--fire", action="store_true", help="mark lines of fire between spawns")
    p.add_argument("--teams", type=parse_teams,
                   help="team of each slot, e.g. AABB (default: halves A and B)")
    p.add_argument("--seed", type=seed_type, default=0,
                   help="match seed (random zones, headings)")
    p.add_argument("--scale", type=scale, default=1.0, help="PNG scale (default 1)")
    p.set_defaults(run=cmd_preview)

    p = sub.add_parser("edit", help="paint a map in a pygame window")
    p.add_argument("map", type=given, help="map file to edit (created on first save if missing)")
    p.add_argument("--size", default="11x11", help="ROWSxCOLS of a new map (default 11x11)")
    p.add_argument("--cell-px", type=int_in_range(8, 128),
                   help="pixels per cell on screen, 8 to 128 (default: fit the map to ~760 px)")
    p.set_defaults(run=cmd_edit)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.run(args))
    except BrokenPipeError:
        return broken_pipe_exit()
    except (InputError, OSError, argparse.ArgumentTypeError) as err:
        print(f"mapgen.py {args.command}: error: {one_line(err)}", file=sys.stderr)
        return 2



if __name__ == "__main__":
    sys.exit(main())
