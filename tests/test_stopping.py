"""Stopping a run inside an iteration (signals, time budget) and resuming from the save:
the rewind of fixed-rollout learners is exact, a SAC segment cut keeps every transition
and resumes deterministically, SAC update rounds stop between gradient steps, metrics
rows after a checkpoint are rewound, and the time limit is the budget of each call."""

import dataclasses
import gc
import json
import multiprocessing
import os
import shutil
import signal
import subprocess
import sys
import time
import warnings

import numpy as np
import pytest
import torch

from alphatank.commands.train import report
from alphatank.envs.vector import VectorMatchEnv
from alphatank.errors import InputError
from alphatank.training.checkpoint import load_checkpoint
from alphatank.training.logging import RunLogger, rewind_metrics
from alphatank.training.ppo import PPOConfig
from alphatank.training.presets import LearnerSpec, TrainConfig
from alphatank.training.runner import EnvWorkerDied, RunWarning, Trainer, resume_trainer
from alphatank.training.sac import SAC, SACConfig
from alphatank.training.stopping import (
    StopFlag,
    StopRequested,
    exit_with_parent,
    stop_on_signals,
)

torch.set_num_threads(1)
pytestmark = pytest.mark.filterwarnings("ignore::alphatank.training.runner.RunWarning")

E = 4
PPO_TINY = PPOConfig(num_steps=16, update_epochs=2, num_minibatches=2)
SAC_TINY = SACConfig(batch_size=32, start_steps=32, update_after=32, update_every=16,
                     buffer_size=4096, hidden=32)


class SignalAt(VectorMatchEnv):
    """The vector env, raising ``signum`` in this process during its ``at``-th step."""

    def __init__(self, *args, at: int | None = None, signum: int = signal.SIGINT, **kw):
        super().__init__(*args, **kw)
        self.at, self.signum, self.calls = at, signum, 0

    def step(self, actions):
        self.calls += 1
        if self.calls == self.at:
            signal.raise_signal(self.signum)
        return super().step(actions)


def config(name: str, learner: LearnerSpec, iterations: int, **kw) -> TrainConfig:
    base = dict(name=name, scenario="vs_aggressive", total_steps=iterations * 16 * E,
                num_envs=E, num_workers=1, seed=5, wandb="disabled", checkpoint_every=2,
                rollout_steps=16, game={"max_steps": 30}, learners=(learner,))
    base.update(kw)
    return TrainConfig(**base)


def trainer(cfg: TrainConfig, run_dir, at: int | None = None,
            signum: int = signal.SIGINT) -> Trainer:
    env = SignalAt(cfg.scenario, E, cfg.seed, game_overrides=cfg.game, at=at, signum=signum)
    return Trainer(cfg, run_dir, env=env, progress=False)


def states_equal(a: dict, b: dict) -> bool:
    if a.keys() != b.keys():
        return False
    for key in a:
        x, y = a[key], b[key]
        if isinstance(x, dict):
            if not states_equal(x, y):
                return False
        elif isinstance(x, torch.Tensor):
            if not torch.equal(x, y):
                return False
        elif x != y:
            return False
    return True


def test_a_stop_inside_an_iteration_saves_its_start_and_resumes_exactly(tmp_path):
    spec = LearnerSpec("ppo", "ppo", (0,), PPO_TINY)
    # reference: saves after iterations 2 and 3 (its end), then resumed for 2 more
    ref = trainer(config("ref", spec, 3), tmp_path / "ref")
    assert ref.train()["stopped"] is None
    # the same run, 5 iterations, Ctrl-C during the 6th vector step of iteration 4:
    # iteration 3 was not saved (every 2), so the stop saves the state it began with
    stopped = trainer(config("stop", spec, 5), tmp_path / "stop", at=3 * 16 + 6)
    handler = signal.getsignal(signal.SIGINT)
    summary = stopped.train()
    assert signal.getsignal(signal.SIGINT) is handler  # restored
    assert summary["exit_code"] == 130
    assert summary["stopped"] == {"reason": "SIGINT", "checkpoint_step": 3 * 16 * E,
                                  "dropped_steps": 6 * E}
    assert summary["saved_step"] == 3 * 16 * E < summary["global_step"]  # what demo reports
    a, b = load_checkpoint(tmp_path / "ref"), load_checkpoint(tmp_path / "stop")
    assert a.path.name == b.path.name == f"step_{3 * 16 * E:010d}"
    assert {k: v for k, v in a.meta["progress"].items() if k != "elapsed"} == \
        {k: v for k, v in b.meta["progress"].items() if k != "elapsed"}
    assert a.meta["windows"] == b.meta["windows"]
    # normaliser statistics and random generators moved during the dropped steps: rewound
    assert states_equal(a.state("ppo"), b.state("ppo"))
    rows = [json.loads(x) for x in (tmp_path / "stop" / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == [16 * E, 32 * E, 48 * E]  # nothing for the cut
    runs = []
    for name in ("ref", "stop"):
        tr = resume_trainer(tmp_path / name, progress=False, total_steps=5 * 16 * E)
        assert tr.train()["stopped"] is None
        runs.append(tr)
    assert [h["step"] for h in runs[1].history] == [64 * E, 80 * E]
    for key in ("losses/policy_loss", "losses/value_loss", "charts/episodes"):
        assert [h[key] for h in runs[0].history] == [h[key] for h in runs[1].history], key
    assert states_equal(runs[0].learners["ppo"].state_dict(),
                        runs[1].learners["ppo"].state_dict())


def test_the_summary_of_a_stop_that_drops_an_iteration_counts_what_was_saved(tmp_path):
    """A stop inside the update of iteration 4 drops that iteration's episodes with it:
    the summary counts the episodes and win rates the checkpoint holds (those of the
    iterations before), not those of the dropped one."""
    spec = LearnerSpec("ppo", "ppo", (0,), PPO_TINY)
    ref = trainer(config("ref", spec, 4), tmp_path / "ref")
    ref.train()
    done, dropped = ref.history[2], ref.history[3]
    assert dropped["charts/episodes"] > done["charts/episodes"]  # episodes ended in it
    stopped = trainer(config("stop", spec, 5), tmp_path / "stop", at=4 * 16)  # in the update
    summary = stopped.train()
    assert summary["stopped"] == {"reason": "SIGINT", "checkpoint_step": 3 * 16 * E,
                                  "dropped_steps": 16 * E}
    ck = load_checkpoint(tmp_path / "stop")
    assert summary["episodes"] == ck.meta["progress"]["episodes"] == done["charts/episodes"]
    for key in ("charts/episodes", "charts/win_rate", "charts/episode_return",
                "charts/episode_length"):
        assert summary[key] == done[key], key
    assert stopped._windows() == ck.meta["windows"]


class SignalInFinalEval(Trainer):
    """A trainer that gets SIGINT during its final evaluation (after its last iteration)."""

    def evaluate(self, games: int) -> dict[str, float]:
        if self.global_step >= self.cfg.total_steps:
            signal.raise_signal(signal.SIGINT)
        return super().evaluate(games)


def test_a_stop_during_the_final_evaluation_says_the_run_is_finished(tmp_path, capsys):
    """The run has all its steps: the stop skips the final evaluation, and the summary says
    the run is finished and how to evaluate it, not to resume (which would do nothing)."""
    spec = LearnerSpec("ppo", "ppo", (0,), PPO_TINY)
    cfg = config("fin", spec, 2, eval_every=1, eval_games=2)
    env = SignalAt(cfg.scenario, E, cfg.seed, game_overrides=cfg.game)
    summary = SignalInFinalEval(cfg, tmp_path / "fin", env=env, progress=False).train()
    assert summary["exit_code"] == 130
    assert summary["stopped"] == {"reason": "SIGINT", "checkpoint_step": 2 * 16 * E,
                                  "finished": True, "final_eval_skipped": True}
    assert report(summary) == 130
    assert capsys.readouterr().out.splitlines()[0] == (
        f"stopped by SIGINT: the run is finished (saved step {2 * 16 * E}); its final "
        f"evaluation was skipped: alphatank eval {tmp_path / 'fin'} plays one")
    rows = [json.loads(x) for x in (tmp_path / "fin" / "metrics.jsonl").read_text().splitlines()]
    assert [(r["step"], "eval/win_rate" in r) for r in rows] == [(16 * E, True),
                                                                  (32 * E, False)]
    again = resume_trainer(tmp_path / "fin", progress=False).train()  # nothing left to do
    assert again["stopped"] is None and again["global_step"] == 2 * 16 * E


def test_a_sac_stop_cuts_the_segment_keeps_every_transition_and_resumes_deterministically(
        tmp_path):
    spec = LearnerSpec("sac", "sac", (0,), SAC_TINY)
    cfg = config("sac", spec, 6, checkpoint_every=4)
    tr = trainer(cfg, tmp_path / "sac", at=16 + 5, signum=signal.SIGTERM)
    summary = tr.train()
    assert summary["exit_code"] == 143
    assert summary["stopped"] == {"reason": "SIGTERM", "checkpoint_step": 21 * E,
                                  "cut_steps": 5 * E, "dropped_rollouts": []}
    ck = load_checkpoint(tmp_path / "sac")
    assert ck.meta["progress"]["global_step"] == 21 * E and ck.meta["progress"]["cut"] == 5
    assert len(ck.replay("sac")["obs"]) == 21 * E  # every transition kept
    rows = [json.loads(x) for x in (tmp_path / "sac" / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == [16 * E, 21 * E]  # the cut logs its partial row
    copy = tmp_path / "copy"
    shutil.copytree(tmp_path / "sac", copy)
    runs = []
    for run_dir in (tmp_path / "sac", copy):
        resumed = resume_trainer(run_dir, progress=False, total_steps=6 * 16 * E)
        assert resumed.global_step == 21 * E
        resumed.train()
        runs.append(resumed)
    # a full iteration starts at the cut; the same checkpoint gives the same run; the
    # last iteration is shorter: the run ends at its planned 96 x E steps (it went on to
    # 101 x E, an iteration past what --list and experiments plan)
    assert [h["step"] for h in runs[0].history] == [37 * E, 53 * E, 69 * E, 85 * E,
                                                    96 * E]
    assert load_checkpoint(tmp_path / "sac").meta["progress"]["global_step"] == 96 * E
    assert [h["losses/qf_loss"] for h in runs[0].history] == \
        [h["losses/qf_loss"] for h in runs[1].history]
    assert states_equal(runs[0].learners["sac"].state_dict(),
                        runs[1].learners["sac"].state_dict())


def test_mixed_runs_cut_and_drop_the_unfinished_ppo_rollout(tmp_path):
    sac = LearnerSpec("sac", "sac", (1,), SAC_TINY)
    ppo = LearnerSpec("ppo", "ppo", (0,), PPO_TINY)
    cfg = config("pair", sac, 4, scenario="pair", learners=(ppo, sac), checkpoint_every=4)
    env = SignalAt("pair", E, cfg.seed, game_overrides=cfg.game, at=16 + 9)
    tr = Trainer(cfg, tmp_path / "pair", env=env, progress=False)
    before = {}
    original = tr._iteration_start

    def spy():
        out = original()
        before.update(out)
        return out

    tr._iteration_start = spy
    assert tr.train()["stopped"]["dropped_rollouts"] == ["ppo"]
    ck = load_checkpoint(tmp_path / "pair")
    assert ck.meta["progress"]["global_step"] == 25 * E
    assert states_equal(ck.state("ppo"), before["ppo"])  # as the iteration began
    assert ck.state("ppo")["obs_norm"]["count"] < 25 * E  # not the 9 dropped steps
    assert len(ck.replay("sac")["obs"]) == 25 * E
    # the shifted iterations end at the planned 64 x E steps (the last one is 7 steps)
    resumed = resume_trainer(tmp_path / "pair", progress=False)
    assert resumed.train()["stopped"] is None
    assert [h["step"] for h in resumed.history] == [41 * E, 57 * E, 64 * E]
    assert load_checkpoint(tmp_path / "pair").meta["progress"]["global_step"] == 64 * E


def test_sac_update_rounds_stop_between_gradient_steps_and_owe_the_rest():
    def filled(seed=0):
        sac = SAC(5, 4, SACConfig(hidden=16, batch_size=8, start_steps=0, update_after=8,
                                  update_every=8, buffer_size=256), seed=seed)
        rng = np.random.default_rng(1)
        for _ in range(8):
            sac.act(rng.normal(size=(4, 5)).astype(np.float32))
            sac.observe(rng.normal(size=(4, 5)).astype(np.float32), rng.normal(size=4),
                        np.zeros(4, bool), np.zeros(4, bool))
        return sac

    whole, cut = filled(), filled()
    assert whole.since_update == cut.since_update == 32 - 8 + 4
    whole.update()
    assert whole.grad_steps == 28 and whole.owed == 0
    cut.interrupt = lambda: cut.grad_steps >= 11
    cut.update()
    assert cut.grad_steps == 11 and cut.owed == 17 and cut.ready  # the rest is owed
    cut.interrupt = None
    cut.update()
    assert cut.grad_steps == 28
    a, b = whole.state_dict(), cut.state_dict()
    assert a.pop("counters")[2] == 1 and b.pop("counters")[2] == 2  # update rounds
    assert states_equal(a, b)  # the same gradient steps in the same order
    frac = filled()
    frac.cfg = dataclasses.replace(frac.cfg, utd_ratio=0.3)
    frac.update()
    assert frac.grad_steps == 8 and frac.owed == pytest.approx(0.4)  # 28 x 0.3 = 8.4


def test_the_time_limit_is_the_budget_of_each_call(tmp_path):
    spec = LearnerSpec("ppo", "ppo", (0,), PPO_TINY)
    cfg = config("timed", spec, 10**6, time_limit_s=1.5, checkpoint_every=100)
    tr = Trainer(cfg, tmp_path / "timed", progress=False)
    first = tr.train()
    assert first["stopped"]["reason"] == "time limit" and first["exit_code"] == 0
    ck = load_checkpoint(tmp_path / "timed")
    step1, t1 = ck.meta["progress"]["global_step"], ck.meta["progress"]["elapsed"]
    assert step1 > 0 and 1.5 <= t1 < 1.5 + 5  # stopped within 5 s of the limit
    again = resume_trainer(tmp_path / "timed", progress=False)
    assert again.cfg.time_limit_s == 1.5
    again.train()
    ck = load_checkpoint(tmp_path / "timed")
    # a fresh 1.5 s for this call, not "1.5 s in all" (which would allow one iteration)
    assert ck.meta["progress"]["elapsed"] >= t1 + 1.5
    assert ck.meta["progress"]["global_step"] > step1 + 16 * E


def test_a_time_limit_shorter_than_an_iteration_says_a_resume_gets_no_further(tmp_path,
                                                                               capsys):
    """A time limit that ends the run before it trains one iteration (fresh or resumed):
    the summary says that a resume under the same limit would get no further (it said
    only to resume, which stopped at the same step again, forever); a call that got
    somewhere does not say it."""
    cfg = config("short", LearnerSpec("ppo", "ppo", (0,), PPO_TINY), 4, time_limit_s=1e-3)
    run = tmp_path / "short"
    for start in (lambda: Trainer(cfg, run, progress=False),
                  lambda: resume_trainer(run, progress=False)):
        out = start().train()
        assert out["stopped"]["no_progress"] and out["saved_step"] == 0
        assert report(out) == 0
        assert "a resume under the same --time-limit gets no further" in capsys.readouterr().out
    out = resume_trainer(run, progress=False, time_limit_s=0.0).train()
    assert out["stopped"] is None and report(out) == 0
    assert "no further" not in capsys.readouterr().out


def test_stop_flag_signals_and_interruptible_blocks():
    flag = StopFlag()
    with stop_on_signals(flag):
        assert not flag()
        signal.raise_signal(signal.SIGTERM)
        assert flag() and flag.reason == "SIGTERM" and flag.exit_code == 143
        with pytest.raises(StopRequested), flag.interruptible():
            pass  # a pending stop skips the block
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)  # a second Ctrl-C while stopping aborts
        with pytest.raises(KeyboardInterrupt), flag.shielded():  # a save is finished first
            signal.raise_signal(signal.SIGINT)
            saved = True
        assert saved
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    timed = StopFlag(0.05)
    with stop_on_signals(timed), pytest.raises(StopRequested), timed.interruptible():
        signal.pause()  # blocked: only the alarm of the deadline ends it
    assert timed.reason == "time limit" and timed.exit_code == 0
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


def test_a_deferred_part_of_an_interruptible_block_ends_before_the_stop():
    """A stop inside :meth:`StopFlag.deferred` (a trainer starting its env workers) waits
    for the part to end, then raises StopRequested; outside an interruptible block it only
    sets the flag."""
    flag, done = StopFlag(), []
    with stop_on_signals(flag), pytest.raises(StopRequested), flag.interruptible():
        with flag.deferred():
            signal.raise_signal(signal.SIGTERM)
            done.append("made")
        done.append("went on")
    assert done == ["made"] and flag.exit_code == 143
    with flag.deferred():
        pass  # no interruptible block: nothing raised


def test_a_stop_before_a_trainer_is_made_undoes_it_and_one_after_ends_train(tmp_path):
    """A Trainer given the flag its caller's signal handlers set (alphatank train's, from
    its start-up on): a signal that came before it is made raises StopRequested with the
    lock it took released and the folders it made removed; one that comes once it is made
    ends train() as it begins, with a checkpoint to resume from."""
    cfg = config("early", LearnerSpec("ppo", "ppo", (0,), PPO_TINY), 4)
    run = tmp_path / "runs" / "early"
    flag = StopFlag()
    with stop_on_signals(flag):
        signal.raise_signal(signal.SIGTERM)
        with pytest.raises(StopRequested):
            Trainer(cfg, run, progress=False, stop=flag)
    assert not any(tmp_path.iterdir())  # no runs/.early.lock, no runs/
    later = StopFlag()
    tr = Trainer(cfg, run, progress=False, stop=later)
    later.request("SIGTERM", signal.SIGTERM)
    out = tr.train()
    assert out["exit_code"] == 143 and out["stopped"]["reason"] == "SIGTERM"
    assert load_checkpoint(run).meta["progress"]["global_step"] == 0
    assert not (tmp_path / "runs" / ".early.lock").exists()


def kill_a_worker() -> None:
    """SIGKILL one env worker process of this process (as the out-of-memory killer)."""
    worker = multiprocessing.active_children()[0]
    os.kill(worker.pid, signal.SIGKILL)
    worker.join(30)


def test_an_env_worker_that_dies_ends_train_saying_so_and_what_is_kept(tmp_path):
    """An env worker process killed, before a run's first save and in a resumed run:
    train() raises EnvWorkerDied, one line saying what is kept, lock released (the broken
    pipe reached the command's handler for a closed stdout: exit 141 without a word; or a
    traceback whose line told to create the env under ``if __name__ == "__main__"``)."""
    cfg = config("dies", LearnerSpec("ppo", "ppo", (0,), PPO_TINY), 2, num_workers=2)
    run = tmp_path / "dies"
    tr = Trainer(cfg, run, progress=False)
    kill_a_worker()
    with pytest.raises(EnvWorkerDied, match=r"^an env worker process died at step 0 "
                                            r"\(killed\? out of memory\?\); nothing was saved$"):
        tr.train()
    assert not (tmp_path / ".dies.lock").exists() and not multiprocessing.active_children()
    Trainer(dataclasses.replace(cfg, num_workers=1), tmp_path / "done", progress=False).train()
    again = resume_trainer(tmp_path / "done", progress=False, total_steps=4 * 16 * E,
                           num_workers=2)
    kill_a_worker()
    with pytest.raises(EnvWorkerDied, match=f"last checkpoint, step {2 * 16 * E}, is kept: "
                                            f"continue with alphatank train --resume "
                                            f"{tmp_path / 'done'}$"):
        again.train()


# a worker: watches its parent, then runs a job until a stop (like a run), says why it
# ended and waits as a pool worker does for its next job (the job's end ends it); with
# "ignore" it ignores SIGTERM, so only the (short) grace period can end it; with "idle" it
# waits outside a job, so it exits at once
WORKER = """
import pathlib, signal, sys, time
from alphatank.training.stopping import (StopFlag, exit_with_parent, orphaned, running_job,
                                         stop_on_signals)
out = pathlib.Path(sys.argv[1])
exit_with_parent(poll_s=0.05, grace_s=0.5 if sys.argv[2] == "ignore" else 60)
if sys.argv[2] == "idle":
    out.with_suffix(".ready").write_text("ready")
    time.sleep(60)
with running_job():
    if sys.argv[2] == "ignore":
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        out.with_suffix(".ready").write_text("ready")
        time.sleep(60)
    flag = StopFlag()
    with stop_on_signals(flag):
        out.with_suffix(".ready").write_text("ready")
        while not flag():
            time.sleep(0.01)
    out.write_text(f"{flag.reason} orphaned={orphaned()}")
time.sleep(60)  # as a pool worker waits for its next job: the job's end ends it
"""
# the driver: starts a worker, waits until it watches, then dies without waiting for it
DRIVER = """
import pathlib, subprocess, sys, time
ready = pathlib.Path(sys.argv[2]).with_suffix(".ready")
p = subprocess.Popen([sys.executable, "-c", sys.argv[1], sys.argv[2], sys.argv[3]])
while not ready.exists():
    time.sleep(0.01)
print(p.pid)
"""


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"  # a zombie has ended
    except FileNotFoundError:
        return False


def test_a_worker_whose_parent_dies_stops_like_on_sigterm_and_exits_after_its_job(tmp_path):
    with pytest.raises(ValueError, match="poll_s"):
        exit_with_parent(poll_s=0)
    pids = {}
    for mode in ("stop", "ignore", "idle"):
        out = tmp_path / f"{mode}.txt"
        done = subprocess.run([sys.executable, "-c", DRIVER, WORKER, str(out), mode],
                              capture_output=True, text=True, timeout=60, check=True)
        pids[mode] = int(done.stdout)
    deadline = time.monotonic() + 20  # a grace of 60 s, but for "ignore"
    while any(_alive(p) for p in pids.values()) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(_alive(p) for p in pids.values())
    # its run stopped, not killed, and the worker knows why (so it starts no next job); it
    # exited when its job ended
    assert (tmp_path / "stop.txt").read_text() == "SIGTERM orphaned=True"
    assert not (tmp_path / "ignore.txt").exists()


def test_saves_more_often_than_an_episode_lasts_are_warned(tmp_path):
    spec = LearnerSpec("ppo", "ppo", (0,), PPO_TINY)
    with pytest.warns(RunWarning, match=r"checkpoint_every 1 x 16 .* max_steps \(30\).* >= 2"):
        Trainer(config("warn", spec, 1, checkpoint_every=1), tmp_path / "w", progress=False)


def test_a_fresh_run_starts_its_metrics_afresh_and_a_resumed_one_appends(tmp_path):
    """Rows left by a run killed before its first save belong to no checkpoint: a new run
    in that folder must not plot them as its own; a resumed run keeps its rows."""
    path = tmp_path / "metrics.jsonl"
    path.write_text('{"step": 50000, "charts/win_rate": 0.9}\n')
    rows = []
    for resume_step, step in ((None, 16), (16, 32)):  # a fresh run saved at 16, resumed
        logger = RunLogger(tmp_path, {}, "half", wandb_mode="disabled", resume_step=resume_step)
        logger.log({"charts/win_rate": 0.1}, step)
        logger.close()
        rows.append([json.loads(x)["step"] for x in path.read_text().splitlines()])
    assert rows == [[16], [16, 32]]


def test_a_logger_that_wandb_refuses_is_one_line_and_leaves_no_metrics_file(tmp_path):
    """wandb refusing the run (here a run id it cannot take, or a project name; online
    without `wandb login` alike) left ``metrics.jsonl`` open, for the garbage collector to
    close ('unclosed file'); then its error was a traceback (wandb.errors.UsageError) and a
    new run's folder kept an empty metrics.jsonl. It is one InputError line naming wandb's
    mode and cause; the metrics file is made only once wandb has started."""
    for kw, cause in (({"run_id": "bad/id"}, "Run ID cannot contain"),
                      ({"project": "me/tanks"}, "Invalid project name 'me/tanks'")):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ResourceWarning)
            with pytest.raises(InputError, match=f"^wandb offline: {cause}.* \\(--wandb "
                                                 "offline logs without an account\\)$") as info:
                RunLogger(tmp_path, {}, "bad", wandb_mode="offline", **kw)
            gc.collect()
        assert "\n" not in str(info.value)
        assert not (tmp_path / "metrics.jsonl").exists()
        assert not [w for w in caught if "metrics.jsonl" in str(w.message)]


def test_a_wandb_variable_wandb_cannot_read_is_one_line_naming_it(tmp_path, monkeypatch):
    """wandb reads its WANDB_* environment variables whatever mode it is given: a value it
    cannot read (WANDB_MODE=garbage) stopped the run with pydantic's text ('1 validation
    error for Settings | mode | Input should be ...'), naming neither wandb nor the
    variable. It is one InputError line naming the variable and its value."""
    import wandb
    wandb.teardown()  # wandb reads the environment once a process: forget an earlier test's
    monkeypatch.setenv("WANDB_MODE", "garbage")
    with pytest.raises(InputError, match="^wandb offline: the environment's WANDB_MODE="
                                         "'garbage': Input should be 'online', 'offline'.*; "
                                         "unset it or give it a value wandb takes") as info:
        RunLogger(tmp_path, {}, "env", wandb_mode="offline")
    assert "\n" not in str(info.value)
    assert not (tmp_path / "metrics.jsonl").exists()


def test_every_logged_metric_is_finite_and_named_in_the_docs(tmp_path):
    """docs/training.md "Logging" named the losses loosely ('SAC: critic, actor, alpha'),
    so a user looking for them in wandb found none of those names (`losses/qf_loss`...).
    Every key a PPO run (with evaluations) and a SAC run log is now listed there by name."""
    import re
    from pathlib import Path

    docs = Path(__file__).parents[1] / "docs" / "training.md"
    section = docs.read_text(encoding="utf-8").split("## Logging")[1].split("\n## ")[0]
    named = set(re.findall(r"`([a-z_]+/[a-z_/<>]+)`", section))
    for spec in (LearnerSpec("ppo", "ppo", (0,), PPO_TINY), LearnerSpec("sac", "sac", (0,),
                                                                         SAC_TINY)):
        Trainer(config(spec.algo, spec, 2, eval_every=2, eval_games=2),
                tmp_path / spec.algo, progress=False).train()
        text = (tmp_path / spec.algo / "metrics.jsonl").read_text(encoding="utf-8")
        rows = [json.loads(line) for line in text.splitlines()]  # strict: no NaN
        keys = {k for row in rows for k in row} - {"step"}
        assert "eval/win_rate" in keys and "charts/win_rate_vs/aggressive" in keys
        assert all(np.isfinite(v) for row in rows for v in row.values())
        unnamed = {k for k in keys if k not in named
                   and not k.startswith("charts/win_rate_vs/")}
        assert not unnamed, f"{spec.algo} logs {sorted(unnamed)}, not in docs/training.md"


def test_the_progress_bar_shows_no_win_rate_before_an_episode_has_ended(tmp_path, capsys):
    """Before any episode had ended the bar read 'win=nan'; it leaves the win rate out
    until there is one, then shows it."""
    spec = LearnerSpec("ppo", "ppo", (0,), PPO_TINY)
    Trainer(config("bar", spec, 1), tmp_path / "one", progress=True).train()  # 16 of 30 ticks
    first = capsys.readouterr().err
    assert "sps=" in first and "it=1" in first
    assert "win=" not in first and "nan" not in first
    Trainer(config("bar", spec, 3), tmp_path / "three", progress=True).train()
    err = capsys.readouterr().err
    assert "win=0." in err or "win=1." in err


def test_rewind_metrics_drops_rows_after_the_step_and_a_torn_line(tmp_path):
    path = tmp_path / "metrics.jsonl"
    rows = [json.dumps({"step": s, "charts/sps": 1.0}) for s in (10, 20, 30)]
    path.write_text("\n".join(rows) + "\n" + '{"step": 40, "charts/s')
    assert rewind_metrics(path, 20) == 2
    assert [json.loads(x)["step"] for x in path.read_text().splitlines()] == [10, 20]
    assert rewind_metrics(path, 20) == 0
    assert rewind_metrics(tmp_path / "none.jsonl", 5) == 0
