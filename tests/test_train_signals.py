"""``alphatank train`` as a real process: Ctrl-C (SIGINT to the process group, workers
included) and SIGTERM stop it within 5 s with a checkpoint that ``--resume`` continues;
``kill -9`` in the middle of a checkpoint write leaves the previous one intact, and the
resumed run picks it and drops the metrics rows logged after it. A signal during the
start-up ends it in one line with nothing left behind (a new run) or changed (a resumed
one)."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from alphatank.training.checkpoint import DELAY_ENV, load_checkpoint

BASE = ["--wandb", "disabled", "--no-progress", "--total-steps", "100000000"]
PPO = ["--preset", "ppo_vs_aggressive", "--ppo", "num_steps=16,update_epochs=1"]
SAC = ["--preset", "sac_vs_aggressive", "--sac",
       "hidden=32,batch_size=32,start_steps=64,update_after=64,update_every=16,"
       "utd_ratio=0.5,buffer_size=20000"]


def start(runs, name, args, **env) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "alphatank.cli", "train", "--runs", str(runs), "--name", name,
           *args, *BASE]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True, env={**os.environ, **env})


def train(runs, args) -> tuple[int, str]:
    where = [] if "--resume" in args else ["--runs", str(runs)]  # a resumed run's own
    cmd = [sys.executable, "-m", "alphatank.cli", "train", *where, *args,
           "--wandb", "disabled", "--no-progress"]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    return res.returncode, res.stdout + res.stderr


def wait_for(cond, proc: subprocess.Popen, timeout: float = 180.0) -> None:
    end = time.monotonic() + timeout
    while not cond():
        if proc.poll() is not None:
            raise AssertionError(f"train exited early ({proc.returncode}):\n"
                                 f"{proc.communicate()[0]}")
        assert time.monotonic() < end, "timed out waiting for the run"
        time.sleep(0.05)


def rows(run) -> list[dict]:
    path = run / "metrics.jsonl"
    return [json.loads(x) for x in path.read_text().splitlines()] if path.exists() else []


def stop(proc: subprocess.Popen, signum: int, group: bool) -> tuple[float, str]:
    """Send ``signum``; seconds until the process ended, and its output."""
    t = time.monotonic()
    if group:
        os.killpg(proc.pid, signum)
    else:
        proc.send_signal(signum)
    out = proc.communicate(timeout=60)[0]
    print(f"stopped {signal.Signals(signum).name} in {time.monotonic() - t:.2f} s")
    return time.monotonic() - t, out


@pytest.mark.slow
def test_ctrl_c_stops_a_ppo_run_with_workers_and_resume_continues(tmp_path):
    run = tmp_path / "ppo"
    proc = start(tmp_path, "ppo", [*PPO, "--workers", "2", "--num-envs", "4",
                                   "--checkpoint-every", "1000"])
    wait_for(lambda: len(rows(run)) >= 2, proc)
    seconds, out = stop(proc, signal.SIGINT, group=True)  # as Ctrl-C in a terminal
    assert proc.returncode == 130, out
    assert seconds < 5, (seconds, out)
    assert "stopped by SIGINT" in out and f"--resume {run}" in out
    saved = load_checkpoint(run).meta["progress"]["global_step"]
    assert saved > 0 and saved % 64 == 0  # an iteration end (the cut one was dropped)
    code, out = train(tmp_path, ["--resume", str(run), "--total-steps", str(saved + 128)])
    assert code == 0, out
    assert load_checkpoint(run).meta["progress"]["global_step"] == saved + 128


@pytest.mark.slow
def test_sigterm_stops_a_sac_run_inside_its_updates_and_resume_continues(tmp_path):
    run = tmp_path / "sac"
    proc = start(tmp_path, "sac", [*SAC, "--num-envs", "2"])
    wait_for(lambda: len(rows(run)) >= 1, proc)
    time.sleep(0.5)  # inside a later iteration (512 vector steps), updates under way
    seconds, out = stop(proc, signal.SIGTERM, group=False)
    assert proc.returncode == 143, out
    assert seconds < 5, (seconds, out)
    assert "stopped by SIGTERM" in out
    ck = load_checkpoint(run)
    saved = ck.meta["progress"]["global_step"]
    assert ck.meta["progress"]["cut"] > 0 and len(ck.replay("sac")["obs"]) == saved
    assert rows(run)[-1]["step"] == saved  # the cut iteration's own row
    code, out = train(tmp_path, ["--resume", str(run), "--total-steps", str(saved + 64)])
    assert code == 0, out
    # it ends at the planned steps, the total rounded up to whole iterations of 512 x 2
    # env steps, as an uninterrupted run would (its shifted iterations went one past)
    planned = -(-(saved + 64) // (512 * 2)) * 512 * 2
    assert load_checkpoint(run).meta["progress"]["global_step"] == planned > saved


@pytest.mark.slow
def test_kill_9_during_a_checkpoint_write_keeps_the_previous_one(tmp_path):
    run = tmp_path / "k9"
    proc = start(tmp_path, "k9", [*PPO, "--num-envs", "2", "--checkpoint-every", "1"],
                 **{DELAY_ENV: "2"})
    wait_for(lambda: (run / "latest").exists(), proc)
    first = (run / "latest").read_text()
    writing = lambda: [p for p in (run / "checkpoints").iterdir()  # noqa: E731
                       if p.name.startswith(".step_") and ".tmp-" in p.name]
    wait_for(lambda: bool(writing()), proc)  # the second save sleeps in the middle
    os.killpg(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=30)
    assert (run / "latest").read_text() == first
    saved = load_checkpoint(run).meta["progress"]["global_step"]
    assert f"step_{saved:010d}" in first
    assert max(r["step"] for r in rows(run)) > saved  # logged before the killed save
    code, out = train(tmp_path, ["--resume", str(run), "--total-steps", str(saved + 96)])
    assert code == 0, out
    assert "metrics rows logged after that checkpoint dropped" in out
    steps = [r["step"] for r in rows(run)]
    assert steps == sorted(set(steps)) and steps[-1] == saved + 96  # no step twice
    assert not writing()  # the killed save's leftovers are gone


@pytest.mark.slow
def test_a_second_ctrl_c_during_the_stops_save_lets_it_finish(tmp_path):
    """Ctrl-C twice, the second while the stop writes the run's first checkpoint: the save
    is finished, then the run aborts naming that save and how to resume it; it resumes from
    that save and leaves no temporary folder."""
    run = tmp_path / "twice"
    proc = start(tmp_path, "twice", [*PPO, "--num-envs", "2", "--checkpoint-every", "1000"],
                 **{DELAY_ENV: "2"})
    wait_for(lambda: len(rows(run)) >= 1, proc)
    writing = lambda: [p for p in (run / "checkpoints").glob(".step_*.tmp-*")]  # noqa: E731
    os.killpg(proc.pid, signal.SIGINT)
    wait_for(lambda: bool(writing()), proc)  # the save sleeps 2 s in the middle
    seconds, out = stop(proc, signal.SIGINT, group=True)
    assert proc.returncode == 130, out
    assert seconds < 20, (seconds, out)  # the save's 2 s, then the abort
    assert not writing()
    step = load_checkpoint(run).meta["progress"]["global_step"]
    assert step > 0
    assert out.splitlines()[-1] == (f"alphatank train: interrupted after saving step "
                                    f"{step:,}; continue with alphatank train --resume "
                                    f"{run}"), out


@pytest.mark.slow
def test_sigterm_right_after_the_lock_is_taken_undoes_the_start_up(tmp_path):
    """SIGTERM while a new run starts (its folder locked, its env workers starting): one
    line, exit 143, and nothing left: no lock file, no run folder, no shared memory (the
    process was killed silently, leaving runs/.NAME.lock and the workers' shared memory)."""
    proc = start(tmp_path, "early", [*PPO, "--workers", "2", "--num-envs", "2"])
    wait_for(lambda: (tmp_path / ".early.lock").exists(), proc)
    seconds, out = stop(proc, signal.SIGTERM, group=False)
    assert proc.returncode == 143, out
    assert out == "alphatank train: interrupted by SIGTERM during start-up; nothing saved\n"
    assert not any(tmp_path.iterdir())


@pytest.mark.slow
def test_ctrl_c_in_the_start_up_of_a_resumed_run_leaves_it_as_it_was(tmp_path):
    """Ctrl-C while a resumed MAPPO run starts: one line naming the run and how to go on,
    exit 130; its checkpoint and metrics are as they were and its lock is released."""
    code, out = train(tmp_path, ["--preset", "team_vs_def", "--name", "team", "--num-envs",
                                 "2", "--total-steps", "64", "--hp", "mappo.num_steps=16"])
    assert code == 0, out
    run = tmp_path / "team"
    latest, metrics = (run / "latest").read_text(), (run / "metrics.jsonl").read_text()
    proc = subprocess.Popen([sys.executable, "-m", "alphatank.cli", "train", "--resume",
                             str(run), "--total-steps", "128", *BASE[:3]],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    wait_for(lambda: (tmp_path / ".team.lock").exists(), proc)
    seconds, out = stop(proc, signal.SIGINT, group=True)
    assert proc.returncode == 130, out
    # nothing else: the env's fork server, importing torch, does not see the Ctrl-C (it
    # ended with a traceback, and the env it was starting left a shared-memory warning)
    assert out == (f"alphatank train: interrupted by SIGINT during start-up; {run} is as it "
                   f"was; continue with alphatank train --resume {run}\n"), out
    assert (run / "latest").read_text() == latest
    assert (run / "metrics.jsonl").read_text() == metrics
    assert not (tmp_path / ".team.lock").exists()


def fork_server(pid: int) -> bool:
    """Whether process ``pid`` has started its multiprocessing fork server (Linux)."""
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            kids = f.read().split()
    except OSError:
        return False
    for kid in kids:
        try:
            with open(f"/proc/{kid}/cmdline", "rb") as f:
                if b"forkserver" in f.read():
                    return True
        except OSError:
            continue
    return False


@pytest.mark.slow
@pytest.mark.skipif(not os.path.exists(f"/proc/{os.getpid()}/task/{os.getpid()}/children"),
                    reason="needs /proc/PID/task/PID/children")
def test_sigterm_to_the_group_while_the_workers_start_is_a_stop_not_a_traceback(tmp_path):
    """SIGTERM to the process group (``timeout``, a scheduler) as the env workers start:
    it also ends their fork server, which the run took for a failure (an EOFError
    traceback, exit 1); it is the stop: its line, exit 143, nothing left."""
    proc = start(tmp_path, "group", [*PPO, "--workers", "2", "--num-envs", "2"])
    wait_for(lambda: fork_server(proc.pid), proc)  # loading torch before it forks workers
    seconds, out = stop(proc, signal.SIGTERM, group=True)
    assert proc.returncode == 143, out
    assert "alphatank train: interrupted by SIGTERM during start-up; nothing saved" in \
        out.splitlines() and "Traceback" not in out, out
    assert not any(tmp_path.iterdir())
