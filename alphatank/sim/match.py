"""Match rules on top of the physics world.

Teams, firing (muzzle, cooldown in ticks, bullet limits with buff/debuff zones), one-hit
kills, friendly fire, self-hit, immortal training mode, termination, winner, and the typed
events of each tick. All randomness comes from the match's seeded generator.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from alphatank.sim.config import GameConfig, check_seed
from alphatank.sim.grid import floor_areas
from alphatank.sim.mapspec import MapError, MapSpec
from alphatank.sim.world import World

ACTION_HELP = "rotate 0..2 (0 ccw, 1 none, 2 cw), move 0..2 (0 back, 1 stop, 2 forward), fire 0..1"


class Fired(NamedTuple):
    tank: int
    bullet: int


class Bounced(NamedTuple):
    bullet: int
    owner: int
    x: float
    y: float


class Hit(NamedTuple):
    bullet: int
    shooter: int
    victim: int
    friendly: bool  # same team (includes self-hits)


class Killed(NamedTuple):
    victim: int
    shooter: int


class WallContact(NamedTuple):
    tank: int


class ZoneEntered(NamedTuple):
    tank: int
    kind: str  # "buff" or "debuff"


class BulletExpired(NamedTuple):
    bullet: int
    owner: int


Event = Fired | Bounced | Hit | Killed | WallContact | ZoneEntered | BulletExpired


@dataclass
class TickEvents:
    """Everything that happened in one tick, by kind."""

    fired: list[Fired] = field(default_factory=list)
    bounced: list[Bounced] = field(default_factory=list)
    hits: list[Hit] = field(default_factory=list)
    kills: list[Killed] = field(default_factory=list)
    wall_contacts: list[WallContact] = field(default_factory=list)
    zones_entered: list[ZoneEntered] = field(default_factory=list)
    expired: list[BulletExpired] = field(default_factory=list)

    def clear(self) -> None:
        for kind in (self.fired, self.bounced, self.hits, self.kills, self.wall_contacts,
                     self.zones_entered, self.expired):
            kind.clear()

    def __iter__(self) -> Iterator[Event]:
        yield from self.fired
        yield from self.bounced
        yield from self.hits
        yield from self.kills
        yield from self.wall_contacts
        yield from self.zones_entered
        yield from self.expired


class Match:
    """One match: a world plus rules. ``reset(seed)`` rebuilds everything.

    State for readers (bots, observations, rendering) lives in arrays:
    ``tank_xy`` (n, 2), ``tank_angle`` (n,), ``tank_vel`` (n, 2), ``alive`` (n,),
    ``team_index`` (n,), ``bullet_xy``/``bullet_vel`` (n*cap, 2), ``bullet_active``,
    ``bullet_owner``, ``in_buff``/``in_debuff`` (n,), ``wall`` (n,: touching a wall now),
    ``cooldown`` (n,), ``bullets_alive`` (n,), ``score`` (n,). ``alive``, ``wall``,
    ``in_buff``, ``in_debuff`` are the rows of ``flags`` (4, n), ``cooldown`` and
    ``bullets_alive`` those of ``counts`` (2, n), so that a batch copies each in one go
    (``StateBatch.gather``); they are written in place, never rebound.
    """

    def __init__(self, cfg: GameConfig, spec: MapSpec, teams: Sequence[str],
                 seed: int | None = None):
        if len(teams) < 2:
            raise ValueError(f"a match needs at least 2 tanks, got teams={list(teams)}")
        if len(set(teams)) < 2:
            raise ValueError(f"a match needs at least 2 teams, got teams={list(teams)}")
        diagonal = math.hypot(cfg.tank_width, cfg.tank_height)
        if spec.cell < diagonal:
            raise MapError(f"cells of {spec.cell:g} px are too small for tanks of "
                           f"{cfg.tank_width:g} x {cfg.tank_height:g} px (tank_width, "
                           f"tank_height): a tank spawns and turns in one cell, which needs "
                           f"cells of at least its diagonal, {diagonal:.1f} px", spec.source)
        self.cfg, self.spec = cfg, spec
        self.teams = list(teams)
        self.team_names = sorted(set(teams))
        self.n = len(teams)
        self.team_index = np.array([self.team_names.index(t) for t in teams], dtype=np.int64)
        self.events = TickEvents()
        self.reset(seed)

    # ---- set-up ---------------------------------------------------------------------

    def reset(self, seed: int | None = None) -> None:
        """Start a new episode: new spawns, zones and world from the generator seeded
        with ``seed`` (an integer >= 0; None: fresh entropy)."""
        self.rng = np.random.default_rng(None if seed is None else check_seed(seed))
        spec, n = self.spec, self.n
        spawn_cells = self._spawn_cells()
        taken = set(spawn_cells)
        zone_free = [c for c in spec.floor_cells() if c not in taken]
        if spec.random_zones:
            k = min(len(zone_free), self.cfg.random_buff_zones + self.cfg.random_debuff_zones)
            picks = self.rng.choice(len(zone_free), size=k, replace=False)
            cells = [zone_free[i] for i in picks]
            self.buffs = cells[: self.cfg.random_buff_zones]
            self.debuffs = cells[self.cfg.random_buff_zones:]
        else:
            self.buffs, self.debuffs = list(spec.buffs), list(spec.debuffs)
        self.zone_grid = np.zeros(spec.walls.shape, dtype=np.int8)  # 1 buff, -1 debuff
        for r, c in self.buffs:
            self.zone_grid[r, c] = 1
        for r, c in self.debuffs:
            self.zone_grid[r, c] = -1
        self._zone_rows = self.zone_grid.tolist()
        poses = np.zeros((n, 3))
        for i, cell in enumerate(spawn_cells):
            poses[i, :2] = spec.cell_center(cell)
        poses[:, 2] = self.rng.uniform(-math.pi, math.pi, size=n)
        self.spawn_cells = spawn_cells
        self.world = World(self.cfg, spec, poses)
        w = self.world
        self.tank_xy = w.tank_state[:, 0:2]
        self.tank_angle = w.tank_state[:, 2]
        self.tank_vel = w.tank_state[:, 3:5]
        self.bullet_xy = w.bullet_state[:, 0:2]
        self.bullet_vel = w.bullet_state[:, 3:5]
        self.bullet_active = w.bullet_active
        self.bullet_owner = w.bullet_owner
        self.bullet_bounces = w.bullet_bounces
        self.capacity = w.capacity
        can_hit = np.ones((n, n), dtype=bool)
        if not self.cfg.friendly_fire:
            can_hit &= self.team_index[:, None] != self.team_index[None, :]
        np.fill_diagonal(can_hit, self.cfg.self_hit)
        w.can_hit[:] = can_hit
        self.flags = np.zeros((4, n), dtype=bool)
        self.alive, self.wall, self.in_buff, self.in_debuff = self.flags
        self.alive[:] = True
        self.counts = np.zeros((2, n), dtype=np.int64)
        self.cooldown, self.bullets_alive = self.counts
        self.score = np.zeros(n, dtype=np.int64)  # enemy hits scored
        self._zone = [0] * n  # zone code of each tank's cell (1 buff, -1 debuff)
        self._contacts_seen = -1  # world.contacts_changed when _touching was built
        self._touching: list[WallContact] = []
        self.tick = 0
        self.terminated = self.truncated = False
        self.winner: str | None = None
        self.events.clear()
        self._update_zones(report=False)

    def _spawn_cells(self) -> list[tuple[int, int]]:
        """Map spawns for slots 1..n; missing slots (all with ``random_spawns``) drawn from
        free, reachable floor."""
        spec = self.spec
        cells: list[tuple[int, int] | None] = (
            [None] * self.n if self.cfg.random_spawns
            else [spec.spawns.get(i + 1) for i in range(self.n)])
        used = {c for c in cells if c is not None}
        anchor = next((c for c in cells if c is not None), None)
        missing = [i for i, c in enumerate(cells) if c is None]
        if not missing:
            return [c for c in cells if c is not None]
        floor = spec.floor_cells()
        if anchor is None:
            anchor = floor[int(self.rng.integers(len(floor)))]
            if spec.free_cells_in(spec.reachable(anchor)) < len(missing):
                # a pocket too small for the tanks: draw again in a roomy floor area
                roomy = [c for area in floor_areas(spec.walls)
                         if spec.free_cells_in(area) >= len(missing) for c in floor if area[c]]
                if roomy:
                    anchor = roomy[int(self.rng.integers(len(roomy)))]
        reach = spec.reachable(anchor)
        free = [c for c in floor if reach[c] and c not in used
                and c not in spec.buffs and c not in spec.debuffs]
        if len(free) < len(missing):
            raise ValueError(f"map {spec.name!r} has room for {len(free) + len(used)} tanks, "
                             f"{self.n} requested")
        picks = self.rng.choice(len(free), size=len(missing), replace=False)
        for i, p in zip(missing, picks, strict=True):
            cells[i] = free[int(p)]
        return [c for c in cells if c is not None]

    def bench(self, tanks: Sequence[int]) -> None:
        """Take ``tanks`` out of this episode before its first tick (the absent seats of a
        line-up curriculum): dead from the start, out of the physics, no events. Every
        team keeps at least one tank."""
        if self.tick:
            raise RuntimeError("Match.bench: only before the first tick")
        out = ~self.alive
        out[list(tanks)] = True
        kept = np.unique(self.team_index[~out])
        if kept.size < len(self.team_names):
            raise ValueError(f"Match.bench: tanks {sorted(set(tanks))} would leave a team "
                             f"with no tank")
        for i in np.flatnonzero(out & self.alive).tolist():
            self.alive[i] = False
            self.world.remove_tank(i)
        self._update_zones(report=False)

    # ---- rules ----------------------------------------------------------------------

    def place_tank(self, tank: int, x: float, y: float, angle: float) -> None:
        """Teleport a tank (for set-ups and tests); zones are re-evaluated."""
        self.world.place_tank(tank, x, y, angle)
        self.world.read_state()
        self._update_zones(report=False)

    def bullet_limit(self, tank: int) -> int:
        if self.in_debuff[tank]:
            return self.cfg.debuff_max_bullets
        if self.in_buff[tank]:
            return self.cfg.buff_max_bullets
        return self.cfg.max_bullets

    def step(self, actions: np.ndarray) -> TickEvents:
        """Advance one tick. ``actions``: (n, 3) integers (rotate 0..2, move 0..2, fire
        0..1), one row per tank, checked before anything moves; rows of dead tanks are
        ignored. Returns this tick's events (reused between ticks)."""
        if self.terminated or self.truncated:
            raise RuntimeError("step() called on a finished match; call reset()")
        rows = self._action_rows(actions)
        ev, w, cfg = self.events, self.world, self.cfg
        ev.clear()
        cooldown = self.cooldown
        alive = self.alive.tolist()
        for i, c in enumerate(cooldown.tolist()):
            if c:
                cooldown[i] = c = c - 1
            if not alive[i]:
                continue
            rot, move, fire = rows[i]
            w.drive(i, rot - 1, move - 1)
            if fire and not c and self.bullets_alive[i] < self.bullet_limit(i):
                b = w.fire(i)
                if b >= 0:
                    ev.fired.append(Fired(i, b))
                    self.bullets_alive[i] += 1
                    cooldown[i] = (cfg.buff_cooldown_ticks if self.in_buff[i]
                                   else cfg.cooldown_ticks)
        w.step()
        self.tick += 1
        if w.bounces or w.expired or w.hits:
            self._bullet_events(ev, w)
        if w.contacts_changed != self._contacts_seen:
            self._contacts_seen = w.contacts_changed
            touching = [c > 0 for c in w.wall_contacts.tolist()]  # a few tanks: plain Python
            self._touching = [WallContact(i) for i, t in enumerate(touching) if t]
            self.wall[:] = touching
        if self._touching:
            ev.wall_contacts.extend(self._touching)
        self._update_zones(report=True)
        self._check_end()
        return ev

    def _action_rows(self, actions: np.ndarray) -> list[list[int]]:
        """``actions`` as lists of ints, after a dtype, shape and range check whose error
        names the tank and the allowed values."""
        arr = actions if isinstance(actions, np.ndarray) else np.asarray(actions)
        if arr.dtype.kind not in "iub":
            raise TypeError(f"Match.step: actions must be integers ({ACTION_HELP}), "
                            f"got dtype {arr.dtype}")
        if arr.shape != (self.n, 3):
            raise ValueError(f"Match.step: actions must have shape ({self.n}, 3), one row "
                             f"(rotate, move, fire) per tank, got {arr.shape}")
        rows = arr.tolist()
        for i, (rot, move, fire) in enumerate(rows):
            if not (0 <= rot <= 2 and 0 <= move <= 2 and 0 <= fire <= 1):
                raise ValueError(f"Match.step: tank {i}: action {rows[i]} out of range; "
                                 f"allowed: {ACTION_HELP}")
        return rows

    def _bullet_events(self, ev: TickEvents, w: World) -> None:
        """Bounces, expiries and hits of the tick: counts, score, kills, events."""
        owner = self.bullet_owner
        for bounce in w.bounces:
            ev.bounced.append(Bounced(bounce.bullet, int(owner[bounce.bullet]),
                                      bounce.x, bounce.y))
        for b in w.expired:
            o = int(owner[b])
            self.bullets_alive[o] -= 1
            ev.expired.append(BulletExpired(b, o))
        for b, victim in w.hits:
            shooter = int(owner[b])
            self.bullets_alive[shooter] -= 1
            friendly = bool(self.team_index[shooter] == self.team_index[victim])
            ev.hits.append(Hit(b, shooter, victim, friendly))
            if not friendly:
                self.score[shooter] += 1
            if not self.cfg.immortal and self.alive[victim]:
                self.alive[victim] = False
                w.remove_tank(victim)
                ev.kills.append(Killed(victim, shooter))

    def _update_zones(self, report: bool) -> None:
        """Zone membership of live tanks (a few tanks: plain Python beats numpy here);
        the arrays are written only when a tank changes zone."""
        cell, zones, now = self.spec.cell, self._zone_rows, self._zone
        alive = self.alive.tolist()
        for i, (x, y) in enumerate(self.tank_xy.tolist()):
            zone = zones[int(y // cell)][int(x // cell)] if alive[i] else 0
            if zone == now[i]:
                continue
            if report and zone:
                self.events.zones_entered.append(ZoneEntered(i, "buff" if zone == 1
                                                             else "debuff"))
            now[i] = zone
            self.in_buff[i], self.in_debuff[i] = zone == 1, zone == -1

    def _check_end(self) -> None:
        if self.events.kills:
            teams_alive = np.unique(self.team_index[self.alive])
            if teams_alive.size <= 1:
                self.terminated = True
                self.winner = (self.team_names[int(teams_alive[0])] if teams_alive.size
                               else None)
                return
        if self.tick >= self.cfg.max_steps:
            self.truncated = True
            if self.cfg.immortal:
                self.winner = self._most_hits()

    def _most_hits(self) -> str | None:
        totals = np.bincount(self.team_index, weights=self.score, minlength=len(self.team_names))
        best = np.flatnonzero(totals == totals.max())
        return self.team_names[int(best[0])] if best.size == 1 else None

    @property
    def done(self) -> bool:
        return self.terminated or self.truncated

    def state_hash(self) -> str:
        """Digest of the full dynamic state (for determinism checks and replays)."""
        h = hashlib.sha256()
        for arr in (self.world.state, self.alive, self.bullet_active, self.cooldown,
                    self.score, self.bullet_bounces):
            h.update(np.ascontiguousarray(arr).tobytes())
        h.update(self.tick.to_bytes(8, "little"))
        return h.hexdigest()
