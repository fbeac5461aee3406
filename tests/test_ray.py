"""``--ray`` on a real Ray cluster on this machine: a head node started with ``ray start
--head`` on 127.0.0.1 serving ``alphatank train --ray ADDRESS``; an in-process instance
(``ray.init``, 2 CPUs) for the env runners (same results as worker processes, the same
weights after the first update, a killed runner restarted and the run finished) and a
2-row experiment as Ray tasks (resumed without redoing finished rows). Without the ray
extra the commands name it."""

from __future__ import annotations

import hashlib
import http.server
import json
import os
import re
import secrets
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

ray = pytest.importorskip("ray")

from alphatank.cli import main  # noqa: E402
from alphatank.cluster import _reachable, connect  # noqa: E402
from alphatank.envs.ray_vector import RayVectorMatchEnv, RolloutLost  # noqa: E402
from alphatank.envs.vector import SubprocVectorMatchEnv  # noqa: E402
from alphatank.training.hparams import PPOConfig  # noqa: E402
from alphatank.training.presets import LearnerSpec, TrainConfig  # noqa: E402
from alphatank.training.runner import Trainer  # noqa: E402

os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
PY = Path(sys.executable).parent
TINY = ["--preset", "ppo_vs_aggressive", "--ppo", "num_steps=16,update_epochs=1",
        "--num-envs", "4", "--wandb", "disabled", "--no-progress", "--checkpoint-every", "0"]


def tiny_cfg(name: str, iterations: int = 1, **kw) -> TrainConfig:
    return TrainConfig(name, "vs_aggressive", total_steps=iterations * 16 * 4, num_envs=4,
                       wandb="disabled", checkpoint_every=0, game={"max_steps": 24},
                       learners=(LearnerSpec("ppo", "ppo", (0,),
                                             config=PPOConfig(num_steps=16, update_epochs=1)),),
                       **kw)


def weights(trainer: Trainer) -> str:
    h = hashlib.sha256()
    for name, lr in sorted(trainer.learners.items()):
        for key, t in sorted(lr.state_dict()["net"].items()):
            h.update(f"{name}.{key}".encode() + t.numpy().tobytes())
    return h.hexdigest()


# `ray stop` (the head-node test) stops every Ray process on the host, so all Ray tests
# must share one pytest-xdist worker: pyproject's addopts say `--dist loadfile`


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_train_through_a_head_node_started_with_ray_start(tmp_path):
    port = free_port()
    # token authentication on, with a token of this test's own (docs/distributed.md)
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token",
           "RAY_AUTH_TOKEN": secrets.token_hex(16)}
    start = subprocess.run(
        [str(PY / "python"), "-m", "ray.scripts.scripts", "start", "--head",
         "--node-ip-address", "127.0.0.1", "--port", str(port), "--num-cpus", "2",
         "--include-dashboard", "false", "--disable-usage-stats"],
        capture_output=True, text=True, timeout=120, env=env)
    try:
        assert start.returncode == 0, start.stdout + start.stderr
        res = subprocess.run([sys.executable, "-m", "alphatank.cli", "train", "--runs",
                              str(tmp_path), "--name", "head", *TINY, "--total-steps", "128",
                              "--ray", f"127.0.0.1:{port}", "--env-runners", "2",
                              "--env-runner-timeout", "30"],
                             capture_output=True, text=True, timeout=180, env=env)
        out = res.stdout + res.stderr
        assert res.returncode == 0, out
        assert re.search(rf"ray: joined the Ray cluster at [\d.]+:{port} \(1 node\(s\), 2 CPUs\)",
                         out), out
        assert "run " in out and "128 steps" in out
        assert (tmp_path / "head" / "latest").is_file()
    finally:
        subprocess.run([str(PY / "python"), "-m", "ray.scripts.scripts", "stop", "--force"],
                       capture_output=True, timeout=120, env=env)


def test_a_wrong_address_is_one_line(tmp_path):
    res = subprocess.run([sys.executable, "-m", "alphatank.cli", "train", "--runs",
                          str(tmp_path), *TINY, "--ray", f"127.0.0.1:{free_port()}"],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    last = res.stderr.strip().splitlines()[-1]
    assert last.startswith("alphatank train: error: --ray 127.0.0.1:") and "ray start" in last


def test_a_port_that_is_not_rays_or_no_port_is_one_line_at_once(tmp_path, capsys):
    """A web server (the dashboard's 8265 by mistake) kept Ray retrying for minutes; an
    empty host printed Ray's traceback."""
    class Quiet(http.server.BaseHTTPRequestHandler):
        def log_message(self, *args) -> None:
            pass

    server = http.server.HTTPServer(("127.0.0.1", 0), Quiet)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        for address, says in [(f"127.0.0.1:{server.server_port}", "not a Ray cluster's"),
                              (":6379", "not HOST:PORT")]:
            t0 = time.monotonic()
            assert main(["train", "--runs", str(tmp_path), *TINY, "--ray", address]) == 2
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and says in err[0] and time.monotonic() - t0 < 30, err
            assert not ray.is_initialized() and not any(tmp_path.iterdir())
    finally:
        server.shutdown()


def test_an_env_runner_timeout_without_ray_is_one_line(tmp_path, capsys):
    """(A bad value is a usage error: test_train_cli's
    test_bad_counts_are_usage_errors_before_anything_runs.)"""
    assert main(["train", "--runs", str(tmp_path), *TINY, "--env-runner-timeout", "5"]) == 2
    assert "--env-runner-timeout: needs --ray" in capsys.readouterr().err.strip().splitlines()[-1]
    assert not any(tmp_path.iterdir())  # nothing written


@pytest.fixture(scope="module")
def cluster():
    before = signal.getsignal(signal.SIGTERM)
    conn = connect(num_cpus=2)
    assert conn.local and conn.cpus == 2
    _reachable(conn.address)  # the GCS port passes the probe of --ray ADDRESS
    yield conn
    conn.close()
    assert not ray.is_initialized()
    assert signal.getsignal(signal.SIGTERM) == before  # ray.init's handler is gone


def test_env_runners_match_worker_processes_and_a_killed_one_comes_back(cluster):
    kw = {"game_overrides": {"max_steps": 20}, "inputs": ("alive",)}
    rv = RayVectorMatchEnv("vs_aggressive", 5, seed=3, num_runners=2, **kw)
    sv = SubprocVectorMatchEnv("vs_aggressive", 5, seed=3, num_workers=2, **kw)
    rng = np.random.default_rng(0)
    try:
        for env in (rv, sv):
            env.set_opponents(["random", "dodge"], weakness=0.5)
            env.add_opponent("r", "random")
            env.add_opponent("d", "dodge")
            env.set_env_opponents(["r", None, "d", None, "r"])

        def same_steps(n: int) -> int:
            ended = 0
            for _ in range(n):
                act = np.stack([rng.integers(0, k, (5, 1)) for k in (3, 3, 2)], -1)
                a, b = rv.step(act), sv.step(act)
                for x, y in zip(a[:4], b[:4], strict=True):
                    np.testing.assert_array_equal(x, y)
                np.testing.assert_array_equal(a[4]["final_obs"], b[4]["final_obs"])
                np.testing.assert_array_equal(a[4]["final_inputs"]["alive"],
                                              b[4]["final_inputs"]["alive"])
                np.testing.assert_array_equal(rv.inputs["alive"], sv.inputs["alive"])
                assert [e["opponent"] for e in a[4]["episodes"]] == \
                    [e["opponent"] for e in b[4]["episodes"]]
                ended += len(a[4]["episodes"])
            return ended

        np.testing.assert_array_equal(rv.reset(7), sv.reset(7))
        assert same_steps(45) >= 5  # several episodes ended (and reset) on both
        pid = ray.get(rv.runners[1].pid.remote())
        os.kill(pid, signal.SIGKILL)
        act = np.ones((5, 1, 3), np.int64)
        with pytest.raises(RolloutLost, match=r"env runner 1 \(envs 2-4\) was lost .*Ray "
                                              r"restarted it \(restart 1, max_restarts=3\)"):
            rv.step(act)
        assert rv.restarts == [0, 1] and rv.lost_rollouts == 1
        assert ray.get(rv.runners[1].pid.remote()) != pid  # a new process
        with pytest.raises(RuntimeError, match="step"):
            rv.step(act)  # the matches must be reset first
        # the restarted runner has its opponent settings back: the same games again
        np.testing.assert_array_equal(rv.reset(11), sv.reset(11))
        assert same_steps(30) >= 1
        # killed between calls and back before the next: the runner itself says it lost
        # its matches, and the note names that (it read 'RayTaskError(RolloutLost)')
        pid = ray.get(rv.runners[1].pid.remote())
        os.kill(pid, signal.SIGKILL)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                if ray.get(rv.runners[1].pid.remote()) != pid:
                    break
            except ray.exceptions.RayActorError:
                time.sleep(0.1)
        with pytest.raises(RolloutLost, match=r"env runner 1 \(envs 2-4\) was lost \(it died "
                                              r"between calls\); Ray restarted it \(restart 2,"):
            rv.step(act)
    finally:
        rv.close()
        sv.close()


def test_benched_seats_reach_the_env_runners_and_come_back_after_a_restart(cluster):
    rv = RayVectorMatchEnv("team_vs_def_smart", 2, seed=0, num_runners=2,
                           observation="egocentric_nearest")
    try:
        with pytest.raises(ValueError, match="cannot bench seats"):
            rv.set_benched([1])
        rv.set_benched([2, 4])
        alive = [rv.layout[f"tank[{k}].alive"].start for k in range(4)]
        # each learner: its mate, then the one enemy in play, then the two absent ones
        benched = [[[1.0, 1.0, 0.0, 0.0]] * 2] * 2
        assert rv.reset()[..., alive].tolist() == benched
        os.kill(ray.get(rv.runners[0].pid.remote()), signal.SIGKILL)
        with pytest.raises(RolloutLost):
            rv.step(np.zeros((2, 2, 3), np.int64))
        assert rv.reset()[..., alive].tolist() == benched  # the setting was replayed
        rv.set_benched([])
        assert rv.reset()[..., alive].tolist() == [[[1.0] * 4] * 2] * 2
    finally:
        rv.close()


def test_first_update_has_the_same_weights_as_with_local_workers(cluster, tmp_path):
    local = Trainer(tiny_cfg("local", num_workers=2), tmp_path / "local", progress=False)
    local.train()
    remote = Trainer(tiny_cfg("ray"), tmp_path / "ray", progress=False, env_runners=2)
    remote.train()
    assert local.learners["ppo"].updates == remote.learners["ppo"].updates == 1
    assert weights(local) == weights(remote)
    alone = Trainer(tiny_cfg("one"), tmp_path / "one", progress=False)  # one process
    alone.train()
    assert weights(alone) == weights(local)


@pytest.mark.slow
def test_fragments_on_env_runners_match_worker_processes_and_a_lost_one(cluster):
    from test_fragments import frozen

    kw = {"game_overrides": {"max_steps": 20}}
    rv = RayVectorMatchEnv("team_vs_bot", 5, seed=3, num_runners=2, **kw)
    sv = SubprocVectorMatchEnv("team_vs_bot", 5, seed=3, num_workers=2, **kw)
    policy = frozen(sv)

    def same_fragments(seed: int) -> None:
        a = rv.rollout(policy, rv.reset(seed), 30)
        b = sv.rollout(policy, sv.reset(seed), 30)
        for name in ("obs", "actions", "logprobs", "values", "rewards", "terminated",
                     "truncated", "bootstrap", "next_obs"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert [(e["step"], e["env"]) for e in a.episodes] == \
            [(e["step"], e["env"]) for e in b.episodes] and len(a.episodes) >= 5

    try:
        same_fragments(7)
        rv.rollout_start(policy, rv.reset(7), 30)  # what waits for a rollout in flight
        for name, call in {"set_bot_weakness": lambda: rv.set_bot_weakness(0.5),
                           "reset": rv.reset,
                           "step": lambda: rv.step(np.ones((5, 2, 3), np.int64))}.items():
            with pytest.raises(RuntimeError, match=rf"^{name}\(\) while a rollout is in"):
                call()
        assert rv.rollout_finish().steps == 30
        os.kill(ray.get(rv.runners[0].pid.remote()), signal.SIGKILL)
        with pytest.raises(RolloutLost, match=r"env runner 0 \(envs 0-1\) was lost"):
            rv.rollout(policy, np.zeros((5, 2, rv.obs_dim), np.float32), 30)
        assert rv.lost_rollouts == 1
        same_fragments(8)  # after a reset the restarted runner plays the same games
    finally:
        rv.close()
        sv.close()


@pytest.mark.parametrize("overlap", [False, True])
@pytest.mark.slow
def test_a_run_in_fragments_on_env_runners_is_the_one_on_worker_processes(cluster, tmp_path,
                                                                          overlap):
    local = Trainer(tiny_cfg("local", iterations=3, num_workers=2), tmp_path / "local",
                    progress=False, fragments=True, overlap=overlap)
    local.train()
    remote = Trainer(tiny_cfg("ray", iterations=3), tmp_path / "ray", progress=False,
                     env_runners=2, fragments=True, overlap=overlap)
    remote.train()
    assert remote.learners["ppo"].updates == 3
    assert weights(local) == weights(remote)


@pytest.mark.slow
def test_a_hung_env_runner_is_killed_and_restarted(cluster):
    env = RayVectorMatchEnv("vs_aggressive", 4, seed=3, num_runners=2, step_timeout_s=1.5)
    try:
        env.set_opponents(["dodge"])
        obs = env.reset(5)
        act = np.ones((4, 1, 3), np.int64)
        env.step(act)
        pid = ray.get(env.runners[0].pid.remote())
        os.kill(pid, signal.SIGSTOP)  # a real hang: the process stops answering
        t0 = time.monotonic()
        with pytest.raises(RolloutLost, match=r"env runner 0 \(envs 0-1\) was lost \(hung: no "
                                              r"answer within 1.5 s, killed\); Ray restarted "
                                              r"it \(restart 1, max_restarts=3\)"):
            env.step(act)
        assert time.monotonic() - t0 < 60
        assert env.restarts == [1, 0] and env.lost_rollouts == 1
        assert ray.get(env.runners[0].pid.remote()) != pid
        np.testing.assert_array_equal(env.reset(5), obs)  # settings replayed: same games
        assert env.step(act)[0].shape == obs.shape
    finally:
        env.close()


def test_a_run_goes_on_when_an_env_runner_is_killed(cluster, tmp_path, capsys):
    holder: dict = {}
    calls = [0]

    def kill_once(obs: np.ndarray) -> np.ndarray:  # the action-mask hook runs every step
        calls[0] += 1
        if calls[0] == 20:  # inside the second iteration (16 steps each)
            env = holder["trainer"].env
            os.kill(ray.get(env.runners[0].pid.remote()), signal.SIGKILL)
        return np.ones((*obs.shape[:2], 8), dtype=bool)

    trainer = Trainer(tiny_cfg("kill", iterations=3), tmp_path / "kill", progress=False,
                      env_runners=2, action_mask=kill_once)
    holder["trainer"] = trainer
    summary = trainer.train()
    assert summary["global_step"] == 3 * 64 and trainer.iteration == 3
    assert trainer.lost_rollouts == 1 and trainer.learners["ppo"].updates == 3
    assert len(summary["notes"]) == 1
    note = summary["notes"][0]
    assert note.startswith("iteration 2: env runner 0 (envs 0-1) was lost") and \
        "Ray restarted it (restart 1, max_restarts=3)" in note
    assert note.endswith("the rollout in flight (12 steps) was dropped and is collected again")
    assert note in capsys.readouterr().err
    rows = [json.loads(x) for x in (tmp_path / "kill" / "metrics.jsonl").read_text().splitlines()]
    assert {"step": 64, "charts/lost_rollouts": 1.0} in rows
    assert [r["step"] for r in rows if "charts/sps" in r] == [64, 128, 192]


def kill_first(title: str, killed: list[int], stop: threading.Event) -> None:
    """SIGKILL the first process whose title starts with ``title`` (a Ray worker running
    that task), once."""
    while not stop.is_set():
        for proc in Path("/proc").iterdir():
            try:
                if proc.name.isdigit() and (proc / "cmdline").read_bytes().startswith(
                        title.encode()):
                    os.kill(int(proc.name), signal.SIGKILL)
                    killed.append(int(proc.name))
                    return
            except OSError:
                continue
        time.sleep(0.02)


@pytest.mark.slow
def test_two_row_experiment_as_ray_tasks_and_resume(cluster, tmp_path, capsys):
    from test_experiments import write_rows

    root = write_rows(tmp_path / "exp")
    out = tmp_path / "out"
    args = ["experiments", "tiny", "--experiments-dir", str(root), "--out", str(out),
            "--steps", "256", "--games", "2", "--budget", "2", "--no-progress", "--ray"]
    killed: list[int] = []
    stop = threading.Event()
    killer = threading.Thread(target=kill_first, args=("ray::train_task", killed, stop))
    killer.start()
    try:
        assert main(args) == 0  # the killed training task was retried (max_retries)
    finally:
        stop.set()
        killer.join()
    assert len(killed) == 1
    text = capsys.readouterr().out
    assert "2 runs, 2 to do" in text and "with Ray (2 CPUs)" in text
    assert text.count(" seed 0: done") == 2  # progress, one line per finished row
    runs = sorted((out / "runs").iterdir())
    assert len(runs) == 2 and all((r / "done.json").is_file() for r in runs)
    assert all(len(list((r / "eval").glob("*.json"))) == 2 for r in runs)
    data = json.loads((out / "tiny.json").read_text())
    assert not data["missing"] and data["rows"][1]["columns"]["dodge"]["per_seed"]
    # resume: one evaluation missing; nothing finished is redone
    done = {p: p.stat().st_mtime_ns for p in out.glob("runs/*/done.json")}
    evals = sorted(out.glob("runs/*/eval/*.json"))
    evals[0].unlink()
    kept = {p: p.stat().st_mtime_ns for p in evals[1:]}
    assert main([*args, "--resume"]) == 0
    assert "2 runs, 1 to do" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in done} == done
    assert {p: p.stat().st_mtime_ns for p in kept} == kept and evals[0].is_file()


def test_ctrl_c_stops_an_experiment_on_ray_at_once(cluster, tmp_path, capsys):
    """Ray's wait ran the handler only when a task ended (here after the 1-minute budget)
    and then raised a SystemError traceback."""
    from test_experiments import write_rows

    args = ["experiments", "tiny", "--experiments-dir", str(write_rows(tmp_path / "exp")),
            "--out", str(tmp_path / "out"), "--steps", "100000", "--games", "2", "--budget",
            "1", "--no-progress", "--ray"]
    threading.Timer(4, os.kill, (os.getpid(), signal.SIGINT)).start()
    t0 = time.monotonic()
    assert main(args) == 130
    assert time.monotonic() - t0 < 30
    assert "interrupted: finished runs and evaluations are kept" in capsys.readouterr().err
    assert not list((tmp_path / "out").glob("runs/*/done.json"))


HIDE_RAY = "import sys; sys.modules['ray'] = None; from alphatank.cli import main; " \
           "raise SystemExit(main(sys.argv[1:]))"


@pytest.mark.parametrize("verb", [["train", *TINY, "--ray"],
                                  ["experiments", "table4", "--ray", "--steps", "64"]])
def test_without_the_extra_the_commands_say_how_to_install_it(tmp_path, verb):
    res = subprocess.run([sys.executable, "-c", HIDE_RAY, *verb, "--out" if
                          verb[0] == "experiments" else "--runs", str(tmp_path)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    assert res.stderr.strip().splitlines()[-1] == (
        f"alphatank {verb[0]} --ray needs the 'ray' extra: pip install 'alphatank[ray]'")
    assert "Traceback" not in res.stderr


def test_without_ray_flag_ray_is_never_imported(tmp_path):
    code = ("import sys; from alphatank.cli import main; rc = main(sys.argv[1:]); "
            "assert 'ray' not in sys.modules, 'ray was imported'; raise SystemExit(rc)")
    res = subprocess.run([sys.executable, "-c", code, "train", "--runs", str(tmp_path), *TINY,
                          "--total-steps", "64", "--workers", "2"],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "64 steps" in res.stdout
