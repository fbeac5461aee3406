"""Reports of experiment tables: ``<table>.md``, ``.csv``, ``.json`` and figures, from what
the runs and evaluations of a :class:`~alphatank.training.experiments.Plan` left on disk.

Per (row, column): every seed's counts with its Wilson 95% interval; over seeds the
median and the interquartile mean (IQM) with a 95% stratified bootstrap interval
(:mod:`alphatank.training.aggregate`); the paper's figure beside ours. Missing cells
(runs not finished or failed) show as ``-`` and are listed. Checks (the issue's targets)
are evaluated on the IQM. With several seeds, each cell's games are also pooled, with a
permutation test of whether its seeds differ more than their games' luck
(:func:`~alphatank.training.aggregate.pool_runs`). One openskill table rates every run of
the table and the bots it met, from the evaluation games.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from alphatank.files import write_text_atomic
from alphatank.stats import wilson_interval
from alphatank.training.aggregate import Pooled, iqm, median, pool_runs, stratified_bootstrap
from alphatank.training.evaluate import markdown_table, rate_games, rating_table
from alphatank.training.experiments import (
    EVAL_SEED_BASE,
    Column,
    Plan,
    Row,
    Table,
    clone_cut,
    last_failure,
    read_json,
    retrain_hint,
)


@dataclass
class Agg:
    """Win rates (0..1) of one cell over seeds and what they aggregate to."""

    rates: list[float]
    wins: int = 0
    losses: int = 0
    draws: int = 0
    counts: list[tuple[int, int]] = field(default_factory=list)  # per seed (wins, games)

    @property
    def games(self) -> int:
        return self.wins + self.losses + self.draws

    @property
    def median(self) -> float:
        return median(np.array(self.rates))

    @property
    def iqm(self) -> float:
        return iqm(np.array(self.rates))

    @property
    def ci(self) -> tuple[float, float] | None:
        """95% stratified bootstrap interval of the IQM (None with fewer than 2 seeds)."""
        if len(self.rates) < 2:
            return None
        return stratified_bootstrap(np.array(self.rates))

    @property
    def wilson(self) -> tuple[float, float]:
        return wilson_interval(self.wins, self.games)

    @property
    def pooled(self) -> Pooled | None:
        """The seeds' games pooled and tested (None without two seeds' counts)."""
        if len(self.counts) < 2:
            return None
        return pool_runs([w for w, _ in self.counts], [n for _, n in self.counts])


@dataclass
class RowResult:
    row: Row
    columns: list[Column]
    evals: dict[str, dict[int, dict[str, Any]]] = field(default_factory=dict)  # col -> seed
    runs: dict[int, dict[str, Any]] = field(default_factory=dict)  # seed -> done.json
    run_dirs: dict[int, str] = field(default_factory=dict)
    errors: dict[int, str] = field(default_factory=dict)
    seeds: int = 1  # the plan's: a check measures a figure once every seed has it

    def agg(self, col: str) -> Agg | None:
        cells = self.evals.get(col, {})
        if not cells:
            return None
        a = Agg([c["wins"] / c["games"] for _, c in sorted(cells.items())])
        for _, c in sorted(cells.items()):
            a.wins += c["wins"]
            a.losses += c["losses"]
            a.draws += c["draws"]
            a.counts.append((c["wins"], c["games"]))
        return a

    def average(self) -> Agg | None:
        """Per seed the mean win rate over the row's columns (seeds with every column)."""
        names = [c.name for c in self.columns]
        seeds = sorted(set.intersection(*(set(self.evals.get(n, {})) for n in names)))
        if not seeds:
            return None
        return Agg([float(np.mean([self.evals[n][s]["wins"] / self.evals[n][s]["games"]
                                   for n in names])) for s in seeds])

    def ours(self, col: str) -> float | None:
        """The IQM over seeds, in percent."""
        a = self.average() if col == "average" else self.agg(col)
        return None if a is None else 100.0 * a.iqm

    def measured(self, col: str) -> float | None:
        """The value checks compare: :meth:`ours`, None until every seed of the plan has
        it (a check does not judge the seeds that finished first)."""
        a = self.average() if col == "average" else self.agg(col)
        return None if a is None or len(a.rates) < self.seeds else 100.0 * a.iqm

    def paper_value(self, col: str) -> float | None:
        if col in self.row.paper:
            return self.row.paper[col]
        if col == "average":
            vals = [self.row.paper.get(c.name) for c in self.columns]
            if vals and all(v is not None for v in vals):
                return float(np.mean(vals))
        return None


def collect(plan: Plan, table: Table) -> list[RowResult]:
    """What the plan's runs left on disk for ``table``'s rows."""
    out = []
    for row in table.rows:
        rr = RowResult(row, table.row_columns(row), seeds=plan.seeds)
        for s in range(plan.seeds):
            job, specs = plan.cells[(row.id, s)]
            rr.run_dirs[s] = job.run_dir
            failure = last_failure(job)
            if failure is not None:
                rr.errors[s] = failure
            if job.done_file.is_file():
                rr.runs[s] = read_json(job.done_file)
            for name, spec in specs.items():
                f = job.eval_file(spec)
                if f.is_file():
                    rr.evals.setdefault(name, {})[s] = read_json(f)
        out.append(rr)
    return out


def evaluated_rows(plan: Plan, table: Table) -> list[Row]:
    """``table``'s rows with an evaluation of any seed of ``plan`` on disk."""
    return [row for row in table.rows
            if any(job.eval_file(spec).is_file() for s in range(plan.seeds)
                   for job, specs in [plan.cells[(row.id, s)]] for spec in specs.values())]


def reported_runs(path: Path) -> set[tuple[str, int]]:
    """(row name, seed) of every run with results in the report ``path``
    (``<table>.json``); none when it is missing. ValueError naming it when it cannot be
    read or is not such a report (emptied, cut short): never taken for no report."""
    if not path.exists():
        return set()
    data = read_json(path)
    try:
        return {(r["row"], int(run["seed"])) for r in data["rows"]
                for c in r["columns"].values() for run in c["per_seed"]}
    except (ValueError, KeyError, TypeError, AttributeError):
        raise ValueError(f"{path}: not a report of alphatank experiments (rows, columns, "
                         "per_seed)") from None


# ---- formatting -----------------------------------------------------------------------

def pct(x: float) -> str:
    return f"{100 * x:.1f}%"


def interval(ci: tuple[float, float] | None) -> str:
    return "" if ci is None else f"[{100 * ci[0]:.1f}, {100 * ci[1]:.1f}]"


def cell_text(a: Agg | None, paper: float | None) -> str:
    if a is None:
        text = "-"
    elif len(a.rates) == 1:
        text = f"{pct(a.rates[0])} {interval(a.wilson)}" if a.games else pct(a.rates[0])
    else:
        text = f"IQM {pct(a.iqm)} {interval(a.ci)}, med {pct(a.median)}"
    if paper is not None:
        text += f" (paper {paper:g}%)"
    return text


def _opponent_kind(results: list[RowResult]) -> str:
    kinds = {c.get("opponent_kind") for rr in results for cells in rr.evals.values()
             for c in cells.values()}
    return "Bot" if kinds == {"bot"} else "Opponent"


def _steps(rr: RowResult) -> str:
    """Env steps of each seed's run; "cloning cut" for a run whose budget ended while it
    cloned its bot (it was evaluated untrained)."""
    if not rr.runs:
        return "-"
    out = []
    for s in sorted(rr.runs):
        summary = rr.runs[s]["summary"]
        st = trained_steps(summary)
        out.append("cloning cut" if clone_cut(summary) else
                   f"{st / 1e6:.2f}M" if st >= 1e5 else f"{st:,}")
    return "/".join(out)


def trained_steps(summary: dict[str, Any]) -> int:
    """Env steps of the checkpoint a run was evaluated from (``saved_step``: a time limit
    can end a run after steps its last save does not hold; older runs: ``global_step``)."""
    saved = summary.get("saved_step", -1)
    return int(saved) if saved is not None and saved >= 0 else int(summary["global_step"])


def counts_table(results: list[RowResult], seeds: int) -> str:
    """The paper's Table 3 layout (one column per table): counts summed over seeds."""
    them = _opponent_kind(results)
    head = ["Experiment Name", "Agent Wins", f"{them} Wins", "Draws", "Agent Win Ratio",
            "Wilson 95% CI", "Paper"]
    if seeds > 1:
        head += ["Median", "IQM [95% bootstrap CI]"]
    head += ["Steps trained"]
    rows = []
    for rr in results:
        col = rr.columns[0].name
        a = rr.agg(col)
        paper = rr.paper_value(col)
        paper_text = "-" if paper is None else f"{paper:g}%"
        if a is None:
            row = [rr.row.title, "-", "-", "-", "-", "-", paper_text]
            row += ["-", "-"] if seeds > 1 else []
        else:
            row = [rr.row.title, str(a.wins), str(a.losses), str(a.draws),
                   pct(a.wins / a.games), interval(a.wilson), paper_text]
            if seeds > 1:
                row += [pct(a.median), f"{pct(a.iqm)} {interval(a.ci)}".strip()]
        rows.append(row + [_steps(rr)])
    return markdown_table(head, rows)


def matrix_table(table: Table, results: list[RowResult]) -> str:
    """Rows x columns of win rates (with the paper's figure), plus the average."""
    head = [table.title.split(":")[0] if ":" in table.title else "Row",
            *[c.label for c in table.columns]]
    if table.average:
        head.append("Average")
    head.append("Steps trained")
    rows = []
    for rr in results:
        row = [rr.row.title]
        mine = {c.name for c in rr.columns}
        for c in table.columns:
            row.append(cell_text(rr.agg(c.name), rr.paper_value(c.name))
                       if c.name in mine else "")
        if table.average:
            paper = rr.paper_value("average") if table.paper_average else None
            row.append(cell_text(rr.average(), paper))
        rows.append(row + [_steps(rr)])
    return markdown_table(head, rows)


def pooled_table(results: list[RowResult]) -> str | None:
    """Per row and column with two or more seeds: their games pooled (win rate, Wilson
    95%) and the permutation p-value of the seeds' spread; None when no cell has two."""
    cols = list(dict.fromkeys((c.name, c.label) for rr in results for c in rr.columns))
    body = []
    for rr in results:
        cells = []
        for name, _ in cols:
            a = rr.agg(name)  # None for a column the row has no evaluation in
            pool = None if a is None else a.pooled
            cells.append("-" if pool is None else
                         f"{pct(pool.rate)} {interval(pool.interval)}, p {pool.p_text}")
        if any(c != "-" for c in cells):
            body.append([rr.row.title] + cells)
    if not body:
        return None
    return markdown_table(["Row"] + [label for _, label in cols], body)


def runs_table(results: list[RowResult]) -> str:
    """Every (row, seed, column): counts with the run's Wilson interval, and the run."""
    head = ["Row", "Seed", "Column", "Wins", "Losses", "Draws", "Win rate", "Wilson 95% CI",
            "Steps", "Train min", "Stopped by", "Run"]
    rows = []
    for rr in results:
        seeds = sorted(set(rr.run_dirs))
        for s in seeds:
            run = rr.runs.get(s)
            steps = f"{trained_steps(run['summary']):,}" if run else "-"
            minutes = f"{run['wall_s'] / 60:.1f}" if run else "-"
            stopped = run["stopped_by"] if run else ("failed" if s in rr.errors else "-")
            if run and clone_cut(run["summary"]):
                stopped += " (cloning cut)"
            for c in rr.columns:
                e = rr.evals.get(c.name, {}).get(s)
                if e is None:
                    rows.append([rr.row.title, str(s), c.label, "-", "-", "-", "-", "-", steps,
                                 minutes, stopped, Path(rr.run_dirs[s]).name])
                    continue
                lo, hi = wilson_interval(e["wins"], e["games"])
                rows.append([rr.row.title, str(s), c.label, str(e["wins"]), str(e["losses"]),
                             str(e["draws"]), pct(e["wins"] / e["games"]),
                             interval((lo, hi)), steps, minutes, stopped,
                             Path(rr.run_dirs[s]).name])
    return markdown_table(head, rows)


# ---- checks (the targets) ---------------------------------------------------

def run_checks(table: Table, results: list[RowResult]) -> list[dict[str, Any]]:
    """Each check of the table: ``{"check", "passed" (True/False/None: not measurable),
    "details"}``."""
    by_name = {rr.row.name: rr for rr in results}
    out = []
    for chk in table.checks:
        kind = chk["kind"]
        details: list[str] = []
        passed: bool | None = None
        if kind == "beats_paper":
            verdicts = []
            for rr in results:
                if chk.get("rows") and rr.row.name not in chk["rows"]:
                    continue
                for c in [*rr.columns, *([Column("average", "Average")]
                                         if table.average else [])]:
                    paper, ours = rr.paper_value(c.name), rr.measured(c.name)
                    if paper is None:
                        continue
                    if ours is None:
                        verdicts.append(None)
                        continue
                    verdicts.append(ours >= paper)
                    if ours < paper:
                        details.append(f"{rr.row.title} / {c.label}: {ours:.1f}% < paper "
                                       f"{paper:g}%")
            passed = _all(verdicts)
            text = "every cell with a paper figure is at or above it"
        elif kind == "best_average":
            theirs = {n: by_name[n].measured("average") if n in by_name else None
                      for n in chk.get("against", [])}
            best = max((x for x in theirs.values() if x is not None), default=None)
            unmeasured = [n for n, x in theirs.items() if x is None]
            above = chk.get("above")
            verdicts = []
            for name in chk.get("rows", []):
                rr = by_name.get(name)
                mine = None if rr is None else rr.measured("average")
                if mine is None or best is None:
                    verdicts.append(None)
                    continue
                ok = mine > best and (above is None or mine > above)
                # above the specialists measured: not yet above those without an average
                verdicts.append(None if ok and unmeasured else ok)
                details.append(f"{rr.row.title}: average {mine:.1f}% vs best specialist "
                               f"{best:.1f}%" + (f", target > {above:g}%" if above else "")
                               + (" - no" if not ok else " - yes" if not unmeasured else
                                  f" - so far (no average yet of {', '.join(unmeasured)})"))
            passed = (True if any(v is True for v in verdicts) else  # some row: any
                      None if not verdicts or None in verdicts else False)
            text = (f"some row of {chk.get('rows', [])} averages above every specialist"
                    + (f" and above {above:g}%" if above else ""))
        elif kind == "within":
            rr = by_name.get(chk.get("row", ""))
            points = float(chk.get("points", 5))
            verdicts = []
            for col, spec_name in chk.get("specialists", {}).items():
                spec = by_name.get(spec_name)
                mine = None if rr is None else rr.measured(col)
                theirs = None if spec is None else spec.measured(col)
                if mine is None or theirs is None:
                    verdicts.append(None)
                    continue
                ok = mine >= theirs - points
                verdicts.append(ok)
                details.append(f"{col}: {mine:.1f}% vs specialist {theirs:.1f}%"
                               + ("" if ok else " - more than "
                                  f"{points:g} points below"))
            passed = _all(verdicts)
            text = f"{chk.get('row')} within {points:g} points of each specialist on its bot"
        else:  # gap
            a, b = chk.get("columns", ["", ""])
            points = float(chk.get("points", 10))
            verdicts = []
            for rr in results:
                x, y = rr.measured(a), rr.measured(b)
                if x is None or y is None:
                    verdicts.append(None)
                    continue
                ok = abs(x - y) <= points
                verdicts.append(ok)
                details.append(f"{rr.row.title}: {a} {x:.1f}% vs {b} {y:.1f}% (gap "
                               f"{abs(x - y):.1f})")
            passed = _all(verdicts)
            text = f"gap between {a} and {b} at most {points:g} points"
        out.append({"check": chk.get("text", text), "kind": kind, "passed": passed,
                    "details": details})
    return out


def _all(verdicts: list[bool | None]) -> bool | None:
    if not verdicts or any(v is None for v in verdicts):
        return None if all(v is not False for v in verdicts) else False
    return all(verdicts)


# ---- ratings -------------------------------------------------------------------------

def ratings(results: list[RowResult]) -> Any:
    """One openskill league over every (row, seed) agent and the bots it met."""
    games = []
    for rr in results:
        for c in rr.columns:
            for s, e in sorted(rr.evals.get(c.name, {}).items()):
                if e.get("opponent_kind") != "bot":
                    continue
                opp = e["experiment"].split(" vs ", 1)[-1]
                if e["spec"].get("map"):
                    opp += f" (maps {e['spec']['map']})"
                games.append((f"{rr.row.title} s{s}", opp, e["outcomes"]))
    return rate_games(games) if games else None


# ---- the files -------------------------------------------------------------------------

def _figures(plan: Plan, table: Table, results: list[RowResult]) -> dict[str, Path]:
    from alphatank.training.plots import plot_heatmap, plot_row_curves

    figs: dict[str, Path] = {}
    paths = {name: plan.out / "figures" / f"{table.name}_{name}.png"
             for name in ("curves", "heatmap")}
    groups = [(rr.row.title, [rr.run_dirs[s] for s in sorted(rr.runs)]) for rr in results]
    if any(runs for _, runs in groups):
        plot_row_curves(groups, paths["curves"], title=f"{table.title}: training win rate")
        figs["curves"] = paths["curves"]
    if table.heatmap:
        cols = [c.name for c in table.columns] + (["average"] if table.average else [])
        labels = [c.label for c in table.columns] + (["Average"] if table.average else [])
        ours = np.array([[np.nan if rr.ours(c) is None else rr.ours(c) for c in cols]
                         for rr in results])
        paper = np.array([[np.nan if rr.paper_value(c) is None else rr.paper_value(c)
                           for c in cols] for rr in results])
        if not np.isnan(ours).all():
            plot_heatmap(ours, [rr.row.title for rr in results], labels, paths["heatmap"],
                         title=table.title, paper=paper)
            figs["heatmap"] = paths["heatmap"]
    for name, path in paths.items():  # one of an earlier report showed other results
        if name not in figs:
            path.unlink(missing_ok=True)
    return figs


def write_report(plan: Plan, table: Table, command: str = "") -> dict[str, Any]:
    """Write ``<out>/<table>.md``, ``.csv``, ``.json`` and its figures; returns the JSON
    data (with ``checks`` and ``missing``)."""
    results = collect(plan, table)
    checks = run_checks(table, results)
    league = ratings(results)
    figs = _figures(plan, table, results)
    missing = [f"{rr.row.id} seed {s}"
               + (f": {rr.errors[s]}" + retrain_hint(plan.cells[(rr.row.id, s)][0],
                                                     rr.errors[s]) if s in rr.errors else "")
               for rr in results for s in range(plan.seeds)
               if s not in rr.runs or any(s not in rr.evals.get(c.name, {})
                                          for c in rr.columns)]
    data = _json(plan, table, results, checks, league, command, missing)
    md = _markdown(plan, table, results, checks, league, figs, command, missing)
    write_text_atomic(plan.out / f"{table.name}.md", md)
    write_text_atomic(plan.out / f"{table.name}.csv", _csv(table, results))
    import json
    write_text_atomic(plan.out / f"{table.name}.json", json.dumps(data, indent=1) + "\n")
    return data


def _markdown(plan: Plan, table: Table, results: list[RowResult], checks: list[dict],
              league: Any, figs: dict[str, Path], command: str, missing: list[str]) -> str:
    lines = [f"# {table.title}", ""]
    if table.description:
        lines += [table.description, ""]
    lines += [f"Made by `{command}`" if command else "", "",
              f"Budget {plan.budget_min:g} min per run, {plan.seeds} seed(s) per row, "
              f"{plan.games} evaluation games per cell at full bot strength. Seed rule: "
              f"seed index s trains with seed s and is evaluated with seed "
              f"{EVAL_SEED_BASE:,} + s (game i of an evaluation depends only on that seed "
              f"and i). Generated {time.strftime('%Y-%m-%d %H:%M')} on {platform.node() or 'a'}"
              f" machine with {os.cpu_count()} CPU(s).", ""]
    seeds_note = ("one seed: each cell is the win rate with its Wilson 95% interval"
                  if plan.seeds == 1 else
                  f"{plan.seeds} seeds: each cell is the interquartile mean (IQM) over seeds "
                  f"with its 95% stratified bootstrap interval and the median; every run's "
                  f"own Wilson interval is in the table of runs below")
    lines += [f"Cells: {seeds_note}. Paper figures in parentheses.", ""]
    if table.layout == "counts" and len(table.columns) == 1:
        lines += [counts_table(results, plan.seeds), ""]
    else:
        lines += [matrix_table(table, results), ""]
    lines += ["Columns (what each is evaluated against):", ""]
    for c in table.columns:
        what = f"the {c.bot} bot" if c.bot else "the scenario's own opponents"
        lines.append(f"- **{c.label}**: {what} in {c.where()}, bots at weakness "
                     f"{c.weakness:g}" + (f". {c.note}" if c.note else ""))
    lines += ["", "Rows:", ""]
    for rr in results:
        how = (f"; trains on a mix of {', '.join(rr.row.scenarios)}" if rr.row.scenarios
               else "")
        if rr.row.eval_game:
            how += "; evaluated with " + ", ".join(f"{k} = {json.dumps(v)}"
                                                   for k, v in rr.row.eval_game.items())
        lines.append(f"- **{rr.row.title}** (`{rr.row.source}`){how}"
                     + (f". {rr.row.note}" if rr.row.note else ""))
    pooled = pooled_table(results)
    if pooled is not None:
        lines += ["", "## Seeds pooled", "",
                  "Each cell: the seeds' evaluation games together (win rate, Wilson 95%) and "
                  "the permutation p-value of the spread of their win rates (the games dealt "
                  "out to the seeds again 2,000 times): a small p says the seeds differ more "
                  "than their games' luck (a bad or a lucky run), a large one that they play "
                  "like one agent, so the pooled interval is the row's figure.", "", pooled]
    if checks:
        lines += ["", "## Targets", ""]
        for c in checks:
            mark = {True: "met", False: "NOT met", None: "not measurable yet"}[c["passed"]]
            lines.append(f"- {c['check']}: **{mark}**")
            lines += [f"  - {d}" for d in c["details"]]
    if figs:
        lines += ["", "## Figures", ""]
        for name, path in figs.items():
            lines.append(f"![{table.name} {name}]({path.relative_to(plan.out).as_posix()})")
    if league is not None:
        lines += ["", "## openskill ratings (agents and bots in one table, from the "
                  "evaluation games; draws are ties)", "", rating_table(league)]
    for rr in results:
        for s, run in sorted(rr.runs.items()):
            if run.get("league"):
                lines += ["", f"## {rr.row.title}, seed {s}: the league's own ratings at the "
                          f"end of training (learner, bots, snapshots)", "",
                          markdown_table(("Player", "mu", "sigma", "ordinal"),
                                         [(n, f"{m:.2f}", f"{sg:.2f}", f"{o:.2f}")
                                          for n, m, sg, o in run["league"]])]
    lines += ["", "## Runs", "", runs_table(results)]
    if missing:
        lines += ["", "## Missing or failed", ""] + [f"- {m}" for m in missing]
    return "\n".join(lines) + "\n"


def _agg_json(a: Agg | None, paper: float | None) -> dict[str, Any]:
    if a is None:  # the keys of a cell with results, none of their figures
        return {"rates": [], "median": None, "iqm": None, "iqm_ci95": None, "pooled": None,
                "paper": paper}
    ci, pool = a.ci, a.pooled
    return {"rates": [round(r, 4) for r in a.rates], "median": round(a.median, 4),
            "iqm": round(a.iqm, 4), "iqm_ci95": None if ci is None else [round(ci[0], 4),
                                                                         round(ci[1], 4)],
            "pooled": None if pool is None else {
                "wins": pool.wins, "games": pool.games,
                "wilson95": [round(pool.interval[0], 4), round(pool.interval[1], 4)],
                "spread": round(pool.spread, 4), "noise": round(pool.noise, 4),
                "p_value": round(pool.p_value, 4)},
            "paper": paper}


def _json(plan: Plan, table: Table, results: list[RowResult], checks: list[dict],
          league: Any, command: str, missing: list[str]) -> dict[str, Any]:
    rows = []
    for rr in results:
        cols = {}
        for c in rr.columns:
            runs = []
            for s, e in sorted(rr.evals.get(c.name, {}).items()):
                lo, hi = wilson_interval(e["wins"], e["games"])
                runs.append({"seed": s, "wins": e["wins"], "losses": e["losses"],
                             "draws": e["draws"], "games": e["games"],
                             "win_rate": e["win_rate"], "wilson95": [round(lo, 4), round(hi, 4)],
                             "opponent": e["opponent"], "experiment": e["experiment"]})
            cols[c.name] = {**_agg_json(rr.agg(c.name), rr.paper_value(c.name)),
                            "per_seed": runs}
        rows.append({"row": rr.row.name, "title": rr.row.title, "source": rr.row.source,
                     "scenarios": list(rr.row.scenarios), "eval_game": rr.row.eval_game,
                     "columns": cols,
                     "average": _agg_json(rr.average(), rr.paper_value("average")),
                     "runs": [{"seed": s, "run_dir": rr.run_dirs[s],
                               "steps": trained_steps(rr.runs[s]["summary"]) if s in rr.runs
                               else None,
                               "train_s": rr.runs[s]["wall_s"] if s in rr.runs else None,
                               "stopped_by": rr.runs[s]["stopped_by"] if s in rr.runs else None,
                               "cloning_cut": clone_cut(rr.runs[s]["summary"]) if s in rr.runs
                               else None,
                               "error": rr.errors.get(s)} for s in sorted(rr.run_dirs)]})
    return {"table": table.name, "title": table.title, "command": command,
            "generated": time.strftime("%Y-%m-%d %H:%M:%S"), "budget_min": plan.budget_min,
            "seeds": plan.seeds, "games": plan.games,
            "seed_rule": f"train seed s, evaluation seed {EVAL_SEED_BASE} + s",
            "columns": [{"name": c.name, "label": c.label, "where": c.where(),
                         "bot": c.bot, "weakness": c.weakness} for c in table.columns],
            "rows": rows, "checks": checks, "missing": missing,
            "ratings": [] if league is None else [
                {"name": n, "mu": round(m, 3), "sigma": round(sg, 3), "ordinal": round(o, 3)}
                for n, m, sg, o in league.table()]}


def _csv(table: Table, results: list[RowResult]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["table", "row", "title", "column", "seeds", "wins", "losses", "draws",
                "games", "win_rate", "wilson95_low", "wilson95_high", "median", "iqm",
                "iqm_ci95_low", "iqm_ci95_high", "paper", "per_seed_win_rates"])
    for rr in results:
        for c in [*rr.columns, *([Column("average", "Average")] if table.average else [])]:
            a = rr.average() if c.name == "average" else rr.agg(c.name)
            paper = rr.paper_value(c.name)
            if a is None:
                w.writerow([table.name, rr.row.name, rr.row.title, c.name, 0, *[""] * 11,
                            "" if paper is None else paper, ""])
                continue
            lo, hi = a.wilson if a.games else (math.nan, math.nan)
            ci = a.ci or (math.nan, math.nan)
            w.writerow([table.name, rr.row.name, rr.row.title, c.name, len(a.rates),
                        a.wins if a.games else "", a.losses if a.games else "",
                        a.draws if a.games else "", a.games or "",
                        round(a.wins / a.games, 4) if a.games else round(np.mean(a.rates), 4),
                        _r(lo), _r(hi), _r(a.median), _r(a.iqm), _r(ci[0]), _r(ci[1]),
                        "" if paper is None else paper,
                        ";".join(f"{r:.4f}" for r in a.rates)])
    return buf.getvalue()


def _r(x: float) -> str:
    return "" if math.isnan(x) else f"{x:.4f}"
