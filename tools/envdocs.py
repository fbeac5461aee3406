"""Regenerate the parts of docs/environments.md that are generated from the code.

    python tools/envdocs.py          # rewrite them in place
    python tools/envdocs.py --check  # exit 1 (and say which) if the doc is out of date

Each part sits between ``<!-- begin generated: NAME -->`` and ``<!-- end generated: NAME
-->``; ``tests/test_docs_generated.py`` fails when one differs from what this script writes.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable
from pathlib import Path

from alphatank.envs.core import MatchSet
from alphatank.files import write_text_atomic
from alphatank.game.observe import BLOCK_HELP, FIELD_HELP, OBS_KINDS, ObsLayout
from alphatank.game.scenarios import load_scenario, shipped_scenarios

DOC = Path(__file__).resolve().parent.parent / "docs" / "environments.md"
EXAMPLE = "vs_smart"  # the scenario whose layouts the tables show


def layout(scenario: str, kind: str) -> ObsLayout:
    return MatchSet(scenario, 1, observation=kind).obs.layout


def observations() -> str:
    """Both kinds' layouts for the example scenario, the field glossary and every shipped
    scenario's observation size."""
    parts = []
    fields: dict[str, None] = {}
    for kind in OBS_KINDS:
        lay = layout(EXAMPLE, kind)
        parts.append(f"`{kind}` ({lay.size} floats for `{EXAMPLE}`):\n\n"
                     + lay.markdown(BLOCK_HELP))
        for names in lay.slot_fields.values():
            fields.update(dict.fromkeys(names))
    fields["team"] = None
    rows = ["| field | meaning |", "| --- | --- |"]
    for f in fields:
        if f == "c0x":  # the eight corner coordinates share one row
            rows.append("| c0x, c0y, ... c3y | corner k (0 front-left, 1 front-right, 2 "
                        "back-right, 3 back-left on screen), scaled like x and y |")
        elif not re.fullmatch(r"c\d[xy]", f):
            rows.append(f"| {f} | {FIELD_HELP[f]} |")
    parts.append("Fields:\n\n" + "\n".join(rows))
    rows = ["| scenario | tanks | team flags | " + " | ".join(OBS_KINDS) + " |",
            "| --- | --- | --- |" + " --- |" * len(OBS_KINDS)]
    for name in shipped_scenarios():
        sc = load_scenario(name)
        if not sc.learner_seats:
            continue
        sizes = [str(layout(name, kind).size) for kind in OBS_KINDS]
        rows.append(f"| `{name}` | {len(sc.seats)} | {'yes' if sc.team_mode else 'no'} | "
                    + " | ".join(sizes) + " |")
    parts.append("Observation size (floats) of each shipped scenario with a learner seat:\n\n"
                 + "\n".join(rows))
    return "\n\n".join(parts)


SECTIONS: dict[str, Callable[[], str]] = {"observations": observations}


def pattern(name: str) -> re.Pattern[str]:
    return re.compile(rf"(<!-- begin generated: {name} -->\n)(.*?)(<!-- end generated: "
                      rf"{name} -->)", re.S)


def regenerate(text: str) -> str:
    """``text`` with every generated section replaced by its current content."""
    for name, make in SECTIONS.items():
        pat = pattern(name)
        if not pat.search(text):
            raise SystemExit(f"{DOC}: no generated section {name!r} (add the begin/end markers)")
        body = make()
        text = pat.sub(lambda m, body=body: m.group(1) + body + "\n" + m.group(3), text)
    return text


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--check", action="store_true", help="only check; exit 1 if out of date")
    args = ap.parse_args(argv)
    text = DOC.read_text(encoding="utf-8")
    new = regenerate(text)
    if new == text:
        return 0
    if args.check:
        print(f"{DOC}: generated sections are out of date; run python tools/envdocs.py")
        return 1
    write_text_atomic(DOC, new)
    print(f"{DOC}: regenerated {', '.join(SECTIONS)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
