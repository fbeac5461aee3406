"""The compiled kernels give the bits of the numpy expressions they replaced."""

import math

import numpy as np
import pytest

from alphatank.game.kernels import progress_counts
from alphatank.game.observe import ObservationBuilder, StateBatch, slot_counts
from alphatank.sim.config import game_config
from alphatank.sim.mapspec import load_map
from alphatank.sim.match import Match


def numpy_progress(bullet_xy, tank_xy, alive, active, enemy, prev, cap, weights):
    """The bullet_close / bullet_away terms as numpy computed them before the kernel."""
    d = bullet_xy[:, :, None, :] - tank_xy[:, None]
    dist = np.hypot(d[..., 0], d[..., 1])
    ok = enemy & alive[:, None, :] & active[..., None]
    now = np.fmin.reduce(dist, axis=-1, where=ok, initial=math.nan)
    cmp = np.stack([now < prev, now > prev])  # (2, E, nr)
    counts = np.add.reduce(cmp.reshape(2, len(now), -1, cap), axis=-1)  # (2, E, S)
    return counts.transpose(1, 0, 2) * weights[:, None], now


@pytest.mark.parametrize("seed", range(5))
def test_progress_counts_equal_the_numpy_terms_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    E, n, S, cap = 4, 4, 2, 3
    nr = S * cap
    bullet_xy = rng.uniform(0, 600, (E, nr, 2))
    tank_xy = rng.uniform(0, 600, (E, n, 2))
    tank_xy[0, 1] = tank_xy[0, 2]  # two enemies at one spot: a tie for the nearest
    alive = rng.random((E, n)) < 0.7
    active = rng.random((E, nr)) < 0.6
    owner = np.repeat([0, 1], cap)
    team = np.array([0, 1, 1, 0])
    enemy = team[owner][:, None] != team[None, :]
    prev = rng.uniform(0, 800, (E, nr))
    prev[rng.random((E, nr)) < 0.3] = np.nan  # fresh slots
    prev[1] = np.hypot(*(bullet_xy[1, :, None, :] - tank_xy[1, None]).transpose(2, 0, 1)
                       ).min(axis=1)  # no move: neither closer nor farther
    weights = np.array([0.5, -0.25])
    want, want_now = numpy_progress(bullet_xy, tank_xy, alive, active, enemy, prev, cap,
                                    weights)
    out = np.full((E, 2, S), 7.0)
    got_prev = prev.copy()
    progress_counts(bullet_xy, tank_xy, alive, active, enemy, got_prev, cap, weights, out)
    assert out.tobytes() == want.tobytes()  # -0.0 included
    assert got_prev.tobytes() == want_now.tobytes()
    assert np.count_nonzero(want), "the case scores something"


def test_progress_counts_leave_the_terms_alone_while_no_bullet_flies():
    E, n, S, cap = 2, 2, 1, 3
    prev = np.ones((E, S * cap))
    out = np.full((E, 2, S), 3.0)
    progress_counts(np.zeros((E, S * cap, 2)), np.zeros((E, n, 2)), np.ones((E, n), bool),
                    np.zeros((E, S * cap), bool), np.ones((S * cap, n), bool), prev, cap,
                    np.array([1.0, -1.0]), out)
    assert np.isnan(prev).all()
    assert (out == 3.0).all()


def test_paper_observation_sorts_other_bullets_nearest_first_ties_in_slot_order():
    game = game_config("paper")
    spec = load_map("maze")
    teams = ["A", "B"]
    batch = StateBatch(game, 2, 1, *slot_counts(game, [spec]))
    batch.set_static(0, Match(game, spec, teams, seed=0))
    builder = ObservationBuilder("paper", batch, teams, [0])
    builder.set_static(0)
    cap = game.bullet_capacity
    batch.raw[0, 0, 0:2] = (300.0, 300.0)  # the observer
    batch.raw[0, 1, 0:2] = (100.0, 100.0)
    bullets = batch.raw[0, 2:2 + 2 * cap]  # seat 1's slots follow seat 0's
    far, near, tie = cap, cap + 1, cap + 2
    bullets[far, 0:2] = (300.0, 420.0)
    bullets[near, 0:2] = (300.0, 340.0)
    bullets[tie, 0:2] = (340.0, 300.0)  # as near as `near`, a later slot
    batch.bullet_active[0, [far, near, tie]] = True
    obs = builder.build()[0, 0]
    lay, at = builder.layout, builder.at
    width = lay.widths["bullet"]
    slot = obs[lay["bullet"]].reshape(-1, width)
    scale = 1.0 / max(spec.width, spec.height)
    rel_y = slot[:, at["bullet.rel_x:rel_y"]][:, 1]
    assert slot[:, at["bullet.mask"]].tolist() == [1.0, 1.0, 1.0] + [0.0] * (cap - 3)
    assert rel_y[:3].tolist() == pytest.approx([40 * scale, 0.0, 120 * scale])
    assert (np.abs(obs) <= 1.0).all()
