"""Every CLI verb against bad arguments and bad files: a non-zero exit, one error line that
names the file or field (and what is allowed), and never a traceback.

The matrix is data: add a verb's cases to ``CASES`` (argv with ``{name}`` placeholders for
the files of the ``files`` fixture, then fragments the error line must contain). Most
cases run in-process through ``alphatank.cli.main`` / ``tools/mapgen.py``'s ``main``; a
few run as real subprocesses (pipes, exit statuses, the interpreter's own error output).
"""

from __future__ import annotations

import importlib.util
import io
import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from alphatank.cli import main
from alphatank.game.seats import agent_path
from alphatank.training.ppo import PPOConfig
from alphatank.training.presets import LearnerSpec, TrainConfig
from alphatank.training.runner import Trainer
from alphatank.ui.replay import ReplayRecorder, content_digest, save_replay

ROOT = Path(__file__).resolve().parents[1]
GOOD_MAP = "name: m\n\n#####\n#1..#\n#.#.#\n#..2#\n#####\n"
SCENARIO = ('name = "t"\nmap = "open"\n[[seats]]\nteam = "A"\ncontroller = "learner"\n'
            '[[seats]]\nteam = "B"\ncontroller = "bot"\nbot = "random"\n')


def _spec() -> object:
    spec = importlib.util.spec_from_file_location("mapgen_tool", ROOT / "tools" / "mapgen.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


MAPGEN = _spec()


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, str]:
    """Bad files of every kind, and a few good ones to spoil."""
    d = tmp_path_factory.mktemp("bad")
    out: dict[str, str] = {"dir": str(d), "missing": str(d / "nope.txt")}

    def put(name: str, data: bytes | str) -> None:
        p = d / name
        p.write_bytes(data if isinstance(data, bytes) else data.encode("utf-8"))
        out[name.replace(".", "_")] = str(p)

    put("empty.txt", b"")
    put("longgame.toml", 'name = "long"\nmap = "battlefield"\n[game]\ntick_hz = 1\n'
                         'bullet_speed = 10000.0\nmax_steps = 15300\n[[seats]]\nteam = "A"\n'
                         'controller = "bot"\nbot = "random"\n[[seats]]\nteam = "B"\n'
                         'controller = "bot"\nbot = "random"\n')
    put("nulteam.toml", 'name = "nul"\nmap = "open"\n[[seats]]\nteam = "A\\u0000"\n'
                        'controller = "bot"\nbot = "smart"\n[[seats]]\nteam = "B"\n'
                        'controller = "bot"\nbot = "random"\n')
    put("nbspteam.toml", SCENARIO.replace('team = "A"', 'team = "A\\u00a0B"'))
    put("binary.txt", bytes(range(256)) * 4)
    put("latin1.txt", "name: caf\xe9\n\n#####\n#1.2#\n#####\n".encode("latin-1"))
    put("utf16.txt", "name: x\n\n#####\n#1.2#\n#####\n".encode("utf-16"))
    put("cellinf.txt", "cell: inf\n\n#####\n#1.2#\n#####\n")
    put("cellsmall.txt", "cell: 0.001\n\n#####\n#1.2#\n#####\n")
    put("noroom.txt", "#####\n#1.+#\n###4#\n#####\n")
    put("good.txt", GOOD_MAP)
    put("small.txt", "#####\n#1.2#\n#####\n")
    put("empty.toml", b"")
    put("binary.toml", bytes(range(256)))
    put("ff.toml", SCENARIO + '[game]\nfriendly_fire = "no"\n')
    put("steps.toml", SCENARIO + "[game]\nmax_steps = true\n")
    put("victory.toml", SCENARIO + "[rewards]\nvictory = nan\n")
    put("botopt.toml", SCENARIO.replace('bot = "random"', 'bot = "random"\n'
                                        'options = { hold_min = 2.5 }'))
    put("ckptseat.toml", SCENARIO.replace('controller = "bot"\nbot = "random"',
                                          'controller = "checkpoint"\npath = "gone"'))
    put("syntax.toml", "x = [\n")
    put("runsteps.toml", 'scenario = "vs_random"\ntotal_steps = "many"\n')
    put("rungamma.toml", 'scenario = "vs_random"\n[[learners]]\nname = "p"\n'
                         '[learners.config]\ngamma = 3\n')
    run = 'scenario = "vs_random"\n'
    put("runscenario.toml", 'scenario = "vs_nobody"\n')
    put("rungame.toml", 'scenario = "vs_random"\n[game]\nmax_steps = -1\n')
    put("runseats.toml", 'scenario = "vs_random"\n[[learners]]\nname = "p"\nseats = [5]\n')
    put("runsched.toml", 'scenario = "pair"\n[schedule]\nkind = "curriculum"\n')
    put("rundecay.toml", 'scenario = "vs_random"\n[rewards]\nteam_win_time_decay = 2\n')
    put("rundraw.toml", 'scenario = "vs_random"\n[rewards]\nteam_draw = 5\nteam_loss = -5\n')
    put("runname.toml", 'name = "../../escaped"\nscenario = "vs_random"\n')
    put("runmap.toml", run + 'map = "nowhere"\n')
    put("rundesc.toml", run + 'description = "two\\nlines"\n')
    put("descnl.toml", SCENARIO.replace('map = "open"', 'description = "a\\tb"\nmap = "open"'))
    put("runinit.toml", run + 'init_from = "agent:nobody"\n')
    put("runobs.toml", run + 'observation = "egocentric_fulll"\n')
    put("runimitate.toml", run + 'imitate = { bot = "smrt" }\n')
    put("runimitatekey.toml", run + 'imitate = { bot = "smart", stepz = 10 }\n')
    put("runpool.toml", run + '[schedule]\nkind = "cycle"\npool = ["nosuch"]\n')
    put("empty.npz", b"")
    put("binary.npz", bytes(range(256)) * 8)
    (d / "emptydir").mkdir()
    out["emptydir"] = str(d / "emptydir")
    for name, latest in (("latest_empty", b""), ("latest_binary", bytes(range(256)))):
        (d / name).mkdir()
        (d / name / "latest").write_bytes(latest)
        out[name] = str(d / name)

    # A real replay, then spoiled copies.
    from alphatank.game.lineup import build_lineup
    from alphatank.game.scenarios import seats_scenario

    lineup = build_lineup(seats_scenario("smart,random", "open", {"max_steps": 60}))
    rec = ReplayRecorder()  # an episode hook: seeds and the bots' routes from the episode
    lineup.play(1, [rec])
    replay = rec.replay
    assert replay is not None and (replay.routes[..., 0] >= 0).any()
    good = save_replay(replay, d / "good.npz")
    out["good_npz"] = str(good)
    out["replay_as_gif"] = str(shutil.copy(good, d / "replay.gif"))  # a replay named .gif
    raw = good.read_bytes()
    put("truncated.npz", raw[: len(raw) // 2])
    flipped = bytearray(raw)
    with zipfile.ZipFile(good) as z:
        info = z.getinfo("actions.npy")
    head = info.header_offset
    name_len, extra_len = (int.from_bytes(raw[head + k:head + k + 2], "little") for k in (26, 28))
    flipped[head + 30 + name_len + extra_len + info.compress_size // 2] ^= 0xFF  # deflate data
    put("flipped.npz", bytes(flipped))

    def spoiled(name: str, redigest: bool = False, **meta_changes: object) -> None:
        """A copy of the good replay with ``meta_changes``; ``redigest``: with the digest
        of the changed content (anyone can compute it; it is no signature)."""
        with np.load(good) as z:
            arrays = {k: z[k] for k in z.files}
        meta = json.loads(arrays.pop("meta").tobytes())
        meta.update(meta_changes)
        if redigest:
            meta["digest"] = content_digest(meta, arrays)
        blob = np.frombuffer(json.dumps(meta).encode(), np.uint8)
        np.savez_compressed(d / name, meta=blob, **arrays)
        out[name.replace(".", "_")] = str(d / name)

    spoiled("v1.npz", version=1)
    spoiled("v3.npz", version=3)  # from a newer AlphaTank
    spoiled("seed.npz", match_seed=-5)
    spoiled("teamsnull.npz", teams=None)
    spoiled("teamsAA.npz", teams=["A", "A"])
    spoiled("winner.npz", winner="B" if replay.winner != "B" else "A")
    spoiled("fast.npz", config={**replay.config, "bullet_speed": 3e9})
    spoiled("maptext.npz", map_text=replay.map_text + "\n; an edit the simulation ignores\n")
    spoiled("teamnul.npz", teams=["A\x00", *replay.teams[1:]])
    spoiled("longlabel.npz", labels=["y" * 5000, "z"])
    spoiled("escscenario.npz", True, scenario="vs\n\x1b[31mred")  # printed in the header
    spoiled("longmapname.npz", True, map_name="m" * 5000)
    # A 6 TiB array declared in 1 KB: an .npy header's shape, then 100 bytes of data.
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(d / "bomb.npz", "w") as dst:
        for item in src.infolist():
            if item.filename != "actions.npy":
                dst.writestr(item, src.read(item))
        head = io.BytesIO()
        np.lib.format.write_array_header_1_0(
            head, {"descr": "|i1", "fortran_order": False, "shape": (2**40, 2, 3)})
        dst.writestr("actions.npy", head.getvalue() + bytes(100))
    out["bomb_npz"] = str(d / "bomb.npz")

    # A real (untrained) checkpoint, then spoiled copies.
    cfg = TrainConfig(name="ck", scenario="vs_aggressive", total_steps=64, num_envs=2,
                      num_workers=1, seed=0, wandb="disabled", checkpoint_every=0,
                      game={"max_steps": 30},
                      learners=(LearnerSpec("ppo", "ppo", (0,),
                                            PPOConfig(num_steps=16, update_epochs=1)),))
    trainer = Trainer(cfg, d / "run", progress=False)
    ckpt = trainer.save()
    trainer.env.close()
    out["run"], out["ckpt"] = str(d / "run"), str(ckpt)

    def ckpt_copy(name: str) -> Path:
        dst = d / name
        shutil.copytree(ckpt, dst)
        out[name] = str(dst)
        return dst

    meta = json.loads((ckpt / "meta.json").read_text())
    bad = ckpt_copy("ckpt_v99")
    (bad / "meta.json").write_text(json.dumps({**meta, "version": 99}))
    bad = ckpt_copy("ckpt_cut")
    (bad / "meta.json").write_text((ckpt / "meta.json").read_text()[:200])
    bad = ckpt_copy("ckpt_objdim")
    (bad / "meta.json").write_text(json.dumps(
        {**meta, "observation": {**meta["observation"], "obs_dim": "abc"}}))
    for name, edit in (("ckpt_windows", {"windows": 5}),
                       ("ckpt_outcomes", {"windows": {"outcomes": {"nobody": [1.0]}}}),
                       ("ckpt_progress_cut", {"progress": {**meta["progress"], "cut": "x"}})):
        (ckpt_copy(name) / "meta.json").write_text(json.dumps({**meta, **edit}))
    (ckpt_copy("ckpt_noprogress") / "meta.json").write_text(json.dumps(
        {k: v for k, v in meta.items() if k != "progress"}))
    ckpt_copy("ckpt_loose")  # a good save, copied out of its run
    bad = d / "nanrun" / "checkpoints" / ckpt.name  # resumable: a save inside a run
    shutil.copytree(ckpt, bad)
    (d / "nanrun" / "latest").write_text(f"checkpoints/{ckpt.name}\n")
    out["ckpt_nan"] = str(bad)
    state = torch.load(bad / "ppo.pt", weights_only=True)
    first = next(k for k, v in state["net"].items() if v.is_floating_point())
    state["net"][first][0] = float("nan")
    torch.save(state, bad / "ppo.pt")
    from alphatank.training.checkpoint import _sha256

    (bad / "meta.json").write_text(json.dumps(
        {**meta, "files": {"ppo.pt": _sha256(bad / "ppo.pt")}}))
    out["nan_tensor"] = f"net.{first}"
    (d / "runs_empty").mkdir()
    out["runs_empty"] = str(d / "runs_empty")
    later = d / "later" / "checkpoints"  # a run with a save after the one resumed
    shutil.copytree(d / "run", d / "later")
    shutil.copytree(ckpt, later / "step_0000000099")
    out["ckpt_earlier"] = str(later / ckpt.name)
    out["agent_dir"] = agent_path("ppo_vs_smart")
    return out


# (id, argv, fragments the one error line must contain). {name} -> files[name].
CASES = [
    # top level
    ("no-verb", [], ["VERB"]),
    ("unknown-verb", ["fly"], ["invalid choice", "maps"]),
    # maps
    ("maps-missing", ["maps", "{missing}"], ["{missing}", "no such map file"]),
    ("maps-empty", ["maps", "{empty_txt}"], ["{empty_txt}", "empty map"]),
    ("maps-binary", ["maps", "{binary_txt}"], ["{binary_txt}", "UTF-8"]),
    ("maps-latin1", ["maps", "{latin1_txt}"], ["{latin1_txt}", "UTF-8"]),
    ("maps-utf16", ["maps", "{utf16_txt}"], ["{utf16_txt}", "UTF-16"]),
    ("maps-cell-inf", ["maps", "{cellinf_txt}"], ["{cellinf_txt}:1", "'cell'", "[39, 400]"]),
    ("maps-cell-tiny", ["maps", "{cellsmall_txt}"], ["{cellsmall_txt}:1", "'cell'"]),
    ("maps-no-room", ["maps", "{noroom_txt}"], ["{noroom_txt}:3", "only 3 tank(s) fit"]),
    ("maps-folder", ["maps", "{emptydir}"], ["{emptydir}: folder holds no .txt maps"]),
    ("maps-empty-path", ["maps", ""], ["''", "empty map name or path"]),
    ("maps-wrong-kind", ["maps", "{good_npz}"], ["{good_npz}", "UTF-8"]),
    ("maps-device", ["maps", os.devnull], [f"{os.devnull}: not a file (a device or pipe)"]),
    # bench
    ("bench-map", ["bench", "--map", "{missing}"], ["--map: {missing}: no such map file"]),
    ("bench-map-unknown", ["bench", "--map", "nowhere"],
     ["bench: error: --map: nowhere: unknown map 'nowhere'", "battlefield"]),
    ("bench-map-room", ["bench", "--ticks", "10", "--repeats", "1", "--map", "{small_txt}"],
     ["--map", "'small' has room for 3 tanks", "4v4 (8 tanks)"]),
    ("bench-json-folder", ["bench", "--json", "{dir}"], ["--json", "is a folder"]),
    ("bench-ticks", ["bench", "--ticks", "many"], ["--ticks", "integer in [1, ", "'many'"]),
    ("bench-preset", ["bench", "--preset", "fast"],
     ["--preset: unknown preset 'fast'", "long_range"]),
    ("bench-ticks-huge", ["bench", "--ticks", "1000000000000"],
     ["argument --ticks", "integer in [1, 1000000]"]),
    ("bench-steps-no-soak", ["bench", "--steps", "100000"],
     ["--steps: an option of --soak; add --soak"]),
    ("bench-train-option", ["bench", "--train-fragments"],
     ["--train-fragments: an option of --train; add --train"]),
    ("bench-soak-env", ["bench", "--soak", "--env"], ["--env: not an option of --soak"]),
    ("bench-train-threads", ["bench", "--train", "--train-threads", "100000"],
     ["argument --train-threads", "[1, 1024]"]),
    ("bench-soak-train-option", ["bench", "--soak", "--train-workers", "4"],
     ["--train-workers: not an option of --soak"]),
    ("bench-train-envs", ["bench", "--train", "--train-envs", "5000"],
     ["argument --train-envs", "integer in [1, 4096]", "'5000'"]),
    ("bench-soak-scn", ["bench", "--soak", "--scenarios", "nosuch"],
     ["nosuch", "shipped scenarios"]),
    ("bench-soak-twice", ["bench", "--soak", "--scenarios", "vs_random,team,vs_random",
                          "--steps", "2"], ["--scenarios: 'vs_random' is given twice"]),
    ("bench-soak-bots", ["bench", "--soak", "--scenarios", "bot_teams"],
     ["bot_teams", "no learner seat"]),
    ("bench-soak-steps", ["bench", "--soak", "--steps", "2"],
     ["--steps must be >= 30003 with --sample-every 10000 and 3 scenario(s)", "got 2"]),
    ("bench-soak-every", ["bench", "--soak", "--sample-every", "0"], ["--sample-every", ">= 1"]),
    # arena
    ("arena-bot", ["arena", "--bots", "smart,genius"], ["genius", "valid bots"]),
    ("arena-bot-option", ["arena", "--bots", "smart:ricochet=maybe,random"],
     ["ricochet", "true or false"]),
    ("arena-map", ["arena", "--map", "{binary_txt}"], ["{binary_txt}", "UTF-8"]),
    ("arena-map-unknown", ["arena", "--map", "nowhere"],
     ["arena: error: --map: unknown map 'nowhere'", "battlefield", "folder of maps"]),
    ("arena-games", ["arena", "--games", "0"], ["--games", ">= 1"]),
    ("arena-fps-no-render", ["arena", "--seats", "smart,random", "--fps", "30"],
     ["arena: error: --fps is the frame rate of --render's window; give --render with it"]),
    ("arena-render-dummy", ["arena", "--render", "--seats", "smart,random", "--games", "1",
                            "--max-steps", "5"],
     ["arena: error: --render: SDL_VIDEODRIVER=dummy shows nothing", "leave out --render"]),
    ("play-render-dummy", ["play", "--seats", "smart,random"],
     ["play: no display", "Run `alphatank play` on a desktop", "video with `alphatank record`"]),
    ("replay-render-dummy", ["replay", "{good_npz}", "--render"],
     ["replay: no display", "Run `alphatank replay FILE --render` on a desktop",
      "video with `--record OUT.mp4` or `--gif FILE` instead"]),
    ("arena-human", ["arena", "--seats", "human,random"],
     ["['human'] needs a player at the keyboard"]),
    ("play-stand-in-human", ["play", "--headless-test", "--seats", "human,learner",
                             "--stand-in", "human"],
     ["'human': a seat filled for the scenario plays by itself"]),
    ("arena-steps", ["arena", "--max-steps", "0"],
     ["argument --max-steps", "must be an integer in [1, 10000000]", "'0'"]),
    ("arena-steps-big", ["arena", "--max-steps", "99999999999"],
     ["argument --max-steps", "must be an integer in [1, 10000000]", "'99999999999'"]),
    ("arena-preset", ["arena", "--preset", "fast"], ["unknown preset 'fast'"]),
    ("arena-seed", ["arena", "--seed", "-1"], ["--seed", "[0, 2^63)", "'-1'"]),
    ("arena-seats-kind", ["arena", "--seats", "nosuch"], ["'nosuch'", "neither a seat kind",
                                                          "valid bots"]),
    ("arena-seats-one", ["arena", "--seats", "smart"], ["--seats needs at least 2 seats"]),
    ("arena-seats-agent", ["arena", "--seats", "agent:nosuch,smart"],
     ["unknown agent 'nosuch'"]),
    ("arena-seats-ckpt", ["arena", "--seats", "checkpoint:{missing},smart"],
     ["{missing}", "no such checkpoint"]),
    ("arena-seats-learner", ["arena", "--seats", "learner,smart"],
     ["learner seat", "agent:NAME"]),
    # replay
    ("replay-missing", ["replay", "{missing}"], ["{missing}", "no such replay file"]),
    ("replay-empty", ["replay", "{empty_npz}"], ["{empty_npz}", "not a readable replay"]),
    ("replay-binary", ["replay", "{binary_npz}"], ["{binary_npz}", "not a readable replay"]),
    ("replay-truncated", ["replay", "{truncated_npz}"], ["{truncated_npz}", "not a readable"]),
    ("replay-flipped-byte", ["replay", "{flipped_npz}"], ["{flipped_npz}"]),
    ("replay-wrong-kind", ["replay", "{good_txt}"], ["{good_txt}", "not a readable"]),
    ("replay-v1", ["replay", "{v1_npz}"],
     ["{v1_npz}", "version 1", "version 2", "(record the match again)"]),
    ("replay-v3", ["replay", "{v3_npz}"], ["{v3_npz}", "replay version 3 is not supported: "
     "this AlphaTank reads version 2 (a newer AlphaTank wrote it: upgrade AlphaTank to "
     "replay it)"]),
    ("replay-seed", ["replay", "{seed_npz}"], ["{seed_npz}", "meta.match_seed", "-5"]),
    ("replay-teams-null", ["replay", "{teamsnull_npz}"], ["{teamsnull_npz}", "meta.teams"]),
    ("replay-teams-AA", ["replay", "{teamsAA_npz}"], ["meta.teams", "2 different teams"]),
    ("replay-winner", ["replay", "{winner_npz}"], ["{winner_npz}", "digest"]),
    ("replay-fast", ["replay", "{fast_npz}"], ["meta.config.bullet_speed", "[1, 10000]"]),
    ("replay-map-edit", ["replay", "{maptext_npz}"], ["{maptext_npz}", "meta.digest"]),
    ("replay-speed", ["replay", "{good_npz}", "--render", "--headless-test", "--speed", "0"],
     ["--speed", "[0.05, 50]"]),
    ("replay-speed-tiny", ["replay", "{good_npz}", "--render", "--headless-test", "--speed",
                           "1e-9"], ["--speed", "[0.05, 50]", "'1e-9'"]),
    ("replay-speed-no-render", ["replay", "{good_npz}", "--speed", "0.5"],
     ["--speed is for the window of --render; give --render with it"]),
    ("replay-frames-no-render", ["replay", "{good_npz}", "--record", "{dir}/r.mp4",
                                 "--max-frames", "5"], ["--max-frames", "--render"]),
    ("replay-empty-path", ["replay", ""], ["argument file: is empty; give a name or a path"]),
    ("replay-overlay", ["replay", "{good_npz}", "--overlays", "xray"],
     ["argument --overlays", "xray", "aim"]),
    ("replay-record-suffix", ["replay", "{good_npz}", "--record", "{dir}/again"],
     ["--record", "again", "must end in .mp4"]),
    # record
    ("record-same-file", ["record", "--seats", "smart,random", "-o", "{dir}/s.mp4",
                          "--replay", "{dir}/./s.mp4"],
     ["--out and --replay name the same file ({dir}/./s.mp4): one would overwrite the other"]),
    ("replay-team-nul", ["replay", "{teamnul_npz}"],
     ["meta.teams[0]: must be printable, got 'A\\x00': U+0000 is a control character"]),
    ("replay-long-label", ["replay", "{longlabel_npz}"],
     ["meta.labels[0]: must be at most 4096 characters, got 5,000"]),
    ("replay-scenario-escape", ["replay", "{escscenario_npz}"],
     ["meta.scenario: must be printable, got 'vs\\n\\x1b[31mred': U+000A is a control "
      "character"]),
    ("replay-long-map-name", ["replay", "{longmapname_npz}"],
     ["meta.map_name: must be at most 4096 characters, got 5,000"]),
    ("replay-header-bomb", ["replay", "{bomb_npz}"],
     ["member 'actions.npy' unpacks to 6,597,069,766,656 bytes; a replay member may hold "
      "at most 268,435,456"]),
    ("replay-onto-itself", ["replay", "{replay_as_gif}", "--gif", "{replay_as_gif}"],
     ["the replay file and --gif name the same file"]),
    ("record-replay-empty", ["record", "--seats", "smart,random", "--replay", ""],
     ["argument --replay: is empty"]),
    ("record-seats-empty", ["record", "--seats", "", "--max-steps", "3"],
     ["argument --seats: is empty"]),  # not read as none: the default human,smart
    ("play-stand-in-empty", ["play", "--headless-test", "--seats", "learner,smart",
                             "--stand-in", ""], ["argument --stand-in: is empty"]),
    ("record-scenario-empty-path", ["record", "--scenario", ""], ["argument --scenario: is empty"]),
    ("record-replay-room", ["record", "--scenario", "{longgame_toml}", "--replay",
                            "{dir}/long.npz"],
     ["--replay: a game of up to 15,300 ticks (max_steps) may take 5,033,700 physics "
      "substeps to re-simulate; a replay may ask for at most 5,000,000"]),
    ("play-replay-room", ["play", "--headless-test", "--scenario", "{longgame_toml}",
                          "--save-replay", "{dir}/long.npz"], ["--save-replay: a game of up to"]),
    # a bare bot or agent name as --checkpoint was read as a folder path
    ("record-checkpoint-bot", ["record", "--scenario", "vs_smart", "--checkpoint", "smart"],
     ["record: error: --checkpoint: no checkpoint or run folder 'smart' here; for the bot, "
      "give bot:smart"]),
    ("play-checkpoint-agent-name", ["play", "--headless-test", "--scenario", "vs_smart",
                                    "--checkpoint", "ppo_vs_smart"],
     ["play: error: --checkpoint: no checkpoint or run folder 'ppo_vs_smart' here; for the "
      "agent, give agent:ppo_vs_smart"]),
    # a replay holds at most 64 tanks: refused before the game, not after it (the MP4 made)
    ("record-replay-tanks", ["record", "--seats", ",".join(["random"] * 65), "--map", "open",
                             "--replay", "{dir}/many.npz"],
     ["--replay: a replay holds at most 64 tanks, this game has 65"]),
    ("play-replay-tanks", ["play", "--headless-test", "--seats", ",".join(["random"] * 65),
                           "--map", "open", "--save-replay", "{dir}/many.npz"],
     ["--save-replay: a replay holds at most 64 tanks, this game has 65"]),
    ("record-team-nul", ["record", "--scenario", "{nulteam_toml}"],
     ["seats[0].team: must be printable, got 'A\\x00': U+0000 is a control character"]),
    ("record-team-nbsp", ["record", "--scenario", "{nbspteam_toml}"],
     ["seats[0].team: must be printable, got 'A\\xa0B': U+00A0 NO-BREAK SPACE is a space "
      "other than ' '"]),
    ("record-scenario-missing", ["record", "--scenario", "{dir}/none.toml"],
     ["none.toml", "no such scenario file"]),
    ("record-scenario-folder", ["record", "--scenario", "{emptydir}"],
     ["{emptydir}: a folder, not a scenario file"]),
    ("record-scenario-empty", ["record", "--scenario", "{empty_toml}"],
     ["{empty_toml}", "name"]),
    ("record-scenario-description", ["record", "--scenario", "{descnl_toml}"],
     ["{descnl_toml}: description: must be printable, got 'a\\tb': U+0009 is a control "
      "character"]),
    ("record-scenario-binary", ["record", "--scenario", "{binary_toml}"],
     ["{binary_toml}", "UTF-8"]),
    ("record-friendly-fire", ["record", "--scenario", "{ff_toml}"],
     ["{ff_toml}", "[game].friendly_fire", "true or false", "'no'"]),
    ("record-max-steps-bool", ["record", "--scenario", "{steps_toml}"],
     ["[game].max_steps", "integer", "True"]),
    ("record-victory-nan", ["record", "--scenario", "{victory_toml}"],
     ["[rewards].victory", "finite"]),
    ("record-bot-option", ["record", "--scenario", "{botopt_toml}"],
     ["seats[1].options", "hold_min", "integer"]),
    ("record-ckpt-seat", ["record", "--scenario", "{ckptseat_toml}"],
     ["seats[1].path", "gone: no such checkpoint"]),
    ("record-seats", ["record", "--seats", "human,genius"], ["--seats[1]", "genius"]),
    ("record-map", ["record", "--seats", "smart,random", "--map", "{utf16_txt}"],
     ["record: error: --map: {utf16_txt}", "UTF-16"]),
    ("play-map-room", ["play", "--headless-test", "--seats", "smart,random,dodge,aggressive",
                       "--map", "{small_txt}"],
     ["play: error: --map: map 'small' has room for 3 tank(s)"]),
    ("record-ckpt-missing", ["record", "--checkpoint", "{missing}", "--seats", "learner,smart"],
     ["{missing}", "no such checkpoint"]),
    ("record-ckpt-seats", ["record", "--checkpoint", "{run}", "--seats", "learner,smart,random",
                           "--map", "open"], ["{ckpt}", "observation features"]),
    ("record-ckpt-map", ["record", "--checkpoint", "{run}", "--seats", "learner,smart",
                         "--map", "arena4"], ["{ckpt}", "wall rectangles", "arena4",
                                               "its training scenario"]),
    ("record-ckpt-version", ["record", "--checkpoint", "{ckpt_v99}", "--seats", "learner,smart"],
     ["{ckpt_v99}", "version 99"]),
    ("record-ckpt-nan", ["record", "--checkpoint", "{ckpt_nan}", "--seats", "learner,smart"],
     ["{ckpt_nan}", "{nan_tensor}", "NaN"]),
    ("record-seed", ["record", "--seats", "smart,random", "--seed", "-1"], ["--seed", "2^63"]),
    ("record-hold", ["record", "--seats", "smart,random", "--max-steps", "1", "--scale", "0.1",
                     "--hold", "61"], ["argument --hold", "must be a number in [0, 60]", "'61'"]),
    ("record-overlays", ["record", "--overlays", "xray", "--seats", "smart,random"],
     ["argument --overlays", "xray"]),
    ("play-overlays", ["play", "--headless-test", "--overlays", "aim,xray"],
     ["argument --overlays", "unknown overlay(s) ['xray']"]),
    ("record-out-dir", ["record", "--seats", "smart,random", "--max-steps", "3",
                        "-o", "{good_txt}/x.mp4"], ["{good_txt}"]),
    ("record-out-suffix", ["record", "--seats", "smart,random", "-o", "{dir}/m.txt"],
     ["--out", "m.txt", ".mp4, .mkv, .mov or .avi"]),
    ("record-scale", ["record", "--seats", "smart,random", "--scale", "1e-9"],
     ["--scale", "[0.1, 8]"]),
    ("record-gif-suffix", ["record", "--seats", "smart,random", "--gif", "{dir}/m.png"],
     ["--gif", "m.png", "must end in .gif"]),
    ("record-replay-folder", ["record", "--seats", "smart,random", "-o", "{dir}/m.mp4",
                              "--replay", "{dir}"], ["--replay", "is a folder"]),
    ("record-max-steps", ["record", "--seats", "smart,random", "--max-steps", "-4"],
     ["argument --max-steps", "[1, 10000000]", "'-4'"]),  # the flag, not --seats' [game]
    ("record-max-steps-0", ["record", "--scenario", "vs_smart", "--max-steps", "0"],
     ["argument --max-steps", "[1, 10000000]", "'0'"]),
    ("play-max-steps-big", ["play", "--headless-test", "--max-steps", "10000001"],
     ["argument --max-steps", "[1, 10000000]", "'10000001'"]),
    ("record-bot-empty", ["record", "--seats", "bot:,smart"], ["--seats[0]", "bot needs a name"]),
    ("record-checkpoint-agent", ["record", "--checkpoint", "agent:nosuch", "--seats",
                                 "learner,smart"], ["unknown agent 'nosuch'"]),
    # play (under the dummy video driver: --headless-test lets it get to the real checks)
    ("play-replay-folder", ["play", "--headless-test", "--save-replay", "{dir}"],
     ["--save-replay", "is a folder"]),
    ("play-replay-empty", ["play", "--headless-test", "--seats", "smart,random",
                           "--save-replay", ""], ["argument --save-replay: is empty"]),
    ("play-replay-exists", ["play", "--headless-test", "--seats", "smart,random",
                            "--save-replay", "{good_npz}"],
     ["--save-replay", "{good_npz}", "exists", "--force"]),
    ("play-scenario", ["play", "--headless-test", "--scenario", "{ff_toml}"],
     ["[game].friendly_fire"]),
    ("play-ckpt-seats", ["play", "--headless-test", "--checkpoint", "{run}", "--seats",
                         "learner,smart,random", "--map", "open"], ["observation features"]),
    ("play-ckpt-meta", ["play", "--headless-test", "--checkpoint", "{ckpt_objdim}",
                        "--seats", "human,learner"], ["{ckpt_objdim}", "obs_dim", "'abc'"]),
    ("play-seats", ["play", "--headless-test", "--seats", "human@0.5,smart"], ["@weakness"]),
    ("play-fps", ["play", "--headless-test", "--seats", "smart,random", "--fps", "0"],
     ["--fps", "[1, 1000]"]),
    ("play-fps-tiny", ["play", "--headless-test", "--seats", "smart,random", "--fps", "0.001"],
     ["--fps", "[1, 1000]", "'0.001'"]),
    ("record-fps-tiny", ["record", "--seats", "smart,random", "--fps", "1e-9"],
     ["--fps", "[0.01, 1000]", "'1e-9'"]),
    ("play-seats-one-agent", ["play", "--headless-test", "--seats", "agent:nosuch"],
     ["--seats needs at least 2 seats"]),
    ("play-seats-agent", ["play", "--headless-test", "--seats", "agent:nosuch,smart"],
     ["seats[0].agent", "unknown agent 'nosuch'"]),
    ("play-seats-keys", ["play", "--headless-test", "--seats", "human:qwer,smart"],
     ["seats[0].keys", "'qwer'", "arrows"]),
    ("play-checkpoint-agent", ["play", "--headless-test", "--checkpoint", "agent:nosuch",
                               "--seats", "human,learner"], ["unknown agent 'nosuch'"]),
    ("play-stand-in", ["play", "--headless-test", "--scenario", "vs_smart", "--stand-in",
                       "genius"], ["stand-in 'genius'", "valid bots"]),
    ("play-scale-huge", ["play", "--headless-test", "--seats", "smart,random", "--scale", "1e9"],
     ["--scale", "[0.1, 8]", "'1e9'"]),
    ("play-scale-tiny", ["play", "--headless-test", "--seats", "smart,random", "--scale",
                         "1e-9"], ["--scale", "[0.1, 8]", "'1e-9'"]),
    ("play-max-frames", ["play", "--headless-test", "--seats", "smart,random",
                         "--max-frames", "0"], ["--max-frames", ">= 1"]),
    # eval
    ("eval-json-folder", ["eval", "bot:smart", "--scenario", "vs_random", "--json", "{dir}"],
     ["--json", "{dir}", "is a folder"]),
    ("eval-csv-under-file", ["eval", "bot:smart", "--scenario", "vs_random", "--csv",
                             "{good_txt}/rows.csv"], ["--csv", "{good_txt} is a file"]),
    ("eval-json-csv-same", ["eval", "bot:smart", "--scenario", "vs_random", "--games", "1",
                            "--json", "{dir}/rows", "--csv", "{dir}/./rows"],
     ["--csv and --json name the same file ({dir}/rows): one would overwrite the other"]),
    ("eval-csv-team-json-same", ["eval", "bot:smart", "--scenario", "vs_random", "--games",
                                 "1", "--team-stats", "--json", "{dir}/rows.json", "--csv",
                                 "{dir}/rows.team.json"],
     ["--csv and --team-stats name the same file", "one would overwrite the other"]),
    ("eval-json-empty", ["eval", "bot:smart", "--scenario", "vs_random", "--json", ""],
     ["argument --json: is empty"]),
    ("eval-missing", ["eval", "{missing}"], ["{missing}", "no such checkpoint"]),
    ("eval-empty-dir", ["eval", "{emptydir}"], ["{emptydir}", "not a checkpoint"]),
    ("eval-latest-empty", ["eval", "{latest_empty}"],
     ["{latest_empty}/latest: is empty; it names the run's latest save"]),
    ("eval-latest-binary", ["eval", "{latest_binary}"],
     ["{latest_binary}/latest: not a UTF-8 text file"]),
    ("eval-file", ["eval", "{good_txt}"], ["{good_txt}", "got a file"]),
    ("eval-truncated", ["eval", "{ckpt_cut}"], ["{ckpt_cut}", "invalid JSON"]),
    ("eval-version", ["eval", "{ckpt_v99}"], ["version 99"]),
    ("eval-meta-type", ["eval", "{ckpt_objdim}"], ["observation.obs_dim", "'abc'"]),
    ("eval-nan", ["eval", "{ckpt_nan}"], ["{nan_tensor}", "NaN"]),
    ("eval-games", ["eval", "{run}", "--games", "0"], ["--games", "integer >= 1", "'0'"]),
    ("eval-num-envs-max", ["eval", "{run}", "--num-envs", "5000"],
     ["--num-envs", "integer in [1, 4096]", "'5000'"]),
    ("eval-num-envs-zero", ["eval", "{run}", "--num-envs", "0"], ["--num-envs", "'0'"]),
    ("eval-vs", ["eval", "{run}", "--vs", "smart,genius", "--games", "1"],
     ["--vs: unknown bot 'genius'", "dodge"]),
    ("eval-seed", ["eval", "{run}", "--seed", "x"], ["--seed", "'x'"]),
    ("eval-game-twice", ["eval", "{run}", "--game", "max_steps=600,max_steps=60", "--games",
                         "1", "--num-envs", "1"], ["--game max_steps: given twice"]),
    ("eval-vs-twice", ["eval", "{run}", "--vs", "smart,dodge,smart", "--games", "1",
                       "--num-envs", "1"], ["--vs: 'smart' is given twice"]),
    ("eval-vs-empty", ["eval", "{run}", "--vs", "", "--games", "1"],
     ["--vs: no bot named in ''; give comma-separated bots"]),
    ("eval-vs-commas", ["eval", "{run}", "--vs", " , ", "--games", "1"],
     ["--vs: no bot named in ' , '"]),
    ("eval-team-empty", ["eval", "{run}", "--team", "", "--games", "1"],
     ["argument --team: is empty"]),
    ("eval-unknown-flag", ["eval", "{run}", "--bogus"],
     ["alphatank eval: error: unrecognized arguments: --bogus", "see alphatank eval --help"]),
    ("eval-scenario", ["eval", "{run}", "--scenario", "{binary_toml}"], ["UTF-8"]),
    ("eval-agent", ["eval", "agent:nosuch"], ["unknown agent 'nosuch'"]),
    ("eval-agent-scenario", ["eval", "agent:ppo_vs_smart", "--scenario", "team_vs_bot"],
     ["expects 236 observation features", "its training scenario 'vs_smart'",
      "paper observation"]),
    ("eval-agent-map", ["eval", "agent:ppo_vs_smart", "--map", "maze"],
     ["expects 236 observation features; scenario 'vs_smart' on map 'maze' gives 256",
      "its training scenario 'vs_smart' (map 'battlefield', teams"]),
    ("eval-checkpoint-empty", ["eval", "checkpoint:"], ["needs the checkpoint folder"]),
    ("eval-map", ["eval", "agent:ppo_vs_smart", "--map", "nowhere"],
     ["eval: error: --map: unknown map 'nowhere'", "battlefield"]),
    ("eval-map-binary", ["eval", "{run}", "--map", "{binary_txt}"],
     ["eval: error: --map: {binary_txt}: not a UTF-8 text file"]),
    ("eval-team-bots-only", ["eval", "{run}", "--team", "B", "--vs", "smart"],
     ["team 'B': scenario 'vs_aggressive' has no learner seat on team B", "learner teams: A"]),
    ("eval-stand-in-team", ["eval", "bot:smart", "--scenario", "vs_smart", "--team", "B"],
     ["team 'B'", "no learner seat", "learner teams: A"]),
    # train
    ("train-resume-missing", ["train", "--resume", "{dir}/runs/nosuch"],
     ["nosuch", "no such checkpoint or run directory"]),
    ("train-resume-empty", ["train", "--resume", "{runs_empty}"],
     ["{runs_empty}", "not a run directory"]),
    ("train-resume-version", ["train", "--resume", "{ckpt_v99}"], ["version 99"]),
    ("train-resume-windows", ["train", "--resume", "{ckpt_windows}"],
     ["{ckpt_windows}/meta.json: windows: must be an object, got 5"]),
    ("train-resume-outcomes", ["train", "--resume", "{ckpt_outcomes}"],
     ["meta.json: windows.outcomes: must map learner names ['ppo']"]),
    ("train-resume-cut", ["train", "--resume", "{ckpt_progress_cut}"],
     ["{ckpt_progress_cut}/meta.json: progress.cut: must be an integer, got 'x'"]),
    ("train-resume-no-progress", ["train", "--resume", "{ckpt_noprogress}"],
     ["{ckpt_noprogress}/meta.json: missing field 'progress'"]),
    ("train-resume-nan", ["train", "--resume", "{ckpt_nan}", "--wandb", "disabled",
                          "--no-progress"], ["{nan_tensor}", "NaN"]),
    ("train-preset", ["train", "--preset", "nosuch"], ["nosuch"]),
    ("train-no-learner-seats", ["train", "--runs", "{dir}/nolearner", "--scenario",
                                "bot_teams", "--wandb", "disabled"],
     ["--scenario: scenario 'bot_teams' has no learner seats: nothing to train"]),
    ("train-selfplay-no-pool", ["train", "--runs", "{dir}/runs", "--preset", "team_ppo_vs_ppo",
                                "--scenario", "team_vs_bot", "--wandb", "disabled"],
     ["--scenario: self-play learners [('team', [0, 1])]", "leave at least one to the "
      "snapshot pool"]),
    ("train-init-from-sac", ["train", "--runs", "{dir}/runs", "--preset", "sac_vs_aggressive",
                             "--init-from", "agent:ppo_vs_smart", "--wandb", "disabled"],
     ["--init-from: a warm start fills PPO and MAPPO learners; this run's [('sac', 'sac')] "
      "take none"]),
    ("train-tensorboard", ["train", "--runs", "{dir}/tbruns", "--tensorboard", "--wandb",
                           "disabled", "--total-steps", "32", "--num-envs", "2",
                           "--no-progress"], ["tensorboard"]),
    ("train-name", ["train", "--runs", "{dir}/runs", "--name", "../../escaped"],
     ["--name", "'../../escaped'", "letters, digits"]),
    ("train-config-name", ["train", "--config", "{runname_toml}"],
     ["{runname_toml}", "name:", "'../../escaped'"]),
    ("train-runs-file", ["train", "--runs", "{good_txt}"], ["--runs", "is a file"]),
    ("train-num-envs-max", ["train", "--num-envs", "100000"],
     ["argument --num-envs", "integer in [1, 4096]", "'100000'"]),
    ("train-replay-memory", ["train", "--preset", "sac_vs_aggressive", "--runs", "{dir}/runs",
                             "--wandb", "disabled", "--hp", "sac.buffer_size=1000000000"],
     ["buffer_size = 1,000,000,000", "GiB available", "lower buffer_size"]),
    ("train-replay-memory-given", ["train", "--preset", "sac_vs_aggressive", "--runs",
                                   "{dir}/runs", "--wandb", "disabled", "--hp",
                                   "sac.buffer_size=1e12"],
     ["buffer_size = 1,000,000,000,000 transitions", "lower buffer_size"]),
    ("train-batch-memory", ["train", "--preset", "sac_vs_aggressive", "--runs", "{dir}/runs",
                            "--wandb", "disabled", "--hp", "sac.batch_size=1e9"],
     ["batch_size = 1,000,000,000 transitions", "GiB available", "lower batch_size"]),
    # accepted before: the first update round never ended, its stop's save did not load
    ("train-utd-ratio-max", ["train", "--preset", "sac_vs_aggressive", "--print-config",
                             "--hp", "sac.utd_ratio=1e308"],
     ["--hp sac.utd_ratio", "must be in (0, 1000]", "1e+308"]),
    ("train-rollout-memory", ["train", "--runs", "{dir}/runs", "--wandb", "disabled", "--hp",
                              "ppo.num_steps=100000000"], ["num_steps = 100,000,000",
                                                           "lower num_steps or num_envs"]),
    ("train-seed", ["train", "--seed", "-1"], ["--seed", "[0, 2^63)"]),
    ("train-steps", ["train", "--total-steps", "many"], ["--total-steps", "integer >= 1"]),
    ("train-config-empty-path", ["train", "--config", ""], ["argument --config: is empty"]),
    ("train-runs-empty", ["train", "--runs", ""], ["argument --runs: is empty"]),
    ("train-config-missing", ["train", "--config", "{dir}/none.toml"],
     ["none.toml", "no such run file"]),
    ("train-config-folder", ["train", "--config", "{dir}"], ["{dir}: a folder, not a run file"]),
    ("train-name-file", ["train", "--runs", "{dir}", "--name", "good.txt"],
     ["--name: {dir}/good.txt: is a file, not a folder"]),
    ("plot-out-under-file", ["plot", "{run}", "-o", "{good_txt}/x.png"],
     ["-o: {good_txt}/x.png: {good_txt} is a file, not a folder"]),
    ("plot-labels-count", ["plot", "{run}", "{run}", "--labels", "a"],
     ["--labels: 1 label(s) for 2 run(s); give one per run"]),
    ("plot-run-empty", ["plot", ""], ["argument RUN: is empty; give a name or a path"]),
    ("plot-run-file", ["plot", "{good_txt}"], ["{good_txt}: a file, not a run folder"]),
    ("agents-export-under-file", ["agents", "export", "{run}", "{good_txt}/agent"],
     ["dest: {good_txt}/agent: {good_txt} is a file, not a folder"]),
    ("agents-export-eval-missing", ["agents", "export", "{run}", "{dir}/agent_e",
                                    "--eval", "{missing}"],
     ["--eval: {missing}: cannot read: No such file or directory; give the `alphatank eval "
      "--json` file of the exported checkpoint"]),
    ("agents-export-eval-not-json", ["agents", "export", "{run}", "{dir}/agent_e",
                                     "--eval", "{good_txt}"],
     ["--eval: {good_txt}: not JSON (Expecting value at line 1 column 1); give the "
      "`alphatank eval --json` file"]),
    ("agents-export-description", ["agents", "export", "{run}", "{dir}/agent_d",
                                   "--description", "a\nb"],
     ["--description: must be printable, got 'a\\nb': U+000A is a control character"]),
    ("agents-export-description-rlo", ["agents", "export", "{run}", "{dir}/agent_d",
                                       "--description", "a\u202eb"],
     ["--description: must be printable, got 'a\\u202eb': U+202E RIGHT-TO-LEFT OVERRIDE is "
      "not printable"]),
    ("train-config-binary", ["train", "--config", "{binary_toml}"], ["{binary_toml}", "UTF-8"]),
    ("train-config-toml", ["train", "--config", "{syntax_toml}"],
     ["{syntax_toml}", "invalid TOML"]),
    ("train-config-scenario", ["train", "--config", "{ff_toml}"], ["{ff_toml}", "scenario"]),
    ("train-config-field", ["train", "--config", "{runsteps_toml}"],
     ["{runsteps_toml}", "total_steps", "'many'"]),
    ("train-config-game", ["train", "--config", "{rungame_toml}"],
     ["{rungame_toml}: [game].max_steps", "[1, 10000000]", "-1"]),
    ("train-config-schedule-no-bots", ["train", "--config", "{runsched_toml}"],
     ["{runsched_toml}: schedule: the curriculum schedule needs bot seats; scenario 'pair' "
      "has none"]),
    # the team-outcome rules name the file and the table like every other [rewards] error
    ("train-config-team-decay", ["train", "--config", "{rundecay_toml}", "--print-config"],
     ["{rundecay_toml}: [rewards].team_win_time_decay: must be in [0, 1], got 2.0"]),
    ("train-config-team-draw", ["train", "--config", "{rundraw_toml}", "--print-config"],
     ["{rundraw_toml}: [rewards].team_draw: (5.0) must not exceed team_loss (-5.0)"]),
    ("train-config-seats", ["train", "--config", "{runseats_toml}"],
     ["{runseats_toml}: learners [('p', [5])] do not drive each of the 1 learner seat(s) "
      "of scenario 'vs_random' exactly once"]),
    ("train-config-hp", ["train", "--config", "{rungamma_toml}"],
     ["{rungamma_toml}", "learners[0].config.gamma", "[0, 1]"]),
    # the run file's own settings: the error names the file, then the field
    ("train-config-scenario-name", ["train", "--config", "{runscenario_toml}"],
     ["{runscenario_toml}: scenario: unknown scenario 'vs_nobody'", "vs_random"]),
    ("train-config-map", ["train", "--config", "{runmap_toml}"],
     ["{runmap_toml}: map:", "unknown map 'nowhere'", "battlefield"]),
    ("train-config-description", ["train", "--config", "{rundesc_toml}", "--print-config"],
     ["{rundesc_toml}: description: must be printable, got 'two\\nlines': U+000A is a "
      "control character"]),
    ("train-config-init-from", ["train", "--config", "{runinit_toml}"],
     ["{runinit_toml}: init_from: unknown agent 'nobody'", "ppo_vs_smart"]),
    ("train-config-observation", ["train", "--config", "{runobs_toml}"],
     ["{runobs_toml}: observation: 'egocentric_fulll'", "egocentric_full'"]),
    ("train-config-imitate-bot", ["train", "--config", "{runimitate_toml}"],
     ["{runimitate_toml}: imitate.bot 'smrt'", "smart"]),
    ("train-config-imitate-key", ["train", "--config", "{runimitatekey_toml}"],
     ["{runimitatekey_toml}: imitate.stepz: unknown key", "steps"]),
    ("train-config-cycle-pool", ["train", "--config", "{runpool_toml}", "--runs", "{dir}/runs",
                                 "--wandb", "disabled", "--no-progress"],
     ["{runpool_toml}: schedule: cycle pool: unknown bot 'nosuch'", "smart"]),
    ("train-config-scenario-flag", ["train", "--config", "{runscenario_toml}", "--scenario",
                                    "vs_nobody_either"], ["--scenario: unknown scenario"]),
    ("train-hp-algo", ["train", "--hp", "nosuch.x=1"], ["--hp nosuch.x", "unknown algorithm"]),
    ("train-hp-field", ["train", "--hp", "ppo.nosuch=1"], ["ppo.nosuch", "valid"]),
    ("train-hp-range", ["train", "--hp", "ppo.gamma=2"], ["--hp ppo.gamma", "[0, 1]"]),
    ("train-hp-hidden", ["train", "--hp", "ppo.hidden=200000"],
     ["--hp ppo.hidden", "(0, 4096]", "200000"]),
    ("train-hp-form", ["train", "--ppo", "gamma"], ["--ppo"]),
    ("train-hp-nan", ["train", "--preset", "sac_vs_aggressive", "--hp",
                      "sac.target_entropy=nan"], ["--hp sac.target_entropy", "finite"]),
    ("train-time-limit-inf", ["train", "--time-limit", "inf"],
     ["--time-limit", "in [0, 604800]", "'inf'"]),
    ("train-time-limit-huge", ["train", "--runs", "{dir}/runs_tl", "--time-limit", "1e30"],
     ["--time-limit", "in [0, 604800]", "'1e30'"]),
    ("train-schedule", ["train", "--schedule", "cycle:sometimes"], ["--schedule", "cycle:fixed"]),
    ("train-curriculum", ["train", "--curriculum", "0.1:2"], ["--curriculum", "START:END"]),
    ("train-map", ["train", "--map", "nowhere"], ["--map", "unknown map 'nowhere'"]),
    ("train-scenario", ["train", "--scenario", "{binary_toml}"], ["--scenario", "UTF-8"]),
    ("train-config-and-preset", ["train", "--config", "{ff_toml}", "--preset", "demo"],
     ["--config and --preset"]),
    ("train-resume-new-flags", ["train", "--resume", "{run}", "--hp", "ppo.gamma=0.9",
                                "--init-from", "{run}"], ["--hp, --init-from apply to new runs"]),
    ("train-resume-new-flag", ["train", "--resume", "{run}", "--schedule", "cycle:fixed"],
     ["--schedule applies to new runs"]),
    ("train-resume-name", ["train", "--resume", "{run}", "--name", "branch"],
     ["--name and --runs name a new run's folder", "copy its folder"]),
    ("train-resume-num-envs", ["train", "--resume", "{run}", "--num-envs", "3"],
     ["--num-envs: the run plays 2 matches", "keeps them"]),
    ("train-resume-loose", ["train", "--resume", "{ckpt_loose}"],
     ["{ckpt_loose}: not a save in a run folder", "--init-from {ckpt_loose}"]),
    ("train-resume-earlier", ["train", "--resume", "{ckpt_earlier}"],
     ["{ckpt_earlier}: the run has later saves (step_0000000099)", "remove the later"]),
    ("train-resume-agent", ["train", "--resume", "{agent_dir}"],
     ["{agent_dir}: an agent folder", "cannot be resumed", "--init-from"]),
    # experiments
    ("experiments-budget-inf", ["experiments", "table3", "--list", "--budget", "inf"],
     ["--budget", "(0, 10080]", "'inf'"]),
    ("experiments-budget-huge", ["experiments", "table3", "--list", "--budget", "1e300"],
     ["--budget", "(0, 10080]"]),
    ("experiments-budget-0", ["experiments", "table3", "--list", "--budget", "0"],
     ["--budget", "(0, 10080]", "'0'"]),
    ("experiments-out-under-file", ["experiments", "table3", "--rows", "smart", "--budget",
                                    "0.2", "--games", "2", "--out", "{good_txt}/x",
                                    "--no-progress"], ["--out", "{good_txt} is a file"]),
    # demo
    ("demo-minutes", ["demo", "--minutes", "-1"], ["--minutes", "in (0, 10080]", "'-1'"]),
    ("demo-minutes-huge", ["demo", "--minutes", "1e9"], ["--minutes", "(a week)", "'1e9'"]),
    ("demo-name", ["demo", "--runs", "{dir}/runs", "--name", "a/b"], ["--name", "'a/b'"]),
    ("demo-name-empty", ["demo", "--runs", "{good_txt}/runs", "--name", ""],
     ["--name: must be letters", "got ''"]),
    ("demo-runs-file", ["demo", "--runs", "{good_txt}/runs"], ["--runs", "{good_txt} is a file"]),
    ("demo-wandb", ["demo", "--wandb", "cloud"], ["--wandb", "invalid choice"]),
]

MAPGEN_CASES = [
    ("mapgen-validate-missing", ["validate", "{missing}"], ["{missing}", "no such map"]),
    ("mapgen-validate-binary", ["validate", "{binary_txt}"], ["{binary_txt}", "UTF-8"]),
    ("mapgen-validate-cell", ["validate", "{cellinf_txt}"], ["'cell'", "[39, 400]"]),
    ("mapgen-validate-empty-path", ["validate", ""], ["''", "empty map name or path"]),
    ("mapgen-validate-room", ["validate", "{good_txt}", "--teams", "ABCDEFGHIJKL"],
     ["{good_txt}", "room for"]),
    ("mapgen-preview-utf16", ["preview", "{utf16_txt}", "--no-png"], ["UTF-16"]),
    ("mapgen-preview-scale", ["preview", "maze", "--scale", "1e9"], ["--scale", "[0.1, 8]"]),
    ("mapgen-generate-size", ["generate", "--size", "big"], ["size", "ROWSxCOLS", "'big'"]),
    ("mapgen-generate-small", ["generate", "--size", "4x4"], ["--size", "[5, 64]", "'4x4'"]),
    ("mapgen-batch-large", ["batch", "--size", "11x11,9x65", "--count", "2", "--out",
                            "{dir}/gen"],
     ["--size", "[5, 64]", "'9x65'"]),
    ("mapgen-edit-small", ["edit", "{dir}/new.txt", "--size", "2x2"], ["--size", "[3, 64]"]),
    ("mapgen-generate-alg", ["generate", "--algorithm", "spiral"], ["--algorithm", "maze"]),
    ("mapgen-batch-count", ["batch", "--count", "0", "--out", "{dir}/gen"], ["--count", ">= 1"]),
    ("mapgen-batch-out-file", ["batch", "--count", "2", "--out", "{good_txt}"],
     ["mapgen.py batch: error: --out", "is a file"]),
    ("mapgen-variants-out-file", ["variants", "maze", "--out", "{good_txt}/v"],
     ["--out", "{good_txt} is a file"]),
    ("mapgen-generate-out-folder", ["generate", "-o", "{dir}", "--force"],
     ["--output", "is a folder"]),
    ("mapgen-preview-png-empty", ["preview", "maze", "--png", ""], ["--png: is empty"]),
    ("mapgen-preview-png-folder", ["preview", "maze", "--png", "{dir}"], ["--png", "is a folder"]),
    ("mapgen-edit-binary", ["edit", "{binary_txt}"], ["{binary_txt}", "UTF-8"]),
    ("mapgen-edit-no-display", ["edit", "{good_txt}"], ["edit needs a display", "dummy"]),
    ("mapgen-no-verb", [], ["required"]),
]

# Cases that would need a machine with `tensorboard` absent to fail: skip where present.
HAS_TENSORBOARD = importlib.util.find_spec("tensorboard") is not None


def _fill(items: list[str], files: dict[str, str]) -> list[str]:
    return [s.format(**files) for s in items]


def _check(rc: int, out: str, err: str, fragments: list[str]) -> None:
    """Non-zero exit, no traceback, and one error line: stderr's only line, or (for verbs
    that report on stdout) stdout's last line."""
    text = out + err
    assert "Traceback" not in text, text
    assert rc != 0, text
    err_lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(err_lines) <= 1, f"want one error line on stderr, got:\n{err}"
    line = err_lines[0] if err_lines else [ln for ln in out.splitlines() if ln.strip()][-1]
    for frag in fragments:
        assert frag in line, f"{frag!r} not in {line!r}"


def _run_main(entry, argv: list[str], capsys) -> tuple[int, str, str]:
    try:
        rc = entry(argv)
    except SystemExit as exc:  # argparse
        rc = exc.code if isinstance(exc.code, int) else 1
    captured = capsys.readouterr()
    return rc, captured.out, captured.err


@pytest.mark.parametrize(("argv", "fragments"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_cli_bad_input(files, capsys, argv, fragments, monkeypatch, tmp_path):
    if "--tensorboard" in argv and HAS_TENSORBOARD:
        pytest.skip("tensorboard is installed here")
    monkeypatch.chdir(tmp_path)
    rc, out, err = _run_main(main, _fill(argv, files), capsys)
    _check(rc, out, err, _fill(fragments, files))


@pytest.mark.parametrize(("argv", "fragments"), [c[1:] for c in MAPGEN_CASES],
                         ids=[c[0] for c in MAPGEN_CASES])
def test_mapgen_bad_input(files, capsys, argv, fragments, monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")  # no window, even on a desktop
    rc, out, err = _run_main(MAPGEN.main, _fill(argv, files), capsys)
    _check(rc, out, err, _fill(fragments, files))


def _env() -> dict[str, str]:
    return {**os.environ, "SDL_VIDEODRIVER": "dummy", "PYGAME_HIDE_SUPPORT_PROMPT": "1"}


@pytest.mark.parametrize(("argv", "fragments"), [
    (["replay", "{flipped_npz}"], ["{flipped_npz}"]),
    (["maps", "{latin1_txt}"], ["{latin1_txt}", "UTF-8"]),
    (["train", "--resume", "{dir}/runs/nosuch"], ["no such checkpoint"]),
], ids=["replay-flipped", "maps-latin1", "train-resume"])
def test_real_processes_fail_in_one_line(files, argv, fragments):
    proc = subprocess.run([sys.executable, "-m", "alphatank.cli", *_fill(argv, files)],
                          capture_output=True, text=True, env=_env(), timeout=120)
    _check(proc.returncode, proc.stdout, proc.stderr, _fill(fragments, files))


def test_mapgen_tool_process_fails_in_one_line(files):
    proc = subprocess.run([sys.executable, str(ROOT / "tools" / "mapgen.py"), "validate",
                           files["utf16_txt"]], capture_output=True, text=True, env=_env(),
                          timeout=120)
    _check(proc.returncode, proc.stdout, proc.stderr, [files["utf16_txt"], "UTF-16"])


def test_closed_pipe_is_quiet():
    """`alphatank maps | head -n 1`: the first line, then a quiet exit (status 141)."""
    proc = subprocess.run(f"{sys.executable} -m alphatank.cli maps | head -n 1; "
                          "echo status=${PIPESTATUS[0]}", shell=True, executable="/bin/bash",
                          capture_output=True, text=True, env=_env(), timeout=120)
    assert proc.stdout.splitlines()[0].startswith("name")
    assert proc.stdout.splitlines()[-1] == "status=141"
    assert proc.stderr == ""


def test_a_broken_pipe_is_taken_for_stdouts_only_when_its_reader_is_gone():
    """A BrokenPipeError from another pipe (an env worker's that failed to start) ended
    the command with status 141 and no word, as if stdout's reader had gone away: the
    command line now asks stdout itself (a real pipe, its reader open, then closed)."""
    probe = ("import sys, time; from alphatank.cli import stdout_reader_gone; "
             "time.sleep(0.3); print(stdout_reader_gone(), file=sys.stderr)")
    for close in (False, True):
        proc = subprocess.Popen([sys.executable, "-c", probe], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, env=_env())
        if close:
            proc.stdout.close()
        assert proc.stderr.read().strip() == str(close)
        proc.wait(timeout=60)
        if not close:
            proc.stdout.close()


def test_version_and_help(capsys):
    from alphatank import __version__

    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0 and capsys.readouterr().out.strip() == f"alphatank {__version__}"
    with pytest.raises(SystemExit):
        main(["eval", "--help"])
    out = capsys.readouterr().out
    assert "95% intervals" in out and "%%" not in out


def test_help_and_one_verb_import_no_other_verbs_modules():
    """`alphatank --help` lists the verbs from their help lines alone, and a verb imports
    its own module only: the help and `maps` start without numba or torch."""
    code = ("import sys\nfrom alphatank.cli import main\n"
            "try:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in ('numba', 'torch', 'alphatank.commands.play') "
            "if m in sys.modules))\n")
    for argv, imported in ((["--help"], "[]"), (["maps"], "[]"),
                           (["play", "--help"], "['alphatank.commands.play', 'numba']")):
        proc = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True,
                              text=True, env=_env(), timeout=120)
        assert proc.returncode == 0, proc.stderr
        assert proc.stdout.splitlines()[-1] == imported, (argv, proc.stdout[-300:])
    proc = subprocess.run([sys.executable, "-m", "alphatank.cli", "--help"],
                          capture_output=True, text=True, env=_env(), timeout=120)
    assert all(f"    {verb} " in proc.stdout for verb in ("demo", "train", "agents"))


def test_record_accepts_dash_o(files, tmp_path, capsys):
    out = tmp_path / "m.mp4"
    assert main(["record", "--seats", "smart,random", "--map", "open", "--max-steps", "5",
                 "-o", str(out)]) == 0
    assert out.stat().st_size > 0
    assert "seat" not in capsys.readouterr().err


def test_record_overwrites_a_replay_only_with_force(tmp_path, capsys):
    """An existing --replay file is refused before the match (no video is made), as
    play's --save-replay is; --force overwrites it."""
    old, video = tmp_path / "keep.npz", tmp_path / "m.mp4"
    old.write_bytes(b"old")
    argv = ["record", "--seats", "smart,random", "--map", "open", "--max-steps", "5",
            "-o", str(video), "--replay", str(old)]
    rc, out, err = _run_main(main, argv, capsys)
    _check(rc, out, err, [f"--replay: {old}: exists (use --force to overwrite)"])
    assert old.read_bytes() == b"old" and not video.exists()
    assert main([*argv, "--force"]) == 0
    assert old.read_bytes() != b"old" and video.stat().st_size > 0


def test_replay_render_without_a_display_is_refused_before_any_video(files, tmp_path, capsys):
    """--render with no display: the refusal is the only line, before the header and before
    a --gif beside it is written (it was written, then the window refused, exit 2)."""
    gif = tmp_path / "r.gif"
    rc, out, err = _run_main(main, ["replay", files["good_npz"], "--gif", str(gif), "--render"],
                             capsys)
    _check(rc, out, err, ["replay: no display available", "SDL_VIDEODRIVER=dummy"])
    assert rc == 2 and out == "" and not gif.exists()


def test_record_refuses_a_map_beside_a_scenario(tmp_path, capsys):
    """--map picks the map for --seats: beside --scenario it was ignored (the match played
    on the scenario's map, even for a map that does not exist); refused, no video made."""
    video = tmp_path / "m.mp4"
    rc, out, err = _run_main(main, ["record", "--scenario", "vs_smart", "--map", "nowhere",
                                    "--max-steps", "5", "-o", str(video)], capsys)
    _check(rc, out, err, ["--map picks the map for --seats; a --scenario plays on its own map "
                          "(give either --scenario or --map, not both)"])
    assert rc == 2 and not video.exists()


@pytest.mark.parametrize(("seats", "why"), [("human,random", "needs a player at the keyboard"),
                                            ("learner,random", "is a learner seat")])
def test_arena_refuses_a_seat_before_its_header(capsys, seats, why):
    """A seat the arena cannot play: the error is the only line (the header of the games
    it would play was printed first)."""
    rc, out, err = _run_main(main, ["arena", "--seats", seats], capsys)
    _check(rc, out, err, [why])
    assert rc == 2 and out == ""


def test_maps_lists_shipped_folders(capsys):
    assert main(["maps"]) == 0
    out = capsys.readouterr().out
    assert "train/maze_0000" in out and "test/maze_0009" in out
    assert "folder train/" in out and "folder test/" in out
    assert main(["maps", "test"]) == 0
    assert capsys.readouterr().out.count(": ok,") == 4


def test_eval_pool_without_shared_opponents_is_refused_before_any_game(files, capsys, tmp_path):
    """Rows that meet no opponent in common: one error naming what each meets, no table,
    no --json / --csv written."""
    rows = [tmp_path / "pool.json", tmp_path / "pool.csv"]
    rc, out, err = _run_main(main, ["eval", "agent:ppo_vs_smart", files["run"], "--pool",
                                    "--json", str(rows[0]), "--csv", str(rows[1])], capsys)
    _check(rc, out, err, ["--pool needs two or more checkpoints against the same opponents",
                          "agent:ppo_vs_smart: B:smart(w=1)", "B:aggressive(w=1)"])
    assert out == "" and not any(p.exists() for p in rows)


def test_eval_pool_of_one_checkpoint_twice_is_refused_before_any_game(files, capsys):
    """The same checkpoint twice (or spelled two ways) would pool its games twice: refused
    naming both arguments (the error said they met no opponent in common)."""
    for again in (files["run"], f"checkpoint:{files['ckpt']}"):
        rc, out, err = _run_main(main, ["eval", files["run"], again, "--pool"], capsys)
        _check(rc, out, err, [f"--pool: {files['run']} and {again} are one checkpoint",
                              "give each run once"])
        assert out == ""


@pytest.mark.parametrize(("argv", "fragments"), [
    (["--ticks", "10", "--preset", "nope"], ["unknown preset 'nope'"]),
    (["--ticks", "10", "--train", "--train-preset", "nope"],
     ["--train-preset nope: unknown training preset 'nope'; valid: ", "ppo_vs_smart"]),
    (["--ticks", "10", "--train", "--train-preset", "sac_vs_aggressive", "--train-fragments",
      "--train-envs", "2", "--train-workers", "1", "--train-iterations", "1"],
     ["--train-preset sac_vs_aggressive --train-fragments: ",
      "fragments are acted by PPO and MAPPO learners only"]),
    (["--soak", "--steps", "3000", "--scenarios", "vs_random"],
     ["--steps must be >= 10001 with --sample-every 10000 and 1 scenario(s)", "got 3000"]),
], ids=["preset", "train-preset", "train-sac-fragments", "soak-too-short"])
def test_bench_checks_every_setting_before_measuring(capsys, tmp_path, argv, fragments):
    """A bad game preset, training preset or a --train combination `alphatank train`
    refuses, or a soak too short to measure a growth (it read 'soak FAILED', exit 1, as a
    leak): one line, exit 2, before any header, figure or --json file."""
    rc, out, err = _run_main(main, ["bench", "--json", str(tmp_path / "b.json"), *argv],
                             capsys)
    _check(rc, out, err, fragments)
    assert rc == 2 and out == "" and not (tmp_path / "b.json").exists()
