"""The map editor: the model (paint, strokes, undo/redo, save refusal) and the pygame
window driven by posted mouse and key events under SDL's dummy video driver."""



import numpy as np
import pygame
import pytest

from alphatank.mapgen import EditorModel, MapGenError
from alphatank.mapgen.editor import BAR_H, MapEditor
from alphatank.sim.mapspec import MapError, load_map, parse_map

CELL = 40


def rows_of(model: EditorModel) -> list[str]:
    return ["".join(r) for r in model.grid]


# ---- model --------------------------------------------------------------------------------


def test_blank_model_is_a_bordered_valid_map():
    m = EditorModel.blank(5, 7, "x")
    assert rows_of(m) == ["#######", "#.....#", "#.....#", "#.....#", "#######"]
    spec = m.check()
    assert spec.name == "x" and spec.walls.sum() == 20


def test_paint_moves_spawns_and_strokes_undo_as_one_step():
    m = EditorModel.blank(5, 7)
    assert m.paint(1, 1, "1") and m.paint(3, 5, "2")
    assert m.paint(1, 3, "1")  # slot 1 moves: the old cell becomes floor
    assert rows_of(m)[1] == "#..1..#"
    assert not m.paint(1, 3, "1")  # no change, no undo step
    m.begin_stroke()
    for c in range(1, 6):
        m.paint(2, c, "#")
    m.end_stroke()
    assert rows_of(m)[2] == "#######"
    assert m.undo() and rows_of(m)[2] == "#.....#"  # the whole drag at once
    assert m.undo() and rows_of(m)[1] == "#1....#"  # the move, both cells
    assert m.redo() and rows_of(m)[1] == "#..1..#"
    m.paint(3, 1, "+")
    assert not m.redo()  # a new paint clears the redo history
    with pytest.raises(MapGenError, match="unknown tool 'x'"):
        m.paint(1, 1, "x")
    assert not m.paint(9, 9, "#")  # outside the grid


def test_save_refuses_invalid_maps_with_the_loaders_message(tmp_path):
    m = EditorModel.blank(5, 7, "x")
    m.paint(1, 1, "1")
    m.paint(1, 5, "2")
    m.paint(1, 3, "#")
    m.paint(2, 3, "#")
    m.paint(3, 3, "#")
    path = tmp_path / "cut.txt"
    with pytest.raises(MapError) as err:
        m.save(path)
    assert not path.exists()
    with pytest.raises(MapError) as loader:
        parse_map(m.text(), str(path), name="cut")
    assert str(err.value) == str(loader.value) == f"{path}:4:6: spawn 2 cannot be reached " \
                                                   "from spawn 1"
    m.undo()
    spec = m.save(path)
    assert load_map(path).spawns == spec.spawns == {1: (1, 1), 2: (1, 5)}
    assert not m.dirty


def test_open_keeps_header_and_reopens_unreachable_maps_but_not_broken_ones(tmp_path):
    path = tmp_path / "m.txt"
    path.write_text("; note\nname: mine\nauthor: me\n\n#####\n#1#2#\n#####\n")
    m = EditorModel.from_file(path)
    assert m.header == {"name": "mine", "author": "me"} and rows_of(m)[1] == "#1#2#"
    m.paint(1, 2, ".")
    m.save(path)
    assert path.read_text() == "; note\nname: mine\nauthor: me\n\n#####\n#1.2#\n#####\n"
    path.write_text("####\n#.#\n####\n")
    with pytest.raises(MapError, match="ragged row"):
        EditorModel.from_file(path)


def test_save_keeps_comment_lines_in_place(tmp_path):
    text = ("; top\nauthor: me\n; about the name\nname: mine\n; after the header\n\n"
            "; the north wall\n#######\n  ; inside the grid\n#1...2#\n#######\n; the end\n")
    path = tmp_path / "m.txt"
    path.write_text(text)
    m = EditorModel.from_file(path)
    m.paint(1, 3, "+")
    m.save(path)
    # header lines come out in the format's order; each comment moves with the line below it
    assert path.read_text() == text.replace("author: me\n; about the name\nname: mine\n",
                                            "; about the name\nname: mine\nauthor: me\n"
                                            ).replace("#1...2#", "#1.+.2#")
    path.write_text("; no header\n#####\n#1.2#\n#####\n")
    EditorModel.from_file(path).save(path)
    assert path.read_text() == "; no header\nname: m\n\n#####\n#1.2#\n#####\n"


# ---- window -------------------------------------------------------------------------------


def at(r: int, c: int) -> tuple[int, int]:
    return (c * CELL + CELL // 2, BAR_H + r * CELL + CELL // 2)


def post(kind: int, **fields: object) -> None:
    pygame.event.post(pygame.event.Event(kind, **fields))


def key(k: int, mod: int = 0) -> None:
    post(pygame.KEYDOWN, key=k, mod=mod, unicode="")


def drag(cells: list[tuple[int, int]], button: int = 1) -> None:
    post(pygame.MOUSEBUTTONDOWN, pos=at(*cells[0]), button=button)
    held = (1, 0, 0) if button == 1 else (0, 0, 1)
    for cell in cells[1:]:
        post(pygame.MOUSEMOTION, pos=at(*cell), rel=(0, 0), buttons=held)
    post(pygame.MOUSEBUTTONUP, pos=at(*cells[-1]), button=button)


@pytest.fixture
def editor(tmp_path):
    ed = MapEditor(EditorModel.blank(7, 9, "drawn"), tmp_path / "drawn.txt", cell_px=CELL)
    pygame.event.clear()
    yield ed
    ed.close()


def test_editor_paints_undoes_and_saves_a_file_that_loads(editor):
    key(pygame.K_w)
    drag([(3, c) for c in range(1, 7)])  # a wall along row 3, leaving a gap at column 7
    editor.run(max_frames=1)
    assert rows_of(editor.model)[3] == "#######.#"
    key(pygame.K_1)
    drag([(1, 1)])
    key(pygame.K_2)
    drag([(5, 1)])
    key(pygame.K_b)
    drag([(1, 7), (2, 7)])  # buff zone cells
    drag([(2, 7)], button=3)  # right button paints floor
    editor.run(max_frames=1)
    assert rows_of(editor.model)[1] == "#1.....+#" and rows_of(editor.model)[2] == "#.......#"
    key(pygame.K_z, pygame.KMOD_CTRL)  # undo the right-click
    key(pygame.K_z, pygame.KMOD_CTRL)  # undo the buff drag (one stroke)
    editor.run(max_frames=1)
    assert rows_of(editor.model)[1] == "#1......#" and rows_of(editor.model)[2][7] == "."
    assert editor.message == "undo"
    key(pygame.K_y, pygame.KMOD_CTRL)  # redo the buff drag
    key(pygame.K_s, pygame.KMOD_CTRL)
    editor.run(max_frames=1)
    assert editor.message == f"saved {editor.path}"
    spec = load_map(editor.path)
    assert spec.spawns == {1: (1, 1), 2: (5, 1)}
    assert set(spec.buffs) == {(1, 7), (2, 7)}
    assert spec.walls[3, 1:7].all() and not spec.walls[3, 7]
    frame = pygame.surfarray.array3d(editor.screen)
    assert frame.shape[:2] == (9 * CELL, BAR_H + 7 * CELL + 26)


def test_editor_refuses_to_save_an_invalid_map_and_says_why(editor):
    editor.path.write_text("old\n")
    key(pygame.K_1)
    drag([(1, 1)])
    key(pygame.K_2)
    drag([(5, 7)])
    key(pygame.K_w)
    drag([(3, c) for c in range(1, 8)])  # cuts the map in two
    key(pygame.K_s, pygame.KMOD_CTRL)
    editor.run(max_frames=1)
    assert editor.path.read_text() == "old\n"  # untouched
    expected = f"{editor.path}:8:8: spawn 2 cannot be reached from spawn 1"
    assert editor.message == f"not saved: {expected}"
    assert editor.error is not None and editor.error.message.startswith("spawn 2 cannot")
    key(pygame.K_z, pygame.KMOD_CTRL)
    key(pygame.K_s, pygame.KMOD_CTRL)
    editor.run(max_frames=1)
    assert load_map(editor.path).spawns == {1: (1, 1), 2: (5, 7)}
    assert editor.error is None


def test_toolbar_click_selects_and_escape_asks_before_losing_changes(editor):
    post(pygame.MOUSEBUTTONDOWN, pos=(int(editor.tool_w * 10.5), BAR_H // 2), button=1)
    editor.run(max_frames=1)
    assert editor.tool == "+"  # toolbar order: # . 1..8 + -
    drag([(2, 2)])
    key(pygame.K_ESCAPE)
    editor.run(max_frames=1)
    assert editor.running and "unsaved changes" in editor.message
    key(pygame.K_ESCAPE)
    assert editor.run(max_frames=5) == 1  # quits within the frame
    assert not editor.running
    assert np.count_nonzero(editor.model.grid == "+") == 1
