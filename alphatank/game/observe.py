"""Per-agent observation vectors, built for many matches and agents at once.

Nine kinds (``OBS_KINDS``), all float32, clipped to [-1, 1], with a fixed size per
scenario and an index map (:class:`ObsLayout`, feature name -> slice):

``paper``       every component of the paper's Table 1 in map coordinates: own tank
                (position, heading sin/cos, velocity, corners, wall contact, alive, plus
                reload and bullets in flight), own bullets, every other tank (teammates first, then
                enemies; position, relative position, distance, corners, velocity, ...),
                other tanks' bullets nearest first (position, velocity, relative position,
                distance), the map's wall rectangles, buff/debuff zone positions and
                in-zone flags. Team scenarios add a ``team`` flag (1 = my team) to tanks
                and bullets. Padded slots have ``mask`` 0 and zeros elsewhere.
``egocentric``  the same entities in the tank's own frame (``fwd`` along the heading,
                ``side`` to its right on screen) plus a ring of wall-distance rays, so
                nothing depends on absolute map coordinates.
``egocentric_path``  the egocentric kind plus, for every other tank, the way to it through
                the maze: the unit direction (own frame) to the floor cell two steps ahead
                on a shortest grid path towards it, and that path's length in cells over
                the map's longest one (BFS, :mod:`alphatank.sim.navigation`). A policy can
                then hunt a bot that never comes to it on any map.
``egocentric_nearest``  the egocentric kind with the other tanks ordered nearest first
                (teammates, then enemies; dead ones last in their group) instead of by
                seat: ``tank[m]`` (m teammates) is always the nearest living enemy, whatever
                the line-up. A 1v1 policy warm-starts a team seat with its enemy features
                on the nearest enemy (in a 1v1 the kind equals ``egocentric``).
``egocentric_aim``  the ``egocentric_nearest`` kind plus a ``shot`` block: where a bullet
                fired now along the heading would go (the ricochet prediction the bots aim
                with): whether the first tank it reaches is an enemy or a teammate, and its
                closest approach to a live enemy. Firing is then a function of what the
                policy sees, not of wall geometry it must infer from rays.
``egocentric_aim_path``  ``egocentric_aim`` with ``egocentric_path``'s way to every other
                tank: where to shoot and which way round the walls leads to a target.
``egocentric_full``  ``egocentric_aim_path`` plus a ``threat`` block: of the other tanks'
                bullets, the one that will pass closest to me within a second (straight
                lines, like the bots' dodging): how close, how soon, and on which side.
``egocentric_fire``  ``egocentric_full`` plus every other tank's line of fire, in its
                ``tank[k]`` slot: whether a bullet it fired now would reach me first
                (the same ricochet prediction), how close it would pass me, and whether
                its gun is ready. The bots fire when their prediction meets a target, so
                this shows who is about to shoot at me before the bullet flies.
``egocentric_advice``  ``egocentric_full`` plus an ``advice`` block: what the smart bot
                would do now in my seat (its rotate, move and fire, one-hot), from a
                bot kept per seat and asked at every observation. The policy sees the
                bot's route memory, lead and bank-shot search, and learns when to do
                otherwise.

Scales: map positions ``2 x / W - 1``; relative positions divided by ``max(W, H)``;
distances by the map diagonal; tank velocities by ``tank_speed``; bullet velocities by
``bullet_speed``; rays by ``ray_length``. :class:`StateBatch` gathers the arrays of all
matches once per step (a few ``copyto`` per match); :class:`ObservationBuilder` then
computes every observation with a fixed number of vectorised numpy calls into
preallocated buffers.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from alphatank.game.kernels import (
    nearest_bullets,
    nearest_threat,
    paper_observation,
    path_features,
    shot_reach,
    wall_rays,
)
from alphatank.game.seats import Seat, make_controller
from alphatank.sim.ballistics import predict_points, segment_distances
from alphatank.sim.config import GameConfig, hit_radius
from alphatank.sim.mapspec import MapSpec
from alphatank.sim.navigation import NavGrid, nav_grid

if TYPE_CHECKING:
    from alphatank.sim.match import Match
    from alphatank.sim.policy import Policy

OBS_KINDS = ("paper", "egocentric", "egocentric_path", "egocentric_nearest", "egocentric_aim",
             "egocentric_aim_path", "egocentric_full", "egocentric_fire", "egocentric_advice")
# What the egocentric kinds add: other tanks nearest first, the way to each, the shot
# block, the threat block, the other tanks' lines of fire, the advice block.
NEAREST_KINDS = ("egocentric_nearest", "egocentric_aim", "egocentric_aim_path", "egocentric_full",
                 "egocentric_fire", "egocentric_advice")
PATH_KINDS = ("egocentric_path", "egocentric_aim_path", "egocentric_full", "egocentric_fire",
              "egocentric_advice")
SHOT_KINDS = ("egocentric_aim", "egocentric_aim_path", "egocentric_full", "egocentric_fire",
              "egocentric_advice")
THREAT_KINDS = ("egocentric_full", "egocentric_fire", "egocentric_advice")
FIRE_KINDS = ("egocentric_fire",)
ADVICE_KINDS = ("egocentric_advice",)
ADVICE_BOT = "smart"  # the bot whose action the advice block shows
# the advice block: one-hot rotate (0 ccw, 1 none, 2 cw), one-hot move (0 back, 1 stop,
# 2 forward), fire
ADVICE_FIELDS = ("rot_ccw", "rot_none", "rot_cw", "back", "stop", "forward", "fire")
THREAT_FIELDS = ("near", "eta", "dir_fwd", "dir_side")
THREAT_HORIZON_S = 1.0  # bullets closing in later than this are no threat yet
SHOT_FIELDS = ("enemy", "friend", "miss")  # the shot block (StateBatch.shots' columns)
FIRE_FIELDS = ("aimed", "aim_near", "ready")  # FIRE_KINDS' extra fields of every tank[k]
TANK_FIELDS = ("alive", "x", "y", "sin", "cos", "vx", "vy", "c0x", "c0y", "c1x", "c1y",
               "c2x", "c2y", "c3x", "c3y", "wall")  # columns of tank_table()
BULLET_FIELDS = ("x", "y", "vx", "vy")  # columns of bullet_table()
# Corner offsets in the tank frame (forward, right): front-left, front-right, back-right,
# back-left on screen (y down); multiplied by (width/2, height/2).
CORNERS = np.array([[1.0, -1.0], [1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0]])


def constant(value: float, dtype: type = np.float64) -> np.ndarray:
    """A read-only 0-d array: the operand of a per-step ufunc call that a Python number
    would be (numpy converts a Python number to an array at every call, about 1 us at a
    batch of one; the result is the same when the dtypes match)."""
    arr = np.full((), value, dtype=dtype)
    arr.setflags(write=False)
    return arr


ONE32, MINUS_ONE32 = constant(1.0, np.float32), constant(-1.0, np.float32)  # obs dtype
ZERO32 = constant(0.0, np.float32)  # x + 0.0 turns -0.0 into 0.0 and leaves the rest
# What each field of a slot means (docs/environments.md's observation tables come from this
# and the layouts; every field a layout names must be here).
FIELD_HELP = {
    "alive": "1 while the tank lives, else 0",
    "team": "1 if the tank (the bullet's shooter) is on my team (team scenarios only)",
    "mask": "1 if the slot holds something (a live bullet, a wall, a zone), else 0",
    "x": "x position, 2 x / W - 1", "y": "y position, 2 y / H - 1",
    "sin": "sin of the heading (egocentric `tank[k]`: of its heading minus mine)",
    "cos": "cos of the heading (egocentric `tank[k]`: of its heading minus mine)",
    "vx": "x velocity / tank_speed (tanks) or / bullet_speed (bullets)",
    "vy": "y velocity / tank_speed (tanks) or / bullet_speed (bullets)",
    **{f"c{k}{a}": f"{a} of corner {k} ({name}), scaled like {a}" for k, name in enumerate(
        ("front-left", "front-right", "back-right", "back-left")) for a in "xy"},
    "wall": "1 while the tank touches a wall",
    "reload": "cooldown ticks left / cooldown_ticks",
    "bullets": "own bullets in flight / bullet capacity",
    "rel_x": "x position minus mine, / max(W, H)", "rel_y": "y position minus mine, / max(W, H)",
    "dist": "distance from me / map diagonal (`ray[k]`: to the nearest wall / ray length)",
    "x0": "left edge, scaled like x", "y0": "top edge, scaled like y",
    "x1": "right edge, scaled like x", "y1": "bottom edge, scaled like y",
    "in_buff": "1 while I am in a buff zone", "in_debuff": "1 while I am in a debuff zone",
    "fwd": "position relative to me along my heading, / max(W, H)",
    "side": "position relative to me towards my right (on screen), / max(W, H)",
    "v_fwd": "velocity along my heading, / tank_speed or / bullet_speed",
    "v_side": "velocity towards my right, / tank_speed or / bullet_speed",
    "path_fwd": "unit direction along my heading to the cell two steps ahead on a shortest "
                "grid path to the tank (the tank itself once in its cell); 0 if dead",
    "path_side": "the same direction towards my right (on screen)",
    "path_dist": "BFS path length to the tank in cells / the map's longest path; "
                 "1 if unreachable, 0 if dead",
    "near": "1 - its closest approach / (4 x hit radius), at least 0",
    "eta": "1 - seconds to its closest approach / 1 s",
    "dir_fwd": "unit direction from me to its closest point, along my heading",
    "dir_side": "the same direction towards my right (on screen)",
    "rot_ccw": "1 if the smart bot in my seat would turn counter-clockwise now",
    "rot_none": "1 if it would not turn", "rot_cw": "1 if it would turn clockwise",
    "back": "1 if it would drive backwards", "stop": "1 if it would stand",
    "forward": "1 if it would drive forwards", "fire": "1 if it would fire",
    "enemy": "1 if a bullet fired now (ricochets predicted) first reaches an enemy tank",
    "friend": "1 if a bullet fired now first reaches a teammate",
    "miss": "closest approach of a bullet fired now to a live enemy (centres) / "
            "bullet_max_distance, at most 1 (1 with no enemy alive)",
    "aimed": "1 if a bullet the tank fired now (ricochets predicted) would reach me first",
    "aim_near": "1 - the closest approach to me of a bullet it fired now / (4 x hit radius), "
                "at least 0; 0 while either of us is dead",
    "ready": "1 if a fire action of the tank now would spawn a bullet (alive, reloaded, "
             "under its bullet limit)",
}
BLOCK_HELP = {
    "self": "the observing tank",
    "own_bullet": "my bullet slots, in slot order",
    "tank": "every other tank: teammates first, then enemies, each in seat order "
            "(`egocentric_nearest` and the kinds built on it: nearest first, dead ones last)",
    "bullet": "other tanks' bullets, nearest first",
    "wall": "the map's merged wall rectangles",
    "buff": "buff zones", "debuff": "debuff zones",
    "zone": "where I stand",
    "ray": "wall distance along evenly spaced directions: ray 0 straight ahead, then clockwise",
    "shot": "a bullet fired now along my heading (0 while I am dead)",
    "threat": "the other tanks' bullet that will pass closest to me within 1 s (straight "
              "lines; all 0 if none)",
    "advice": "what the smart bot would do now in my seat (0 while I am dead)",
}
DEFAULT_RAYS = 16
DEFAULT_RAY_LENGTH = 350.0  # px: five cells of the default map


@dataclass
class ObsLayout:
    """Index map of an observation vector: ``index[name]`` is a slice.

    Scalar features are named ``block.field`` (``self.x``) or ``block[k].field``
    (``tank[0].rel_x``, ``ray[3].dist``); whole blocks by their name (``self``,
    ``tank[0]``, ``tank``, ``bullet``). ``layout["self.x"]`` returns the slice.
    ``slot_fields[block]`` lists the fields of one slot; :meth:`column` and :meth:`span`
    give their positions within a slot (what the builder writes through).
    """

    kind: str
    size: int = 0
    index: dict[str, slice] = field(default_factory=dict)
    fields: list[str] = field(default_factory=list)  # scalar names in vector order
    widths: dict[str, int] = field(default_factory=dict)  # block -> floats per slot
    slots: dict[str, int | None] = field(default_factory=dict)  # block -> slots (None: single)
    slot_fields: dict[str, tuple[str, ...]] = field(default_factory=dict)  # block -> field names

    def __getitem__(self, name: str) -> slice:
        try:
            return self.index[name]
        except KeyError:
            raise KeyError(f"no observation feature {name!r} in the {self.kind} layout; "
                           f"blocks: {self.blocks()}") from None

    def __contains__(self, name: str) -> bool:
        return name in self.index

    def blocks(self) -> list[str]:
        return [k for k in self.index if "." not in k and "[" not in k]

    def add(self, block: str, count: int | None, names: Sequence[str]) -> slice:
        """Append a block of ``count`` slots (None: a single unnumbered slot)."""
        start = self.size
        self.widths[block] = len(names)
        self.slots[block] = count
        self.slot_fields[block] = tuple(names)
        for k in [None] if count is None else range(count):
            head = block if k is None else f"{block}[{k}]"
            s0 = self.size
            for name in names:
                self.index[f"{head}.{name}"] = slice(self.size, self.size + 1)
                self.fields.append(f"{head}.{name}")
                self.size += 1
            if k is not None:
                self.index[head] = slice(s0, self.size)
        self.index[block] = slice(start, self.size)
        return self.index[block]

    def column(self, block: str, name: str) -> int:
        """Position of field ``name`` within one slot of ``block``."""
        names = self.slot_fields.get(block)
        if names is None or name not in names:
            raise KeyError(f"no field {name!r} in block {block!r} of the {self.kind} layout; "
                           f"its fields: {list(names or ())}")
        return names.index(name)

    def span(self, block: str, *names: str) -> slice:
        """Positions of the adjacent fields ``names`` (in this order) within one slot of
        ``block``, as a slice (a writable view in numpy)."""
        first = self.column(block, names[0])
        got = [self.column(block, n) for n in names]
        if got != list(range(first, first + len(names))):
            raise ValueError(f"fields {list(names)} of block {block!r} are not adjacent in "
                             f"this order in the {self.kind} layout: "
                             f"{list(self.slot_fields[block])}")
        return slice(first, first + len(names))

    def describe(self) -> str:
        """Human-readable table of blocks and the fields of one slot."""
        lines = [f"{self.kind} observation: {self.size} floats"]
        for b in self.blocks():
            sl = self.index[b]
            lines.append(f"  {b:12s} [{sl.start:4d}:{sl.stop:4d}]  "
                         f"{', '.join(self.slot_fields[b])}")
        return "\n".join(lines)

    def markdown(self, notes: Mapping[str, str] | None = None) -> str:
        """The layout as a Markdown table: block, slots, floats, index range, fields of a
        slot (and a ``notes[block]`` column when ``notes`` is given)."""
        head = ["block", "slots", "floats", "index"] + (["what"] if notes else []) + ["fields"]
        rows = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
        for b in self.blocks():
            sl, count = self.index[b], self.slots[b]
            cells = [f"`{b}`" if count is None else f"`{b}[k]`",
                     str(1 if count is None else count), str(sl.stop - sl.start),
                     f"{sl.start}:{sl.stop}"]
            cells += [notes.get(b, "")] if notes else []
            cells.append(", ".join(self.slot_fields[b]))
            rows.append("| " + " | ".join(cells) + " |")
        return "\n".join(rows)


class StateBatch:
    """Arrays of ``num_envs`` matches of one scenario, filled once per step by
    :meth:`gather` (dynamic state) and once per episode by :meth:`set_static`."""

    def __init__(self, cfg: GameConfig, n: int, num_envs: int, max_walls: int,
                 max_buffs: int, max_debuffs: int):
        self._args = (cfg, n, num_envs, max_walls, max_buffs, max_debuffs)
        self.cfg, self.n, self.num_envs = cfg, n, num_envs
        cap = cfg.bullet_capacity
        nb = n * cap
        self.capacity, self.n_bullets = cap, nb
        E = num_envs
        self.raw = np.zeros((E, 2 * n + nb, 6))  # copy of world.state
        self.tank_xy = self.raw[:, :n, 0:2]
        self.tank_angle = self.raw[:, :n, 2]
        self.tank_vel = self.raw[:, :n, 3:5]
        self.bullet_xy = self.raw[:, n:n + nb, 0:2]
        self.bullet_vel = self.raw[:, n:n + nb, 3:5]
        self.flags = np.zeros((E, 4, n), dtype=bool)
        self.alive, self.wall, self.in_buff, self.in_debuff = (self.flags[:, k] for k in range(4))
        self.bullet_active = np.zeros((E, nb), dtype=bool)
        self.counts = np.zeros((E, 2, n), dtype=np.int64)
        self.cooldown, self.bullets_alive = self.counts[:, 0], self.counts[:, 1]
        self.tick = np.zeros(E, dtype=np.int64)
        # Per tank, SHOT_FIELDS of a bullet fired now; only the seats of want_shots(),
        # from their predicted paths (complex points, padded with the end point) and
        # lengths (0: dead), traced in gather() and reached for all envs in reach_shots().
        self.shots = np.zeros((E, n, len(SHOT_FIELDS)))
        # ... and of the same shots: the first tank each reaches (-1: none, or not
        # traced) and its closest approach to every tank (inf: itself, dead, not traced).
        self.shot_first = np.full((E, n), -1, dtype=np.int64)
        self.shot_pass = np.full((E, n, n), np.inf)
        self.shot_seats: tuple[int, ...] = ()
        self._shot_radius = hit_radius(cfg)
        self._paths = np.zeros((E, n, cfg.bullet_max_bounces + 2), dtype=np.complex128)
        self._path_len = np.zeros((E, n), dtype=np.int64)
        self._shots_due = False
        self._tank_z = np.zeros((E, n), dtype=np.complex128)
        # Per tank, the advice block (ADVICE_FIELDS) of the seats of want_advice(): one
        # advisor bot per env and seat (reset with the statics), asked in reach_advice()
        # for the envs gathered since the last call.
        self.advice = np.zeros((E, n, len(ADVICE_FIELDS)))
        self.advice_seats: tuple[int, ...] = ()
        self._advisors: list[dict[int, Policy]] = [{} for _ in range(E)]
        self._matches: list[Match | None] = [None] * E
        self._advice_due = np.zeros(E, dtype=bool)
        self.team = np.zeros((E, n), dtype=np.int64)  # team index of every seat
        # Per-episode statics.
        self.size = np.ones((E, 2))  # map width, height (px)
        self.walls = np.zeros((E, max_walls, 4))  # x0, y0, x1, y1 (px)
        self.wall_mask = np.zeros((E, max_walls), dtype=bool)
        self.ray_rects = np.zeros((E, max_walls + 4, 4))  # walls + outer boundary
        self.zones = np.zeros((E, max_buffs + max_debuffs, 2))  # buff centres, then debuff
        self.zone_mask = np.zeros((E, max_buffs + max_debuffs), dtype=bool)
        self.max_buffs, self.max_debuffs = max_buffs, max_debuffs
        # Normalisation constants of each env's map (set with the statics).
        self.inv = np.ones((E, 1, 2))  # 2 / (W, H): positions -> [-1, 1]
        self.scale = np.ones((E, 1, 1))  # 1 / max(W, H): relative positions
        self.idiag = np.ones((E, 1, 1))  # 1 / diagonal: distances
        self.corner_u = np.zeros((E, 1, 4, 2))  # normalised corner offsets (times cos)
        self.corner_v = np.zeros((E, 1, 4, 2))  # (times sin)
        self.specs: list[MapSpec | None] = [None] * E  # each env's map this episode

    def __reduce__(self) -> tuple:
        """Pickle as a fresh batch (views into ``raw`` must stay views; contents are
        refilled at the next reset)."""
        return (type(self), self._args)

    def gather(self, e: int, match: Match) -> None:
        """Copy match ``e``'s dynamic arrays (one batch read already done by the world)."""
        w = match.world
        self.raw[e] = w.state
        self.flags[e] = match.flags  # alive, wall, in_buff, in_debuff
        self.bullet_active[e] = w.bullet_active
        self.counts[e] = match.counts  # cooldown, bullets_alive
        self.tick[e] = match.tick
        if self.shot_seats:
            self.trace_shots(e, match)
        if self.advice_seats:
            self._matches[e] = match
            self._advice_due[e] = True

    def want_advice(self, seats: Sequence[int]) -> None:
        """Ask an advisor bot (``ADVICE_BOT``) what it would do in these seats
        (``advice``); takes effect from the next :meth:`set_static` of each env."""
        self.advice_seats = tuple(sorted(set(self.advice_seats) | {int(s) for s in seats}))

    def reach_advice(self) -> None:
        """Fill ``advice`` of every env gathered since the last call: each wanted live
        seat's advisor acts on the match (its per-episode memory moves on, as a bot's
        does when it plays); dead seats get zeros."""
        adv = self.advice
        for e in np.flatnonzero(self._advice_due).tolist():
            match = self._matches[e]
            advisors = self._advisors[e]
            for s in self.advice_seats:
                row = adv[e, s]
                row.fill(0.0)
                if match.alive[s]:
                    rot, move, fire = advisors[s].act(match, s).tolist()
                    row[rot] = row[3 + move] = 1.0
                    row[6] = fire
            self._matches[e] = None  # keep no match alive (gather sets it again)
        self._advice_due.fill(False)

    def want_shots(self, seats: Sequence[int]) -> None:
        """Predict a shot of these seats in every :meth:`gather` (``shots``)."""
        self.shot_seats = tuple(sorted(set(self.shot_seats) | {int(s) for s in seats}))

    def trace_shots(self, e: int, match: Match) -> None:
        """Trace a bullet fired now along the heading of each wanted live seat of match
        ``e``, like the bots' search (``predict_points(exact=False)``)."""
        w, alive = match.world, match.alive
        for s in self.shot_seats:
            if not alive[s]:
                self._path_len[e, s] = 0
                continue
            mx, my = w.muzzle(s)
            points = predict_points(w, mx, my, float(match.tank_angle[s]), exact=False)
            row = self._paths[e, s]
            for k, (px, py) in enumerate(points):
                row[k] = complex(px, py)
            row[len(points):] = complex(px, py)
            self._path_len[e, s] = len(points)
        self._shots_due = True

    def reach_shots(self) -> None:
        """Fill ``shots`` of every env from the paths traced since the last call, against
        the live tanks: the first tank each path reaches (as
        :func:`alphatank.sim.ballistics.path_hits`) and its closest approach to an enemy
        (as :func:`alphatank.sim.ballistics.path_distances`); every leg's distances in
        numpy, the rest compiled (:func:`~alphatank.game.kernels.shot_reach`)."""
        if not self._shots_due:
            return
        self._shots_due = False
        seats = np.asarray(self.shot_seats)
        length = self._path_len[:, seats]  # (E, S)
        P = int(length.max())
        if P == 0:
            self.shots[:, seats] = 0.0
            self.shot_first[:, seats] = -1
            self.shot_pass[:, seats] = np.inf
            return
        w = self._tank_z
        w.real, w.imag = self.tank_xy[..., 0], self.tank_xy[..., 1]
        dist, t, d = segment_distances(self._paths[:, seats, :P], w[:, None, :])  # (E, S, P-1, n)
        shot_reach(dist, t, np.abs(d[..., 0]), self.alive, seats, length, self.team,
                   self._shot_radius, self.cfg.bullet_max_distance, self.shot_first,
                   self.shot_pass, self.shots)

    def set_static(self, e: int, match: Match) -> None:
        """Map size, wall rectangles and zone centres of match ``e``'s episode."""
        spec = match.spec
        g = self.cfg
        self.specs[e] = spec
        for s in self.advice_seats:
            advisor = self._advisors[e].get(s)
            if advisor is None:
                advisor = make_controller(Seat(match.teams[s], "bot", bot=ADVICE_BOT), 0)
                self._advisors[e][s] = advisor
            advisor.reset(match, s, 0)  # the smart bot draws no random numbers
        self.team[e] = match.team_index
        self.size[e] = (spec.width, spec.height)
        inv = 2.0 / self.size[e]
        self.inv[e, 0] = inv
        self.scale[e] = 1.0 / max(spec.width, spec.height)
        self.idiag[e] = 1.0 / math.hypot(spec.width, spec.height)
        dx, dy = CORNERS[:, 0] * (g.tank_width / 2), CORNERS[:, 1] * (g.tank_height / 2)
        self.corner_u[e, 0] = np.stack([dx * inv[0], dy * inv[1]], axis=1)
        self.corner_v[e, 0] = np.stack([-dy * inv[0], dx * inv[1]], axis=1)
        rects = np.asarray(spec.wall_rects, dtype=np.float64).reshape(-1, 4)
        k = len(rects)
        self.walls[e] = 0.0
        self.walls[e, :k] = rects
        self.wall_mask[e] = False
        self.wall_mask[e, :k] = True
        t, W, H = spec.cell, spec.width, spec.height
        boundary = np.array([(-t, -t, W + t, 0.0), (-t, H, W + t, H + t), (-t, 0.0, 0.0, H),
                             (W, 0.0, W + t, H)])
        # Unused ray slots repeat rectangles (a duplicate changes no minimum).
        self.ray_rects[e] = np.resize(np.concatenate([rects, boundary]),
                                      self.ray_rects[e].shape)
        self.zones[e] = 0.0
        self.zone_mask[e] = False
        for j, cells in ((0, match.buffs), (self.max_buffs, match.debuffs)):
            for i, cell in enumerate(cells):
                self.zones[e, j + i] = spec.cell_center(cell)
                self.zone_mask[e, j + i] = True


def slot_counts(cfg: GameConfig, specs: Sequence[MapSpec]) -> tuple[int, int, int]:
    """Most walls, buff and debuff zones over a scenario's maps (fixed padded sizes)."""
    walls = max(len(s.wall_rects) for s in specs)
    buffs = max(cfg.random_buff_zones if s.random_zones else len(s.buffs) for s in specs)
    debuffs = max(cfg.random_debuff_zones if s.random_zones else len(s.debuffs) for s in specs)
    return walls, buffs, debuffs


def room_misfit(kind: str, room: Sequence[int], need: Sequence[int], maps: str) -> list[str]:
    """Why maps needing ``need`` (wall rectangles, buff and debuff zones; ``maps`` names
    them: "map 'maze' has", "its maps have up to") overflow an observation of ``kind``
    padded to ``room``; empty when they fit. Only the 'paper' kind has a wall block: the
    others read any map's walls through rays and routes."""
    walls, buffs, debuffs = (int(v) for v in room)
    n_walls, n_buffs, n_debuffs = need
    why = []
    if kind == "paper" and n_walls > walls:
        why.append(f"{maps} {n_walls} wall rectangles; its 'paper' observation has room "
                   f"for {walls}")
    if n_buffs > buffs or n_debuffs > debuffs:
        why.append(f"{maps} {n_buffs} buff and {n_debuffs} debuff zones; it has room for "
                   f"{buffs} and {debuffs}")
    return why


class ObservationBuilder:
    """Builds the observations of ``observers`` (seat indices) in every match of a
    :class:`StateBatch`: ``build()`` returns the internal (E, L, obs_dim) float32 buffer."""

    def __init__(self, kind: str, batch: StateBatch, teams: Sequence[str],
                 observers: Sequence[int], team_flags: bool | None = None,
                 rays: int = DEFAULT_RAYS, ray_length: float = DEFAULT_RAY_LENGTH):
        if kind not in OBS_KINDS:
            raise ValueError(f"unknown observation kind {kind!r}; valid: {list(OBS_KINDS)}")
        n = len(teams)
        if batch.n != n:
            raise ValueError(f"batch has {batch.n} tanks, teams name {n}")
        bad = [o for o in observers if not 0 <= o < n]
        if bad:
            raise ValueError(f"observer seats {bad} out of range 0..{n - 1}")
        if rays < 1 or not ray_length > 0:
            raise ValueError(f"rays must be >= 1 and ray_length > 0, got {rays}, {ray_length}")
        self._args = (kind, batch, teams, observers, team_flags, rays, ray_length)
        self.kind, self.batch, self.cfg = kind, batch, batch.cfg
        self.teams = list(teams)
        self.team_flags = (len(set(teams)) < n) if team_flags is None else team_flags
        self.observers = np.asarray(observers, dtype=np.int64)
        self.rays, self.ray_length = rays, float(ray_length)
        E, L, cap = batch.num_envs, len(observers), batch.capacity
        n_oth = n - 1
        K = n_oth * cap
        self.n_others, self.n_other_bullets = n_oth, K
        team = np.array([self.teams.index(t) for t in self.teams])
        # Other tanks per observer: teammates first, then enemies, each in seat order.
        others = []
        for o in self.observers:
            mates = [j for j in range(n) if j != o and team[j] == team[o]]
            foes = [j for j in range(n) if team[j] != team[o]]
            others.append(mates + foes)
        self.other_idx = np.array(others, dtype=np.int64).reshape(L, n_oth)
        self.other_team = (team[self.other_idx] == team[self.observers][:, None]).astype(
            np.float64)
        # egocentric_nearest sort keys: enemies after teammates, dead after the living
        # (distances are below 1e9 px: maps are at most a few thousand)
        self._group_key = np.where(self.other_team > 0, 0.0, 2e9)
        self._dead_key = 1e9
        self.own_bidx = self.observers[:, None] * cap + np.arange(cap)  # (L, cap)
        self.other_bidx = (self.other_idx[:, :, None] * cap + np.arange(cap)).reshape(L, K)
        self.other_bteam = np.repeat(self.other_team, cap, axis=1)  # (L, K)
        self.layout = self._make_layout(n_oth, K, cap, batch)
        self.at = self._columns()
        self.out = np.zeros((E, L, self.layout.size), dtype=np.float32)
        self._views()
        self._ge = np.arange(E)[:, None, None]
        self._gl = np.arange(L)[None, :, None]
        self._tt = np.zeros((E, n, len(TANK_FIELDS)))
        self._bt = np.zeros((E, batch.n_bullets, len(BULLET_FIELDS)))
        self._count_scale = np.array([1.0 / self.cfg.cooldown_ticks, 1.0 / max(cap, 1)])
        self._ray_angles = np.arange(rays) * (2 * math.pi / rays)
        self._ray_out: np.ndarray | None = None  # ray_distances' output
        # Reads of other tanks' bullets: a view when the seat pattern allows (a 1v1),
        # else fancy indexing each step.
        self._other_act = pick(batch.bullet_active, self.other_bidx)  # (E, L, K)
        self._bullets_zero = False  # the other-bullet block is all zeros already
        # egocentric_path: each env's NavGrid, and the envs grouped by grid (one group
        # when every env plays the same map), set with the statics.
        self._nav: list[NavGrid | None] = [None] * E
        self._nav_groups: list[tuple[NavGrid, np.ndarray]] = []
        if kind in PATH_KINDS:  # the tank.path_* columns of v_tank, for path_features
            self._path_cols = np.array([self.at[f"tank.{f}"]
                                        for f in ("path_fwd", "path_side", "path_dist")])
        if kind == "paper":
            self._paper_plan()

    def __reduce__(self) -> tuple:
        return (type(self), self._args)

    # ---- layout ---------------------------------------------------------------------

    def _make_layout(self, n_oth: int, K: int, cap: int, batch: StateBatch) -> ObsLayout:
        t = ("team",) if self.team_flags else ()
        lay = ObsLayout(self.kind)
        B, Dz = batch.max_buffs, batch.max_debuffs
        if self.kind == "paper":
            lay.add("self", None, TANK_FIELDS + ("reload", "bullets"))
            lay.add("own_bullet", cap, ("mask",) + BULLET_FIELDS)
            lay.add("tank", n_oth, t + TANK_FIELDS + ("rel_x", "rel_y", "dist"))
            lay.add("bullet", K, ("mask",) + t + BULLET_FIELDS + ("rel_x", "rel_y", "dist"))
            lay.add("wall", batch.walls.shape[1], ("mask", "x0", "y0", "x1", "y1"))
            lay.add("buff", B, ("mask", "x", "y"))
            lay.add("debuff", Dz, ("mask", "x", "y"))
            lay.add("zone", None, ("in_buff", "in_debuff"))
        else:
            lay.add("self", None, ("alive", "sin", "cos", "v_fwd", "v_side", "wall", "reload",
                                   "bullets", "in_buff", "in_debuff"))
            lay.add("ray", self.rays, ("dist",))
            path = ("path_fwd", "path_side", "path_dist") if self.kind in PATH_KINDS else ()
            fire = FIRE_FIELDS if self.kind in FIRE_KINDS else ()
            lay.add("tank", n_oth, t + ("alive", "fwd", "side", "dist", "sin", "cos", "v_fwd",
                                        "v_side", "wall") + path + fire)
            lay.add("own_bullet", cap, ("mask", "fwd", "side", "v_fwd", "v_side", "dist"))
            lay.add("bullet", K, ("mask",) + t + ("fwd", "side", "v_fwd", "v_side", "dist"))
            lay.add("buff", B, ("mask", "fwd", "side", "dist"))
            lay.add("debuff", Dz, ("mask", "fwd", "side", "dist"))
            if self.kind in SHOT_KINDS:
                lay.add("shot", None, SHOT_FIELDS)
            if self.kind in THREAT_KINDS:
                lay.add("threat", None, THREAT_FIELDS)
            if self.kind in ADVICE_KINDS:
                lay.add("advice", None, ADVICE_FIELDS)
        return lay

    def _columns(self) -> dict[str, int | slice]:
        """Where the builder writes, resolved once from the layout by feature name:
        ``"block.field"`` -> column within a slot of the block (an int), ``"block.a:b"``
        -> the adjacent fields a..b (a slice, so numpy writes through a view)."""
        lay = self.layout
        at: dict[str, int | slice] = {}

        def cols(block: str, *names: str, span: tuple[str, ...] = ()) -> None:
            for name in names:
                at[f"{block}.{name}"] = lay.column(block, name)
            if span:
                at[f"{block}.{span[0]}:{span[-1]}"] = lay.span(block, *span)

        counts = ("reload", "bullets")
        if self.team_flags:
            cols("tank", "team")
            cols("bullet", "team")
        cols("bullet", "mask")
        cols("own_bullet", "mask")
        cols("buff", "mask")
        cols("debuff", "mask")
        if self.kind == "paper":
            cols("self", span=TANK_FIELDS)
            cols("self", span=counts)
            cols("tank", "dist", span=TANK_FIELDS)
            cols("tank", span=("rel_x", "rel_y"))
            cols("own_bullet", span=BULLET_FIELDS)
            cols("bullet", "dist", span=BULLET_FIELDS)
            cols("bullet", span=("rel_x", "rel_y"))
            cols("wall", "mask", span=("x0", "y0"))
            cols("wall", span=("x1", "y1"))
            cols("buff", span=("x", "y"))
            cols("debuff", span=("x", "y"))
            cols("zone", "in_buff", "in_debuff")
        else:
            cols("self", "alive", "sin", "cos", "v_fwd", "v_side", "wall", "in_buff",
                 "in_debuff", span=counts)
            cols("tank", "alive", "sin", "cos", "wall")
            if self.kind in PATH_KINDS:
                cols("tank", "path_fwd", "path_side", "path_dist")
            if self.kind in FIRE_KINDS:
                cols("tank", *FIRE_FIELDS)
        return at

    def _block(self, name: str, count: int) -> np.ndarray:
        """(E, L, count, fields) view of a numbered block of the output buffer."""
        E, L, _ = self.out.shape
        return self.out[:, :, self.layout[name]].reshape(E, L, count, self.layout.widths[name])

    def _views(self) -> None:
        lay, cap = self.layout, self.batch.capacity
        self.v_self = self.out[:, :, lay["self"]]
        self.v_own = self._block("own_bullet", cap)
        self.v_tank = self._block("tank", self.n_others)
        self.v_bullet = self._block("bullet", self.n_other_bullets)
        self.v_buff = self._block("buff", self.batch.max_buffs)
        self.v_debuff = self._block("debuff", self.batch.max_debuffs)
        if self.team_flags:
            self.v_tank[..., self.at["tank.team"]] = self.other_team
        if self.kind == "paper":
            self.v_wall = self._block("wall", self.batch.walls.shape[1])
        else:
            self.v_ray = self.out[:, :, lay["ray"]]
            self._ego_tables()
        if self.kind in THREAT_KINDS:
            self.v_threat = self.out[:, :, lay["threat"]]
        if self.kind in SHOT_KINDS:
            self.v_shot = self.out[:, :, lay["shot"]]
            self.batch.want_shots(self.observers.tolist())
            self._shot_src = pick(self.batch.shots, self.observers[:, None])  # (E, L, 1, 3)
        if self.kind in FIRE_KINDS:
            self.batch.want_shots(np.unique(self.other_idx).tolist())
        if self.kind in ADVICE_KINDS:
            self.v_advice = self.out[:, :, lay["advice"]]
            self.batch.want_advice(self.observers.tolist())
            self._advice_src = pick(self.batch.advice, self.observers[:, None])  # (E, L, 1, 7)

    # ---- statics --------------------------------------------------------------------

    def set_static(self, e: int) -> None:
        """Write the per-episode blocks of env ``e`` (walls, zone positions in ``paper``;
        the map's navigation grid in ``PATH_KINDS``)."""
        if self.kind in PATH_KINDS:
            self._set_nav(e)
        if self.kind != "paper":
            return
        b, at = self.batch, self.at
        self._corner_vu[e, 0, 0] = b.corner_v[e, 0]
        self._corner_vu[e, 0, 1] = b.corner_u[e, 0]
        inv = b.inv[e, 0]
        m = b.wall_mask[e][:, None]
        vw = self.v_wall[e]
        vw[..., at["wall.mask"]] = b.wall_mask[e]
        vw[..., at["wall.x0:y0"]] = (b.walls[e, :, 0:2] * inv - 1) * m
        vw[..., at["wall.x1:y1"]] = (b.walls[e, :, 2:4] * inv - 1) * m
        zones = (b.zones[e] * inv - 1) * b.zone_mask[e][:, None]
        nbf = b.max_buffs
        self.v_buff[e, ..., at["buff.mask"]] = b.zone_mask[e, :nbf]
        self.v_buff[e, ..., at["buff.x:y"]] = zones[:nbf]
        self.v_debuff[e, ..., at["debuff.mask"]] = b.zone_mask[e, nbf:]
        self.v_debuff[e, ..., at["debuff.x:y"]] = zones[nbf:]

    def _set_nav(self, e: int) -> None:
        spec = self.batch.specs[e]
        if spec is None:
            raise ValueError(f"env {e} has no map yet: call StateBatch.set_static first")
        self._nav[e] = nav_grid(spec)
        groups: dict[int, tuple[NavGrid, list[int]]] = {}
        for i, grid in enumerate(self._nav):
            if grid is not None:
                groups.setdefault(id(grid), (grid, []))[1].append(i)
        self._nav_groups = [(grid, np.array(envs, dtype=np.int64))
                            for grid, envs in groups.values()]

    # ---- per step -------------------------------------------------------------------

    def build(self) -> np.ndarray:
        """Observations of all envs and observers from the batch's current state."""
        if self.kind == "paper":
            self._build_paper()  # clipped by its kernel
            return self.out
        self._build_ego()
        if self.kind in NEAREST_KINDS and self.n_others > 1:
            self._order_nearest()
        if self.kind in SHOT_KINDS:
            self.batch.reach_shots()
            src = self._shot_src
            self.v_shot[...] = (self.batch.shots[:, self.observers] if src is None
                                else src[:, :, 0])
        if self.kind in ADVICE_KINDS:
            self.batch.reach_advice()
            src = self._advice_src
            self.v_advice[...] = (self.batch.advice[:, self.observers] if src is None
                                  else src[:, :, 0])
        out = self.out
        np.minimum(out, ONE32, out=out)
        np.maximum(out, MINUS_ONE32, out=out)
        # A masked-out feature is 0 times a stale value, -0.0 when that value was negative:
        # +0.0 always, so an observation's bits hang on the state alone.
        np.add(out, ZERO32, out=out)
        return out

    def _paper_plan(self) -> None:
        """Arguments of the ``paper`` kind's kernel
        (:func:`~alphatank.game.kernels.paper_observation`): every feature an observation
        copies unchanged (own tank, other tanks' table fields, own bullets, zone flags) is
        computed once per tank or bullet slot into one float64 source row per env, then
        copied to all observers through precomputed flat indices."""
        b, lay, at = self.batch, self.layout, self.at
        E, L, D = self.out.shape
        n, nb = b.n, b.n_bullets
        parts = {"P": 4 * (n + nb), "T": 10 * n, "F": 4 * n, "C": 2 * n, "A": nb}
        start, S = {}, 0
        for k, size in parts.items():
            start[k] = S
            S += size
        self._src = np.zeros((E, S))
        self._v_scale = np.r_[np.full(n, 1.0 / self.cfg.tank_speed),
                              np.full(nb, 1.0 / self.cfg.bullet_speed)][:, None]
        self._corner_vu = np.zeros((E, 1, 2, 4, 2))  # corner_v, corner_u (set_static)
        table = ("x", "y", "vx", "vy")

        def tank_src(j: int, field: str) -> int:
            if field in ("alive", "wall"):
                return start["F"] + ("alive", "wall").index(field) * n + j
            if field in table:
                return start["P"] + 4 * j + table.index(field)
            return start["T"] + 10 * j + TANK_COLS.index(field)

        pairs: list[tuple[int, int]] = []  # (column in one env's L*D block, src column)
        for li, o in enumerate(self.observers):
            base = li * D

            def put(name: str, src_col: int, base: int = base) -> None:
                pairs.append((base + lay[name].start, src_col))

            for f in TANK_FIELDS:
                put(f"self.{f}", tank_src(o, f))
            put("self.reload", start["C"] + 2 * o)
            put("self.bullets", start["C"] + 2 * o + 1)
            for k, j in enumerate(self.other_idx[li]):
                for f in TANK_FIELDS:
                    put(f"tank[{k}].{f}", tank_src(j, f))
            for k, slot in enumerate(self.own_bidx[li]):
                put(f"own_bullet[{k}].mask", start["A"] + slot)
                for c, f in enumerate(BULLET_FIELDS):
                    put(f"own_bullet[{k}].{f}", start["P"] + 4 * (n + slot) + c)
            put("zone.in_buff", start["F"] + 2 * n + o)
            put("zone.in_debuff", start["F"] + 3 * n + o)
        dst, col = np.array(pairs, dtype=np.intp).reshape(-1, 2).T
        envs = np.arange(E, dtype=np.intp)[:, None]
        self._take = (envs * S + col).reshape(-1)
        self._put = (envs * (L * D) + dst).reshape(-1)
        team = at["bullet.team"] if self.team_flags else -1
        self._tank_cols = np.array([lay["tank"].start, lay.widths["tank"],
                                    at["tank.rel_x:rel_y"].start, at["tank.dist"]])
        self._bullet_cols = np.array([lay["bullet"].start, lay.widths["bullet"],
                                      at["bullet.mask"], team, at["bullet.x:vy"].start,
                                      at["bullet.rel_x:rel_y"].start, at["bullet.dist"]])

    def _self_counts(self, out: np.ndarray) -> None:
        """reload (cooldown / cooldown ticks) and bullets (in flight / capacity)."""
        counts = self.batch.counts[:, :, self.observers]  # (E, 2, L)
        np.multiply(counts.transpose(0, 2, 1), self._count_scale, out=out)

    def _other_bullets(self, xy: np.ndarray) -> bool:
        """Other tanks' bullets nearest first, from ``self._seg``'s second end on in
        ``_relv``, ``_velv`` and the masks, and the ``bullet`` block's mask and team
        columns (:func:`~alphatank.game.kernels.nearest_bullets`); ``xy`` (E, L, 2): the
        observers. False (and the block zeroed) when no other bullet flies anywhere in
        the batch."""
        b, bidx = self.batch, self.other_bidx
        act = self._other_act
        act = b.bullet_active[:, bidx] if act is None else act
        if not np.count_nonzero(act):
            if not self._bullets_zero:
                self.v_bullet[...] = 0.0
                self._bullets_zero = True
            return False
        self._bullets_zero = False
        at = self.at
        nearest_bullets(b.bullet_xy, b.bullet_vel, b.bullet_active, bidx, self.other_bteam, xy,
                        self._seg[1], self._relv, self._velv, self._rmask, self._vmask,
                        self.v_bullet, at["bullet.mask"],
                        at["bullet.team"] if self.team_flags else -1)
        return True

    def _build_paper(self) -> None:
        """The ``paper`` kind, clipped (see :meth:`_paper_plan`); the same values as
        :func:`tank_table` / :func:`bullet_table` with the same operations."""
        b = self.batch
        paper_observation(b.raw, b.n, b.inv, b.scale, b.idiag, self._v_scale,
                          self._corner_vu, b.flags, b.counts, self._count_scale,
                          b.bullet_active, self._src, self._take, self._put, self.observers,
                          self.other_idx, self.other_bidx, self.other_bteam,
                          self._tank_cols, self._bullet_cols, self.out)

    def _ego_tables(self) -> None:
        """Column maps of the egocentric kind: every relative position (other tanks, own
        bullets, other bullets, zones) and every velocity (tanks, own and other bullets)
        is rotated in one batch, then scattered to its ``fwd``/``side``/``dist`` slots."""
        lay = self.layout
        no, cap, K = self.n_others, self.batch.capacity, self.n_other_bullets
        B, Dz = self.batch.max_buffs, self.batch.max_debuffs
        rel = ([f"tank[{j}]" for j in range(no)] + [f"own_bullet[{k}]" for k in range(cap)]
               + [f"bullet[{k}]" for k in range(K)] + [f"buff[{k}]" for k in range(B)]
               + [f"debuff[{k}]" for k in range(Dz)])
        vel = rel[:no + cap + K]

        def col(names: list[str], f: str) -> np.ndarray:
            return np.array([lay[f"{n}.{f}"].start for n in names], dtype=np.int64)

        self._rel_cols = (col(rel, "fwd"), col(rel, "side"), col(rel, "dist"))
        self._vel_cols = (col(vel, "v_fwd"), col(vel, "v_side"))
        E, L = self.out.shape[:2]
        self._relv = np.zeros((E, L, len(rel), 2))
        self._velv = np.zeros((E, L, len(vel), 2))
        self._rmask = np.ones((E, L, len(rel)))
        self._vmask = np.ones((E, L, len(vel)))
        g = self.cfg
        self._vscale = np.r_[np.full(no, 1.0 / g.tank_speed),
                             np.full(cap + K, 1.0 / g.bullet_speed)]
        self._seg = (no, no + cap, no + cap + K)  # ends of the tank / own / other-bullet groups
        self._near_key = np.zeros((E, L, no))  # egocentric_nearest sort keys
        self._hit_radius = hit_radius(g)

    def _build_ego(self) -> None:
        b, g, at = self.batch, self.cfg, self.at
        obs, oi = self.observers, self.other_idx
        ang = b.tank_angle
        sin, cos = np.sin(ang), np.cos(ang)
        s, c = sin[:, obs], cos[:, obs]  # (E, L)
        vs = self.v_self
        vs[..., at["self.alive"]] = b.alive[:, obs]
        vs[..., at["self.sin"]] = s
        vs[..., at["self.cos"]] = c
        v = b.tank_vel[:, obs] * (1.0 / g.tank_speed)  # (E, L, 2)
        vs[..., at["self.v_fwd"]] = v[..., 0] * c + v[..., 1] * s
        vs[..., at["self.v_side"]] = v[..., 1] * c - v[..., 0] * s
        vs[..., at["self.wall"]] = b.wall[:, obs]
        self._self_counts(vs[..., at["self.reload:bullets"]])
        vs[..., at["self.in_buff"]] = b.in_buff[:, obs]
        vs[..., at["self.in_debuff"]] = b.in_debuff[:, obs]
        xy = b.tank_xy[:, obs]
        self_xy = xy[:, :, None, :]
        self.v_ray[...] = self.ray_distances(xy, ang[:, obs]) / self.ray_length
        # Other tanks: scalars.
        vt = self.v_tank
        vt[..., at["tank.alive"]] = b.alive[:, oi]
        so, co = sin[:, oi], cos[:, oi]
        s3, c3 = s[..., None], c[..., None]
        vt[..., at["tank.sin"]] = so * c3 - co * s3  # sin(their heading - mine)
        vt[..., at["tank.cos"]] = co * c3 + so * s3
        vt[..., at["tank.wall"]] = b.wall[:, oi]
        # Every relative position and velocity, then one rotation.
        o, oc, ock = self._seg
        relv, velv, rm, vm = self._relv, self._velv, self._rmask, self._vmask
        np.subtract(b.tank_xy[:, oi], self_xy, out=relv[:, :, :o])
        np.subtract(b.bullet_xy[:, self.own_bidx], self_xy, out=relv[:, :, o:oc])
        np.subtract(b.zones[:, None], self_xy, out=relv[:, :, ock:])
        velv[:, :, :o] = b.tank_vel[:, oi]
        velv[:, :, o:oc] = b.bullet_vel[:, self.own_bidx]
        act = b.bullet_active[:, self.own_bidx]
        rm[:, :, o:oc] = act
        vm[:, :, o:oc] = act
        rm[:, :, ock:] = b.zone_mask[:, None, :]
        flying = self._other_bullets(xy)
        if not flying:
            rm[:, :, oc:ock] = 0.0
            vm[:, :, oc:ock] = 0.0
        if self.kind in THREAT_KINDS:
            self._build_threat((relv[:, :, oc:ock], velv[:, :, oc:ock], rm[:, :, oc:ock])
                               if flying else None, c3, s3)
        out = self.out
        fc, sc_, dc = self._rel_cols
        k = rm * b.scale
        out[..., fc] = (relv[..., 0] * c3 + relv[..., 1] * s3) * k
        out[..., sc_] = (relv[..., 1] * c3 - relv[..., 0] * s3) * k
        out[..., dc] = np.hypot(relv[..., 0], relv[..., 1]) * (rm * b.idiag)
        vf, vsd = self._vel_cols
        k = vm * self._vscale
        out[..., vf] = (velv[..., 0] * c3 + velv[..., 1] * s3) * k
        out[..., vsd] = (velv[..., 1] * c3 - velv[..., 0] * s3) * k
        self.v_own[..., at["own_bullet.mask"]] = act
        self.v_buff[..., at["buff.mask"]] = b.zone_mask[:, None, :b.max_buffs]
        self.v_debuff[..., at["debuff.mask"]] = b.zone_mask[:, None, b.max_buffs:]
        if self._nav_groups:
            self._build_paths(c3, s3)
        if self.kind in FIRE_KINDS:
            self._build_fire()

    def _build_fire(self) -> None:
        """``tank.aimed``, ``tank.aim_near`` and ``tank.ready`` (``FIRE_KINDS``): every
        other tank's shot if it fired now, as :meth:`StateBatch.reach_shots` traced it,
        seen from each observer (in seat order; :meth:`_order_nearest` moves them on)."""
        b, at, vt = self.batch, self.at, self.v_tank
        obs, oi = self.observers, self.other_idx
        b.reach_shots()
        both = b.alive[:, oi] & b.alive[:, obs][..., None]  # (E, L, O)
        vt[..., at["tank.aimed"]] = (b.shot_first[:, oi] == obs[:, None]) & both
        passing = b.shot_pass[:, oi, obs[:, None]]  # (E, L, O)
        near = np.maximum(1.0 - passing / (4.0 * self._hit_radius), 0.0)
        vt[..., at["tank.aim_near"]] = np.where(both, near, 0.0)
        g = self.cfg
        limit = np.where(b.in_debuff, g.debuff_max_bullets,
                         np.where(b.in_buff, g.buff_max_bullets, g.max_bullets))
        ready = (b.cooldown <= 1) & (b.bullets_alive < limit) & b.alive  # (E, n)
        vt[..., at["tank.ready"]] = ready[:, oi]

    def _build_threat(self, bullets: tuple[np.ndarray, ...] | None, c3: np.ndarray,
                      s3: np.ndarray) -> None:
        """The ``threat`` block: of the other tanks' bullets flying at me in a straight
        line (walls ignored, like the bots' dodging), the one that will pass closest
        within ``THREAT_HORIZON_S``: how close (``near``), how soon (``eta``) and where
        its closest point lies (unit direction, own frame: dodge the other way); zeros
        while I am dead (:func:`~alphatank.game.kernels.nearest_threat`)."""
        vt = self.v_threat
        if bullets is None:
            vt[...] = 0.0
            return
        rel, vel, mask = bullets  # (E, L, K, 2), (E, L, K, 2), (E, L, K)
        nearest_threat(rel, vel, mask, c3[..., 0], s3[..., 0],
                       self.batch.alive[:, self.observers], 4.0 * self._hit_radius,
                       THREAT_HORIZON_S, vt)

    def _order_nearest(self) -> None:
        """Reorder each observer's other-tank slots nearest first within teammates and
        within enemies, dead tanks last in their group (``NEAREST_KINDS``)."""
        b, oi = self.batch, self.other_idx
        rel = self._relv[:, :, :self.n_others]
        key = np.hypot(rel[..., 0], rel[..., 1], out=self._near_key)
        np.copyto(key, self._dead_key, where=~b.alive[:, oi])
        key += self._group_key
        order = key.argsort(axis=-1, kind="stable")
        self.v_tank[...] = self.v_tank[self._ge, self._gl, order]

    def _build_paths(self, c3: np.ndarray, s3: np.ndarray) -> None:
        """``tank.path_*`` of every observer and other tank, one group of envs per map:
        shortest-path next cells from the all-pairs tables, rotated into the own frame
        (:func:`~alphatank.game.kernels.path_features`)."""
        b = self.batch
        for grid, envs in self._nav_groups:
            nodes = grid.nodes_of(b.tank_xy[envs].reshape(-1, 2)).reshape(len(envs), b.n)
            path_features(envs, nodes, b.tank_xy, b.alive, self.observers, self.other_idx,
                          grid.next_table, grid.dist_table, grid.centers, c3[..., 0],
                          s3[..., 0], 1.0 / grid.diameter, self._path_cols, self.v_tank)

    def ray_distances(self, xy: np.ndarray, angle: np.ndarray) -> np.ndarray:
        """(E, L, R) px to the nearest wall rectangle along ``rays`` directions from each
        observer (heading first, then clockwise on screen), by exact slab intersection;
        capped at ``ray_length`` (:func:`~alphatank.game.kernels.wall_rays`). ``xy``:
        (E, L, 2), ``angle``: (E, L). The result is a buffer reused by the next call of
        the same shape."""
        a = angle[..., None] + self._ray_angles  # (E, L, R)
        out = self._ray_out
        if out is None or out.shape != a.shape:
            out = self._ray_out = np.empty(a.shape)
        wall_rays(xy, np.cos(a), np.sin(a), self.batch.ray_rects, self.ray_length, out)
        return out


TANK_COLS = ("sin", "cos", "c0x", "c0y", "c1x", "c1y", "c2x", "c2y", "c3x", "c3y")  # per tank,
# in the paper builder's source row (x, y, vx, vy sit with the bullets', alive and wall with
# the flags)


def pick(arr: np.ndarray, idx: np.ndarray) -> np.ndarray | None:
    """``arr[:, idx]`` as a read-only strided view when ``idx`` (2-D, indices into axis 1)
    is affine in both its axes (a 1v1, or every seat in order), else None (index it)."""
    idx = np.asarray(idx)
    if idx.ndim != 2 or idx.size == 0:
        return None
    a = int(idx[0, 0])
    s0 = int(idx[1, 0] - idx[0, 0]) if idx.shape[0] > 1 else 0
    s1 = int(idx[0, 1] - idx[0, 0]) if idx.shape[1] > 1 else 0
    grid = a + s0 * np.arange(idx.shape[0])[:, None] + s1 * np.arange(idx.shape[1])
    if not np.array_equal(grid, idx) or s0 < 0 or s1 < 0:
        return None
    st = arr.strides
    view = np.lib.stride_tricks.as_strided(
        arr[:, a:], shape=(arr.shape[0], *idx.shape, *arr.shape[2:]),
        strides=(st[0], s0 * st[1], s1 * st[1], *st[2:]), writeable=False)
    return view


def _span(names: Sequence[str], first: str, last: str) -> slice:
    return slice(names.index(first), names.index(last) + 1)


# Columns of tank_table() / bullet_table(), by name.
_T_ALIVE, _T_SIN, _T_COS, _T_WALL = (TANK_FIELDS.index(f) for f in ("alive", "sin", "cos", "wall"))
_T_XY, _T_V, _T_CORNERS = (_span(TANK_FIELDS, *p) for p in (("x", "y"), ("vx", "vy"),
                                                            ("c0x", "c3y")))
_B_XY, _B_V = _span(BULLET_FIELDS, "x", "y"), _span(BULLET_FIELDS, "vx", "vy")


def tank_table(b: StateBatch, out: np.ndarray) -> np.ndarray:
    """(E, n, len(TANK_FIELDS)) normalised absolute features of every tank."""
    out[..., _T_ALIVE] = b.alive
    xy = out[..., _T_XY]
    np.multiply(b.tank_xy, b.inv, out=xy)
    xy -= 1.0
    s, c = out[..., _T_SIN], out[..., _T_COS]
    np.sin(b.tank_angle, out=s)
    np.cos(b.tank_angle, out=c)
    np.multiply(b.tank_vel, 1.0 / b.cfg.tank_speed, out=out[..., _T_V])
    corners = out[..., _T_CORNERS].reshape(out.shape[0], -1, 4, 2)
    np.multiply(c[..., None, None], b.corner_u, out=corners)
    corners += s[..., None, None] * b.corner_v
    corners += xy[:, :, None, :]
    out[..., _T_WALL] = b.wall
    return out


def bullet_table(b: StateBatch, out: np.ndarray) -> np.ndarray:
    """(E, n_bullets, len(BULLET_FIELDS)) normalised x, y, vx, vy of every bullet slot;
    0 when inactive."""
    xy = out[..., _B_XY]
    np.multiply(b.bullet_xy, b.inv, out=xy)
    xy -= 1.0
    np.multiply(b.bullet_vel, 1.0 / b.cfg.bullet_speed, out=out[..., _B_V])
    out *= b.bullet_active[..., None]
    return out


class GlobalState:
    """Centralised-critic state of every match in a :class:`StateBatch`: all tanks
    (``TANK_FIELDS`` + team), all bullet slots, zones (kind +1 buff, -1 debuff) and the
    episode's elapsed fraction. ``layout`` is its index map."""

    def __init__(self, batch: StateBatch, teams: Sequence[str]):
        self._args = (batch, teams)
        self.batch = batch
        n, nb = batch.n, batch.n_bullets
        names = sorted(set(teams))
        self.team = np.array([names.index(t) for t in teams]) / max(1, len(names) - 1)
        Z = batch.zones.shape[1]
        lay = ObsLayout("state")
        lay.add("tank", n, TANK_FIELDS + ("team",))
        lay.add("bullet", nb, ("mask", "x", "y", "vx", "vy"))
        lay.add("zone", Z, ("mask", "kind", "x", "y"))
        lay.add("time", None, ("t",))
        self.layout = lay
        E = batch.num_envs
        self.out = np.zeros((E, lay.size), dtype=np.float32)
        self._tt = np.zeros((E, n, len(TANK_FIELDS)))
        self._bt = np.zeros((E, nb, 4))
        self._tank = self.out[:, lay["tank"]].reshape(E, n, lay.widths["tank"])
        self._bullet = self.out[:, lay["bullet"]].reshape(E, nb, lay.widths["bullet"])
        self._zone = self.out[:, lay["zone"]].reshape(E, Z, lay.widths["zone"])
        self._kind = np.where(np.arange(Z) < batch.max_buffs, 1.0, -1.0)

    def __reduce__(self) -> tuple:
        return (type(self), self._args)

    def build(self) -> np.ndarray:
        b = self.batch
        self._tank[..., :-1] = tank_table(b, self._tt)
        self._tank[..., -1] = self.team
        self._bullet[..., 0] = b.bullet_active
        self._bullet[..., 1:] = bullet_table(b, self._bt)
        zm = b.zone_mask
        self._zone[..., 0] = zm
        self._zone[..., 1] = self._kind * zm
        self._zone[..., 2:4] = (b.zones * b.inv - 1.0) * zm[..., None]
        self.out[:, -1] = b.tick / b.cfg.max_steps
        np.clip(self.out, -1.0, 1.0, out=self.out)
        self.out += 0.0  # -0.0 -> 0.0, as in ObservationBuilder.build
        return self.out
