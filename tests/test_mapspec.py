"""Map format: parsing, wall merging, validation errors with line and column."""

from pathlib import Path

import numpy as np
import pytest

from alphatank.cli import main
from alphatank.mapgen.generate import MAX_SIZE, generate
from alphatank.mapgen.model import EditorModel
from alphatank.sim.grid import reachable_from
from alphatank.sim.mapspec import (
    MAX_FLOOR,
    MapError,
    load_map,
    map_text,
    merge_walls,
    parse_map,
    shipped_maps,
)

GOOD = """\
; a comment line
name: tiny
cell: 50
description: test map

#####
#1.+#
#.#.#
#-.2#
#####
"""


def test_parse_header_grid_spawns_zones():
    spec = parse_map(GOOD, "tiny.txt")
    assert spec.name == "tiny" and spec.cell == 50.0 and spec.description == "test map"
    assert (spec.rows, spec.cols) == (5, 5)
    assert spec.spawns == {1: (1, 1), 2: (3, 3)}
    assert spec.buffs == ((1, 3),) and spec.debuffs == ((3, 1),)
    assert spec.walls[2, 2] and not spec.walls[1, 1]
    assert (spec.width, spec.height) == (250.0, 250.0)


def test_grid_without_header_and_name_from_file():
    spec = parse_map("###\n#1#\n#2#\n###\n", "maps/bare.txt")
    assert spec.name == "bare" and spec.cell == 70.0


def test_map_text_round_trips():
    spec = parse_map(GOOD, "tiny.txt")
    again = parse_map(map_text(spec), "again.txt")
    assert np.array_equal(again.walls, spec.walls)
    assert again.spawns == spec.spawns and again.buffs == spec.buffs
    assert again.debuffs == spec.debuffs and again.cell == spec.cell


def test_map_text_keeps_the_author():
    text = GOOD.replace("description: test map\n", "description: test map\nauthor: me; you\n")
    spec = parse_map(text, "tiny.txt")
    assert spec.author == "me; you"
    assert map_text(spec) == text.removeprefix("; a comment line\n")
    assert parse_map(map_text(spec), "again.txt").author == "me; you"


@pytest.mark.parametrize("seed", range(20))
def test_merged_rectangles_cover_walls_exactly(seed):
    walls = np.random.default_rng(seed).random((9, 13)) < 0.45
    cover = np.zeros(walls.shape, dtype=int)
    for r0, c0, r1, c1 in merge_walls(walls):
        cover[r0:r1, c0:c1] += 1
    assert np.array_equal(cover, walls.astype(int))  # every wall once, no floor


def test_merging_reduces_box_count():
    spec = load_map("open")
    assert len(spec.wall_rects) == 4  # the ring: two full rows, two columns


@pytest.mark.parametrize("name", ["open", "battlefield", "maze", "arena4", "arena8"])
def test_shipped_maps_load_by_name(name):
    spec = load_map(name)
    assert spec.name == name and spec.walls.any() and len(spec.spawns) >= 2


def test_shipped_team_arenas_have_4_and_8_slots():
    counts = {len(load_map(n).spawns) for n in shipped_maps()}
    assert {4, 8} <= counts


def test_load_by_path(tmp_path: Path):
    f = tmp_path / "mine.txt"
    f.write_text(GOOD)
    assert load_map(f).name == "tiny"


def test_unknown_map_name_lists_shipped():
    with pytest.raises(MapError, match="shipped maps: .*maze"):
        load_map("no_such_map")


BAD = [
    # (text, line, col, message fragment)
    ("#####\n#1.2#\n#..#\n#####\n", 3, 5, "ragged row"),
    ("#####\n#1x2#\n#####\n", 2, 3, "unknown character 'x'"),
    ("#####\n\t#1.2#\n#####\n", 2, 1, "unknown character '\\t'"),  # not a ragged row
    ("#####\n #1.2\n#####\n", 2, 1, "unknown character ' '"),
    ("#####\n#1.1#\n#####\n", 2, 4, "duplicate spawn 1"),
    ("#####\n#1#2#\n#####\n", 2, 4, "spawn 2 cannot be reached"),
    ("; only a comment\n\n", 2, 0, "empty map"),
    ("name: x\nsize: 9\n\n###\n#1#\n###\n", 2, 1, "unknown header key 'size'"),
    ("name: x\ncell: -3\n\n###\n#1#\n###\n", 2, 1, "'cell' must be a positive"),
    ("###\n#1#\n\n#2#\n###\n", 3, 1, "blank line inside the grid"),
    ("###\n###\n", 1, 1, "no floor cells"),
    ("name: x\nzones: sometimes\n\n###\n#.#\n###\n", 2, 1, "'zones' must be"),
    # lines break at \n, \r\n and \r only, as editors count them: a form feed or U+2028
    # is a character of its line, not a line break that moves the reported line and column
    ("#####\n#1\x0c2#\n#####\n", 2, 3, "unknown character '\\x0c'"),
    ("#####\n#1\x852#\n#####\n", 2, 3, "unknown character '\\x85'"),
    ("name: x\ndescription: a\u2028b\n\n###\n#1#\n#?#\n###\n", 6, 2, "unknown character '?'"),
    ("#####\r#1.2#\r#..#\r#####\r", 3, 5, "ragged row"),
]


@pytest.mark.parametrize(("text", "line", "col", "fragment"), BAD)
def test_malformed_maps_name_file_line_column(text, line, col, fragment):
    with pytest.raises(MapError) as info:
        parse_map(text, "bad.txt")
    err = info.value
    assert (err.source, err.line, err.col) == ("bad.txt", line, col)
    assert fragment in err.message
    assert str(err).startswith(f"bad.txt:{line}")


def _room(rows: int, cols: int, header: str = "") -> str:
    """A walled room with ``rows`` x ``cols`` floor cells."""
    wall, floor = "#" * (cols + 2), "#" + "." * cols + "#"
    return header + "\n".join([wall, *[floor] * rows, wall]) + "\n"


def test_floor_and_world_size_limits_name_the_limit():
    assert (~parse_map(_room(64, 64), "big.txt").walls).sum() == MAX_FLOOR == 4096
    with pytest.raises(MapError) as info:
        parse_map(_room(64, 65), "big.txt")
    assert str(info.value) == "big.txt:1:1: 4160 floor cells (anything but '#'); at most 4096"
    assert parse_map(_room(5, 20, "cell: 400\n\n"), "wide.txt").width == 8800
    with pytest.raises(MapError) as info:
        parse_map(_room(5, 21, "name: w\ncell: 400\n\n"), "wide.txt")
    assert str(info.value) == ("wide.txt:2:1: world of 9200 x 2800 px (7 x 23 cells of 400 px);"
                               " at most 8960 px each way")
    with pytest.raises(MapError) as info:
        parse_map(_room(1, 127), "big.txt")
    assert str(info.value) == "big.txt:1:129: row of 129 cells; a grid has at most 128 each way"
    with pytest.raises(MapError) as info:  # named at the first row too many
        parse_map(_room(127, 1) + "###\n" * 10, "big.txt")
    assert str(info.value) == "big.txt:129:1: grid of over 128 rows; at most 128 each way"


def test_a_huge_map_file_is_refused_by_its_size_unread(tmp_path):
    path = tmp_path / "huge.txt"
    path.write_text(_room(5, 5) + "; padding\n" * 200_000)  # about 2 MB of comment lines
    for load in (load_map, EditorModel.from_file):
        with pytest.raises(MapError) as info:
            load(path)
        assert str(info.value) == f"{path}: over 1,048,576 bytes, too large for a map file"
    # the map generator's largest size, with no interior walls, loads
    spec = generate(MAX_SIZE, MAX_SIZE, "open", density=0.0)
    assert parse_map(map_text(spec)).rows == MAX_SIZE


def test_trailing_comments_on_cell_and_zones_lines_only():
    readme = (Path(__file__).parents[1] / "README.md").read_text(encoding="utf-8")
    zones = next(ln for ln in readme.splitlines() if ln.startswith("zones: random "))
    assert ";" in zones  # the README's example line, as written there
    spec = parse_map(f"name: a;b\ndescription: walls; spawns\ncell: 50 ; px\n{zones}\n\n"
                     "####\n#12#\n####\n", "c.txt")
    assert (spec.name, spec.description, spec.cell, spec.random_zones) == (
        "a;b", "walls; spawns", 50.0, True)
    with pytest.raises(MapError, match=r"c.txt:1:1: header 'zones' must be .* got 'often'"):
        parse_map("zones: often ; random\n\n###\n#1#\n###\n", "c.txt")


def test_a_shipped_map_name_is_not_hidden_by_a_file_or_folder_of_that_name(tmp_path,
                                                                           monkeypatch):
    """A folder 'maze' in the working folder made load_map('maze') 'is a folder, not a map
    file' (bench, maps, the README's Match example); a file 'open' was read as the map."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "maze").mkdir()
    (tmp_path / "open").write_text("not a map\n")
    (tmp_path / "train").mkdir()
    (tmp_path / "train" / "maze_0000").mkdir()
    for name in ("maze", "open", "train/maze_0000"):
        assert load_map(name).source == f"maps/{name}.txt"
    with pytest.raises(MapError, match="is a folder, not a map file"):  # named as a path
        load_map(Path("maze"))
    with pytest.raises(MapError, match=r"^open:1:1: unknown character"):  # the file here
        load_map("./open")


def test_an_empty_map_path_is_refused_not_the_current_folder(tmp_path, monkeypatch, capsys):
    (tmp_path / "a.txt").write_text("#####\n#1.2#\n#####\n")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(MapError, match=r"^'': empty map name or path; give a shipped map's"):
        load_map("")
    assert main(["maps", ""]) == 2
    assert capsys.readouterr().err == ("alphatank maps: error: '': empty map name or path; give "
                                       "a shipped map's name (e.g. 'maze') or a .txt file\n")
    assert main(["maps", "."]) == 0 and "a.txt: ok" in capsys.readouterr().out


def test_comment_lines_keep_original_line_numbers():
    with pytest.raises(MapError) as info:
        parse_map("; c1\n; c2\n###\n#?#\n###\n", "c.txt")
    assert (info.value.line, info.value.col) == (4, 2)


def test_floor_cells_and_reachable_areas_match_a_search_of_the_grid():
    """The per-map floor list and area labels give what a fresh grid search gives, for
    every floor cell of a map with walled-off pockets."""
    spec = parse_map("#######\n#12#..#\n#..#..#\n#######\n#.#...#\n#######")
    assert spec.floor_cells() == tuple(
        (int(r), int(c)) for r, c in zip(*np.nonzero(~spec.walls), strict=True))
    for cell in spec.floor_cells():
        np.testing.assert_array_equal(spec.reachable(cell), reachable_from(spec.walls, cell))
    assert spec.reachable((1, 1)).sum() == 4 and not spec.reachable((1, 1))[1, 4]
