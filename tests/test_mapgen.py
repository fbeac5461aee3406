"""Map generator, warnings, the tools/mapgen.py CLI and the shipped train/test map folders."""

import importlib.util
import os
import re
from pathlib import Path

import numpy as np
import pytest

from alphatank.mapgen import (
    ALGORITHMS,
    SYMMETRIES,
    EditorModel,
    GenOptions,
    MapGenError,
    ascii_art,
    check_map,
    generate,
    generate_from,
    map_variants,
    map_warnings,
)
from alphatank.mapgen.generate import image, lines_clear, transform
from alphatank.sim.grid import components, open_sides
from alphatank.sim.mapspec import MapError, load_map, map_text, parse_map

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("mapgen_cli", ROOT / "tools" / "mapgen.py")
cli = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(cli)


def is_symmetric(spec, symmetry: str) -> bool:
    """Whether walls, zones and spawn slots (slot i <-> i + n//2, an odd last slot on the
    axis) are symmetric."""
    shape = spec.walls.shape
    if not np.array_equal(spec.walls, transform(spec.walls, symmetry)):
        return False
    for cells in (spec.buffs, spec.debuffs):
        if {image(c, shape, symmetry) for c in cells} != set(cells):
            return False
    n = len(spec.spawns)
    if sorted(spec.spawns) != list(range(1, n + 1)):
        return False
    for slot, cell in spec.spawns.items():
        mate = slot + n // 2 if slot <= n // 2 else slot - n // 2 if slot <= 2 * (n // 2) else slot
        if spec.spawns[mate] != image(cell, shape, symmetry):
            return False
    return True


# (rows, cols), spawns, zones: sizes odd and even, square and not; an odd spawn count sits
# on the axis (mirror needs odd cols, rotation odd rows and cols).
CONFIGS = [((7, 7), 2, (2, 2)), ((11, 11), 4, (2, 2)), ((12, 15), 2, (0, 2)),
           ((16, 10), 8, (2, 2)), ((11, 11), 3, (2, 2)), ((9, 13), 2, None)]


def _floor_edges(walls: np.ndarray) -> int:
    f = ~walls
    return int((f[1:, :] & f[:-1, :]).sum() + (f[:, 1:] & f[:, :-1]).sum())


@pytest.mark.parametrize("symmetry", SYMMETRIES)
@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_every_generator_makes_valid_connected_maps_for_200_seeds(algorithm, symmetry):
    for seed in range(200):
        (rows, cols), spawns, zones = CONFIGS[seed % len(CONFIGS)]
        density = (0.1, 0.25, 0.4, 0.6)[seed % 4]
        spec = generate(rows, cols, algorithm, density, symmetry, spawns, zones,
                        loops=0.15, seed=seed)
        again = parse_map(map_text(spec), "gen.txt")  # the game's own validation
        assert np.array_equal(again.walls, spec.walls)
        w = spec.walls
        assert w.shape == (rows, cols)
        assert w[0].all() and w[-1].all() and w[:, 0].all() and w[:, -1].all()
        assert components(w)[1] == 1, (algorithm, symmetry, seed)  # all floor connected
        assert sorted(spec.spawns) == list(range(1, spawns + 1))
        if zones is None:
            assert spec.random_zones and not spec.buffs and not spec.debuffs
        else:
            assert (len(spec.buffs), len(spec.debuffs)) == zones
        if symmetry != "none":
            assert is_symmetric(spec, symmetry), (algorithm, symmetry, seed)
        codes = {x.code for x in map_warnings(spec)}
        assert not codes & {"unreachable-zone", "isolated-floor", "spawn-slots"}


@pytest.mark.parametrize("symmetry", ["mirror", "rotational"])
def test_symmetric_maps_are_exactly_symmetric(symmetry):
    spec = generate(11, 11, "scatter", 0.35, symmetry, spawns=4, zones=(2, 2), seed=5)
    flip = spec.walls[:, ::-1] if symmetry == "mirror" else spec.walls[::-1, ::-1]
    assert np.array_equal(spec.walls, flip)
    for slot in (1, 2):  # slot i faces slot i + n/2
        assert spec.spawns[slot + 2] == image(spec.spawns[slot], (11, 11), symmetry)
    for cells in (spec.buffs, spec.debuffs):
        assert {image(c, (11, 11), symmetry) for c in cells} == set(cells)
    assert not is_symmetric(generate(11, 11, "scatter", 0.35, "none", seed=5), symmetry)


def test_same_seed_same_file_and_other_seeds_differ():
    a = map_text(generate(13, 13, "rooms", 0.3, "mirror", seed=42))
    b = map_text(generate(13, 13, "rooms", 0.3, "mirror", seed=42))
    assert a == b
    texts = {map_text(generate(13, 13, "rooms", 0.3, "mirror", seed=s, name="x"))
             for s in range(10)}
    assert len(texts) >= 9


def test_cli_generate_same_seed_same_bytes(tmp_path, capsys):
    args = ["generate", "--size", "11x13", "--algorithm", "maze", "--symmetry", "mirror",
            "--spawns", "2", "--zones", "2,2", "--seed", "7"]
    assert cli.main([*args, "-o", str(tmp_path / "a.txt")]) == 0
    assert cli.main([*args, "-o", str(tmp_path / "b.txt"), "--name", "a"]) == 0
    assert (tmp_path / "a.txt").read_bytes() == (tmp_path / "b.txt").read_bytes()
    assert "wrote" in capsys.readouterr().out
    spec = load_map(tmp_path / "a.txt")
    assert spec.name == "a" and is_symmetric(spec, "mirror")
    # The description records the options, so the file can be rebuilt from it.
    assert "--algorithm maze --density 0.25 --symmetry mirror" in spec.description
    assert cli.main([*args, "-o", str(tmp_path / "a.txt")]) == 2  # no silent overwrite
    assert "--force" in capsys.readouterr().err


def test_a_generated_map_rebuilds_from_its_description_at_any_density(tmp_path, capsys):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    for seed in ("1", "4", "6"):  # 'density 0.236686' (six digits) drew other rooms for 4, 6
        assert cli.main(["generate", "--size", "15x15", "--algorithm", "rooms", "--density",
                         "0.2366864", "--loops", "0", "--seed", seed, "-o", str(a),
                         "--force"]) == 0
        args = load_map(a).description.split("tools/mapgen.py ")[1].split()
        assert "0.2366864" in args
        assert cli.main(["generate", *args, "-o", str(b), "--name", "a", "--force"]) == 0
        assert a.read_text() == b.read_text()


def test_cli_generate_writes_into_a_device_and_warns_with_the_file_name(tmp_path, capsys):
    # /dev/null needed --force ("exists"), then the map written into it failed the
    # reload check ("not a file (a device or pipe)"), exit 2
    assert cli.main(["generate", "-o", os.devnull]) == 0
    assert capsys.readouterr().out.startswith(f"wrote {os.devnull}: ")
    out = tmp_path / "open.txt"
    assert cli.main(["generate", "--algorithm", "open", "--density", "0", "-o", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1:] and all(ln.startswith(f"{out}:") for ln in lines[1:])  # lines of fire
    assert [str(w) for w in check_map(out)[1]] == lines[1:]


def test_cli_generate_refuses_lists_and_names_that_are_not_one_line(tmp_path, capsys):
    out = tmp_path / "a.txt"
    for flag, value in (("--size", "11x11,9x9"), ("--algorithm", "maze,rooms"),
                        ("--symmetry", "mirror,none")):  # batch's lists: generate took the 1st
        with pytest.raises(SystemExit) as exc:
            cli.main(["generate", flag, value, "-o", str(out)])
        assert exc.value.code == 2
        assert (f"argument {flag}: takes one value in generate (comma-separated lists are for "
                f"batch), got {value!r}") in capsys.readouterr().err
    for name in ("x\ncell: 50", " ", "a\tb"):  # a line break wrote a header line of its own
        with pytest.raises(SystemExit):
            cli.main(["generate", "--name", name, "-o", str(out)])
        assert (f"argument --name: name must be one line of printable text, got {name!r}"
                in capsys.readouterr().err)
        with pytest.raises(MapGenError, match="one line of printable text"):
            generate(name=name)
    assert not out.exists()
    assert cli.main(["generate", "--name", "My map; v2", "-o", str(out)]) == 0
    assert load_map(out).name == "My map; v2" and load_map(out).cell == 70


def test_cli_out_of_range_options_name_their_flag(tmp_path, capsys):
    for command, flag, value, allowed in (
            ("generate", "--spawns", "9", "an integer in [0, 8]"),
            ("batch", "--spawns", "-1", "an integer in [0, 8]"),
            ("generate", "--density", "1", "a number in [0, 1)"),
            ("generate", "--density", "nan", "a number in [0, 1)"),
            ("generate", "--loops", "2", "a number in [0, 1]"),
            ("generate", "--seed", "-1", "an integer in [0, 2^63)"),
            ("preview", "--seed", "-1", "an integer in [0, 2^63)")):  # was a traceback
        args = ["maze", "--no-png"] if command == "preview" else ["--count", "1", "--out",
                                                                   str(tmp_path)]
        with pytest.raises(SystemExit) as exc:
            cli.main([command, *(args if command != "generate" else []), flag, value])
        assert exc.value.code == 2
        assert (f"argument {flag}: must be {allowed}, got {value!r}"
                in capsys.readouterr().err)
    assert list(tmp_path.iterdir()) == []


def test_loops_turn_a_perfect_maze_into_a_graph_with_cycles():
    for seed in range(5):
        tree = generate(11, 15, "maze", symmetry="none", loops=0.0, seed=seed).walls
        assert _floor_edges(tree) == int((~tree).sum()) - 1  # a spanning tree
        loopy = generate(11, 15, "maze", symmetry="none", loops=0.3, seed=seed).walls
        assert _floor_edges(loopy) > int((~loopy).sum()) - 1


@pytest.mark.parametrize("algorithm", ["rooms", "open", "scatter"])
def test_density_sets_the_wall_share(algorithm):
    def share(d: float) -> float:
        return float(np.mean([generate(15, 15, algorithm, d, loops=0.0, seed=s)
                              .walls[1:-1, 1:-1].mean() for s in range(8)]))
    low, high = share(0.05), share(0.3)
    assert low < 0.12 and high > low + 0.1
    assert share(0.0) == 0.0


def test_generator_options_are_checked_with_allowed_values():
    for bad, why in (({"density": "0.3"}, "density must be a number, got '0.3'"),
                     ({"rows": 11.5}, "rows must be an integer, got 11.5"),
                     ({"seed": 1.5}, "seed must be an integer, got 1.5"),
                     ({"zones": (1, 2, 3)}, r"zones must be two counts .* got \(1, 2, 3\)")):
        with pytest.raises(MapGenError, match=why):  # not a TypeError deep inside
            GenOptions(**bad)
    with pytest.raises(MapGenError, match=r"algorithm must be one of \['maze'"):
        generate(algorithm="caves")
    with pytest.raises(MapGenError, match="symmetry must be one of"):
        GenOptions(symmetry="diagonal")
    with pytest.raises(MapGenError, match="rows must be in"):
        generate(rows=4)
    with pytest.raises(MapGenError, match="centre column"):
        generate(10, 10, symmetry="mirror", spawns=3)
    with pytest.raises(MapGenError, match="do not fit"):
        generate(5, 5, spawns=8, zones=(2, 2))
    with pytest.raises(MapGenError, match="density"):
        generate(density=1.0)


def test_spawns_are_spread_out():
    for seed in range(20):
        spec = generate(11, 11, "open", 0.0, "mirror", spawns=2, zones=(0, 0), seed=seed)
        assert abs(spec.spawns[1][1] - spec.spawns[2][1]) >= 6


# ---- warnings -------------------------------------------------------------------------


def test_lines_clear_is_exact_on_the_grid():
    walls = np.zeros((5, 5), dtype=bool)
    a, b = np.array([[1, 1]]), np.array([[3, 3]])
    assert lines_clear(walls, a, b)[0]
    walls[1, 2] = True  # the diagonal passes through this cell's corner: grazing blocks
    assert not lines_clear(walls, a, b)[0]
    walls[:] = False
    walls[1, 3] = True  # off the line
    assert lines_clear(walls, a, b)[0]
    walls[2, 2] = True
    assert not lines_clear(walls, np.array([[2, 0]]), np.array([[2, 4]]))[0]
    assert lines_clear(walls, np.array([[3, 0]]), np.array([[3, 4]]))[0]


def test_line_of_fire_warning_names_both_spawns_and_positions():
    spec = load_map("open")  # spawns (2, 2) and (8, 8) on an empty floor
    ws = map_warnings(spec, (ROOT / "maps" / "open.txt").read_text())
    assert [w.code for w in ws] == ["line-of-fire"]
    assert (ws[0].line, ws[0].col) == (7, 3)
    assert str(ws[0]).startswith("maps/open.txt:7:3: warning: spawn 1 has a direct line of "
                                 "fire to spawn 2 (line 13, column 9)")
    blocked = parse_map("#######\n#1....#\n#..#..#\n#....2#\n#######\n")
    assert map_warnings(blocked) == []
    # teams: only enemies count
    arena = load_map("arena4")
    all_pairs = [w for w in map_warnings(arena) if w.code == "line-of-fire"]
    enemies = [w for w in map_warnings(arena, teams="AABB") if w.code == "line-of-fire"]
    assert len(all_pairs) == 4 and len(enemies) == 2


def test_dead_end_unreachable_zone_isolated_floor_and_skipped_slot_warnings():
    text = "name: bad\n\n#########\n#1#...#.#\n#.#.3.#+#\n#.....###\n#########\n"
    spec = parse_map(text, "bad.txt")
    ws = {w.code: w for w in map_warnings(spec, text)}
    assert set(ws) == {"dead-end-spawn", "unreachable-zone", "isolated-floor", "spawn-slots"}
    assert (ws["dead-end-spawn"].line, ws["dead-end-spawn"].col) == (4, 2)
    assert (ws["unreachable-zone"].line, ws["unreachable-zone"].col) == (5, 8)
    assert "buff zone cannot be reached from spawn 1" in ws["unreachable-zone"].message
    assert "2 floor cell(s)" in ws["isolated-floor"].message
    assert "skip [2]" in ws["spawn-slots"].message and ws["spawn-slots"].line == 5
    walled_in = parse_map("#####\n#1#.#\n#####\n")
    assert "walled in" in map_warnings(walled_in)[0].message


def test_zone_cells_that_zones_random_ignores_are_a_warning():
    from alphatank.sim.config import game_config
    from alphatank.sim.match import Match

    text = "zones: random\n\n#######\n#1..-2#\n#..+..#\n#######\n"
    spec = parse_map(text, "both.txt")
    match = Match(game_config(), spec, ["A", "B"], seed=0)
    assert (match.buffs, match.debuffs) != (list(spec.buffs), list(spec.debuffs))
    (w,) = [w for w in map_warnings(spec, text) if w.code == "ignored-zones"]
    assert (w.line, w.col) == (4, 5)  # the first of the cells, row by row
    assert w.message.startswith("2 '+'/'-' zone cell(s), the first here, are ignored: "
                                "'zones: random' draws each match's zones")
    fixed = text.replace("zones: random", "zones: fixed")
    assert "ignored-zones" not in {w.code for w in map_warnings(parse_map(fixed), fixed)}


def test_warning_lines_follow_comments_and_header():
    text = "; top\nname: c\n\n; between\n#####\n; inside\n#1.2#\n#...#\n#####\n"
    ws = map_warnings(parse_map(text), text)
    assert [(w.line, w.col) for w in ws] == [(7, 2)]
    text = "name: c\ndescription: one\u2028two\x0cthree\n\n#####\n#1.2#\n#...#\n#####\n"
    spec = parse_map(text)  # neither U+2028 nor a form feed breaks a line in an editor
    assert spec.description == "one\u2028two\x0cthree"
    assert [(w.line, w.col) for w in map_warnings(spec, text)] == [(5, 2)]
    assert EditorModel.from_text(text).text() == text


def test_shipped_maps_have_no_errors_and_expected_warnings():
    for name in ("open", "battlefield", "maze", "arena4", "arena8"):
        codes = {w.code for w in map_warnings(load_map(name))}
        assert codes <= {"line-of-fire"}


# ---- CLI: validate, preview, batch ------------------------------------------------------

MALFORMED = {
    "header_no_colon": "name: x\nnot a header\n\n###\n#1#\n###\n",
    "unknown_key": "name: x\ncolour: red\n\n###\n#1#\n###\n",
    "duplicate_key": "name: x\nname: y\n\n###\n#.#\n###\n",
    "empty": "name: x\n\n",
    "blank_in_grid": "###\n#.#\n\n#.#\n###\n",
    "ragged": "####\n#.#\n####\n",
    "bad_cell": "cell: -3\n\n###\n#.#\n###\n",
    "bad_zones": "zones: some\n\n###\n#.#\n###\n",
    "unknown_char": "#####\n#1x2#\n#####\n",
    "duplicate_spawn": "#####\n#1.1#\n#####\n",
    "no_floor": "###\n###\n",
    "unreachable": "#####\n#1#2#\n#####\n",
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_validate_prints_exactly_the_loaders_message(case, tmp_path, capsys):
    path = tmp_path / f"{case}.txt"
    path.write_text(MALFORMED[case])
    with pytest.raises(MapError) as err:
        load_map(path)
    assert cli.main(["validate", str(path)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out == [str(err.value)]
    assert re.match(rf"{re.escape(str(path))}:\d+", out[0])


def test_validate_missing_files_and_folders_like_the_loader(tmp_path, capsys):
    missing = tmp_path / "none.txt"
    with pytest.raises(MapError) as err:
        load_map(missing)
    assert cli.main(["validate", str(missing), "no_such_map"]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0] == str(err.value) and out[1].startswith("no_such_map: unknown map")


def test_validate_ok_warnings_strict_and_folders(tmp_path, capsys):
    assert cli.main(["validate", "maze", "open"]) == 0
    out = capsys.readouterr().out
    assert "maps/maze.txt: ok" in out and "[line-of-fire]" in out
    assert cli.main(["validate", "--strict", "open"]) == 1
    capsys.readouterr()
    (tmp_path / "a.txt").write_text("#####\n#1.2#\n#####\n")
    (tmp_path / "b.txt").write_text("#####\n#1#2#\n#####\n")
    assert cli.main(["validate", str(tmp_path)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith(f"{tmp_path / 'a.txt'}: ok")
    assert any(line.startswith(f"{tmp_path / 'b.txt'}:2:4: spawn 2 cannot") for line in out)


def test_validate_and_variants_take_shipped_folder_names_like_alphatank_maps(tmp_path, capsys,
                                                                           monkeypatch):
    monkeypatch.chdir(tmp_path)  # no local folder of that name
    assert cli.main(["validate", "test"]) == 0
    assert capsys.readouterr().out.count(": ok (") == 4
    assert cli.main(["variants", "test/", "--out", str(tmp_path / "v")]) == 0
    assert len(list((tmp_path / "v").glob("*_rot90.txt"))) == 4


def test_preview_prints_ascii_and_draws_png_with_the_game_renderer(tmp_path, capsys):
    import pygame

    from alphatank.ui.render import FLOOR, WALL

    png = tmp_path / "arena4.png"
    assert cli.main(["preview", "arena4", "--png", str(png), "--fire"]) == 0
    out = capsys.readouterr().out
    art = ascii_art(load_map("arena4"), show_fire=True)
    assert art in out and "* " in art and f"wrote {png}" in out
    assert art.splitlines()[1].startswith("##1 * *")
    img = pygame.image.load(str(png))
    assert img.get_size() == (13 * 70, 10 * 70)
    assert tuple(img.get_at((35, 35)))[:3] == WALL  # border cell centre
    assert tuple(img.get_at((5 * 70 + 10, 3 * 70 + 10)))[:3] != WALL  # floor
    assert tuple(img.get_at((3 * 70 + 35, 3 * 70 + 5)))[:3] in (FLOOR, tuple(FLOOR))


def test_preview_refuses_teams_and_maps_a_match_cannot_hold_in_one_line(tmp_path, capsys,
                                                                       monkeypatch):
    monkeypatch.chdir(tmp_path)  # where the default PNG would go
    for teams in ("A", "AA", "A,B"):  # one tank, one team, a comma as a team: no match
        for command in ("preview", "validate"):
            with pytest.raises(SystemExit) as exc:
                cli.main([command, "maze", "--teams", teams])
            assert exc.value.code == 2
            err = capsys.readouterr().err
            assert "argument --teams: must be the team of each slot" in err
            assert f"got {teams!r}" in err and "Traceback" not in err
    tiny = tmp_path / "tiny.txt"
    tiny.write_text("1\n")  # room for one tank: the PNG's two cannot be placed
    assert cli.main(["preview", str(tiny)]) == 2
    assert capsys.readouterr().err.strip() == (
        f"mapgen.py preview: error: {tiny}: room for 1 tank(s) (free floor reachable from the "
        "spawns), the PNG draws 2 on their spawns; give --no-png for the text preview")
    assert cli.main(["preview", str(tiny), "--no-png"]) == 0
    assert list(tmp_path.glob("*.png")) == []


def test_preview_png_must_be_a_png_file_and_never_overwrites_the_map(tmp_path, capsys):
    src = tmp_path / "mine.txt"
    src.write_text("#####\n#1.2#\n#####\n")
    for png in (str(src), str(tmp_path / "out"), str(tmp_path / "out.jpg")):
        # pygame wrote TGA or JPEG bytes, over the map too
        assert cli.main(["preview", str(src), "--png", png]) == 2
        assert capsys.readouterr().err == (f"mapgen.py preview: error: --png: {png}: must name "
                                           "a .png file (another name got TGA, JPEG or BMP "
                                           "bytes)\n")
    assert src.read_text() == "#####\n#1.2#\n#####\n"
    assert cli.main(["preview", str(src), "--png", str(tmp_path / "Mine.PNG")]) == 0
    assert (tmp_path / "Mine.PNG").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Mine.PNG", "mine.txt"]


def test_map_names_that_are_not_file_names_write_nothing_outside_the_folder(tmp_path,
                                                                           capsys,
                                                                           monkeypatch):
    inner = tmp_path / "inner"
    inner.mkdir()
    monkeypatch.chdir(inner)
    for name in ("../escape", "sub/dir", ".."):
        src = tmp_path / "src.txt"
        src.write_text(f"name: {name}\n\n#####\n#1.2#\n#####\n")
        assert cli.main(["variants", str(src), "--out", str(inner / "v")]) == 2
        assert capsys.readouterr().err.strip() == (
            f"mapgen.py variants: error: {src}: map name {name!r} cannot name the variants' "
            "files in --out; give the map a name: header without '/' or '\\' (and not '.' "
            "or '..')")
        assert cli.main(["preview", str(src)]) == 2
        assert f"map name {name!r} cannot name the default PNG (or give --png)" in \
            capsys.readouterr().err
        assert sorted(p.name for p in tmp_path.rglob("*")) == ["inner", "src.txt"]
    assert cli.main(["preview", str(src), "--png", "ok.png"]) == 0
    assert (inner / "ok.png").is_file()


def test_edit_cell_px_is_checked_before_a_window_opens(tmp_path, capsys):
    for px in ("-5", "0", "100000"):  # a pygame traceback, the default, an out-of-memory one
        with pytest.raises(SystemExit) as exc:
            cli.main(["edit", str(tmp_path / "new.txt"), "--cell-px", px])
        assert exc.value.code == 2
        assert (f"argument --cell-px: must be an integer in [8, 128], got {px!r}"
                in capsys.readouterr().err)
    assert not (tmp_path / "new.txt").exists()


def test_batch_writes_consecutive_seeds_and_a_held_out_split(tmp_path, capsys):
    args = ["batch", "--count", "10", "--seed", "100", "--out", str(tmp_path), "--split",
            "0.8", "--algorithm", "maze,rooms", "--symmetry", "mirror,rotational"]
    assert cli.main(args) == 0
    train = sorted(p.name for p in (tmp_path / "train").glob("*.txt"))
    test = sorted(p.name for p in (tmp_path / "test").glob("*.txt"))
    assert len(train) == 8 and len(test) == 2
    seeds = sorted(int(n[-8:-4]) for n in train + test)
    assert seeds == list(range(100, 110))
    assert test == ["maze_0104.txt", "maze_0109.txt"]  # every 5th map is held out
    for p in sorted(tmp_path.rglob("*.txt")):
        spec = load_map(p)
        sym = re.search(r"--symmetry (\w+)", spec.description).group(1)
        assert is_symmetric(spec, sym)
    first = (tmp_path / "train" / "maze_0100.txt").read_text()
    assert cli.main(args) == 2  # refuses to overwrite
    assert cli.main([*args, "--force"]) == 0
    assert (tmp_path / "train" / "maze_0100.txt").read_text() == first
    assert cli.main(["batch", "--count", "3", "--out", str(tmp_path / "flat")]) == 0
    assert len(list((tmp_path / "flat").glob("*.txt"))) == 3
    (tmp_path / "train" / "maze_0100.txt").unlink()  # one missing, the others there:
    capsys.readouterr()
    assert cli.main(args) == 2  # refused before writing any, not after the first
    assert not (tmp_path / "train" / "maze_0100.txt").exists()
    assert "9 of the batch's files" in capsys.readouterr().err


# ---- shipped folders ----------------------------------------------------------------------


def test_batch_split_refuses_a_file_in_place_of_a_folder_before_writing(tmp_path, capsys):
    (tmp_path / "test").write_text("not a folder\n")
    args = ["batch", "--count", "4", "--out", str(tmp_path), "--split", "0.5"]
    assert cli.main(args) == 2  # map 0 went to train/ before map 1 failed on test/
    assert capsys.readouterr().err.strip() == (
        f"mapgen.py batch: error: --out: {tmp_path / 'test'}: is a file, not a folder")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["test"]


@pytest.mark.parametrize("folder,count", [("train", 16), ("test", 4)])
def test_shipped_train_and_test_maps_are_valid_and_rebuildable(folder, count):
    paths = sorted((ROOT / "maps" / folder).glob("*.txt"))
    assert len(paths) == count
    for p in paths:
        spec = load_map(p)
        assert spec.name == p.stem
        args = re.search(r"generated by tools/mapgen.py (.*)$", spec.description).group(1)
        parsed = cli.build_parser().parse_args(["generate", *args.split()])
        rebuilt = generate_from(cli.options_from_args(parsed), name=spec.name)
        assert map_text(rebuilt) == p.read_text()
        assert not {w.code for w in map_warnings(spec)} - {"line-of-fire"}
        assert open_sides(spec.walls)[spec.spawns[1]] >= 2
    train = {p.stem for p in (ROOT / "maps" / "train").glob("*.txt")}
    test = {p.stem for p in (ROOT / "maps" / "test").glob("*.txt")}
    assert not train & test


def test_variants_turn_and_flip_walls_spawns_and_zones_together(tmp_path, capsys):
    spec = load_map(ROOT / "maps" / "train" / "rooms_0002.txt")
    variants = map_variants(spec)
    assert map_text(variants[0]) == map_text(spec)  # the original first, under its name
    assert [v.name for v in variants[1:4]] == [f"rooms_0002_{t}"
                                                for t in ("flipv", "fliph", "rot180")]
    rot90 = next(v for v in variants if v.name.endswith("_rot90"))
    np.testing.assert_array_equal(rot90.walls, np.rot90(spec.walls))
    n = spec.rows - 1
    for slot, (r, c) in spec.spawns.items():  # numpy's rot90: (r, c) -> (n - c, r)
        assert rot90.spawns[slot] == (n - c, r)
    assert sorted(rot90.buffs) == sorted((n - c, r) for r, c in spec.buffs)
    assert sorted(rot90.debuffs) == sorted((n - c, r) for r, c in spec.debuffs)
    texts = [map_text(v).partition("\n\n")[2] for v in variants]
    assert len(set(texts)) == len(texts) <= 8  # an image equal to an earlier one is left out
    # a map that is its own mirror image (spawn digits aside) keeps what differs
    plain = load_map(ROOT / "maps" / "open.txt")
    assert 1 <= len(map_variants(plain)) <= 8
    authored = parse_map(map_text(spec).replace("\n\n", "\nauthor: me\n\n", 1), "a.txt")
    assert all("\nauthor: me\n\n" in map_text(v) for v in map_variants(authored))
    assert cli.main(["variants", str(ROOT / "maps" / "train" / "rooms_0002.txt"), "--out",
                     str(tmp_path)]) == 0
    assert sorted(p.stem for p in tmp_path.glob("*.txt")) == sorted(v.name for v in variants)
    assert cli.main(["variants", "rooms_0002.txt", "--out", str(tmp_path)]) == 1  # no such map
    # two maps of one name would write the same files: refused before any is written
    twin = tmp_path / "twin"
    twin.mkdir()
    (twin / "other.txt").write_text((ROOT / "maps" / "train" / "rooms_0002.txt").read_text())
    capsys.readouterr()
    assert cli.main(["variants", str(ROOT / "maps" / "train" / "rooms_0002.txt"),
                     str(twin / "other.txt"), "--out", str(tmp_path / "v"), "--force"]) == 2
    assert "share the name 'rooms_0002'" in capsys.readouterr().err
    assert not (tmp_path / "v").exists()
    assert cli.main(["variants", str(ROOT / "maps" / "train" / "rooms_0002.txt"), "--out",
                     str(tmp_path)]) == 2
    assert f"exists ({len(variants)} of the variants' files do" in capsys.readouterr().err


def test_shipped_train_d8_is_the_variants_of_train():
    made = {v.name: map_text(v) for p in sorted((ROOT / "maps" / "train").glob("*.txt"))
            for v in map_variants(load_map(p))}
    shipped = {p.stem: p.read_text() for p in (ROOT / "maps" / "train_d8").glob("*.txt")}
    assert shipped == made and len(shipped) == 128
    test = {p.stem for p in (ROOT / "maps" / "test").glob("*.txt")}
    assert not {n.split("_")[0] + "_" + n.split("_")[1] for n in shipped} & test


def test_env_reset_samples_maps_from_a_folder_by_seed_and_names_them(tmp_path, capsys):
    from alphatank.envs import TankBattleEnv
    from alphatank.game.scenarios import parse_scenario

    seats = [{"team": "A", "controller": "learner"},
             {"team": "B", "controller": "bot", "bot": "random"}]
    env = TankBattleEnv(parse_scenario({"name": "folder", "map": "train", "seats": seats}))
    names = [env.reset(seed=s)[1]["map"] for s in range(16)]
    train = {p.stem for p in (ROOT / "maps" / "train").glob("*.txt")}
    assert set(names) <= train and len(set(names)) >= 5  # many maps, all from train/
    assert names == [env.reset(seed=s)[1]["map"] for s in range(16)]  # the seed picks the map
    env.reset(seed=3)
    assert env.match.spec.name == names[3]
    assert env.step(env.action_space.sample())[4]["map"] == names[3]
    # A folder written by the batch mode works the same way (the held-out convention).
    assert cli.main(["batch", "--count", "5", "--seed", "0", "--out", str(tmp_path),
                     "--split", "0.6", "--algorithm", "open,scatter"]) == 0
    held_out = parse_scenario({"name": "held_out", "map": str(tmp_path / "test"),
                               "seats": seats})
    env = TankBattleEnv(held_out)
    seen = {env.reset(seed=s)[1]["map"] for s in range(12)}
    assert seen == {p.stem for p in (tmp_path / "test").glob("*.txt")} and len(seen) == 2
