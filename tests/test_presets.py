"""Training runs as data: every shipped preset loads, fits its scenario and round-trips
through TOML; malformed run files give one-line errors naming the file and the field."""

import dataclasses
import os
import threading
import tomllib
from importlib import resources

import pytest

from alphatank.game.scenarios import load_scenario
from alphatank.training.hparams import PPOConfig, SACConfig
from alphatank.training.presets import (
    LearnerSpec,
    TrainConfig,
    get_preset,
    learners_fit,
    load_run,
    parse_run,
    preset_names,
    run_learners,
    run_scenario,
    run_toml,
)

PAPER_PRESETS = {"ppo_vs_ppo", "sac_vs_sac", "sac_vs_ppo", "ppo_vs_smart", "ppo_vs_aggressive",
                 "ppo_vs_dodge", "ppo_vs_defensive", "ppo_vs_random", "sac_vs_aggressive",
                 "ppo_cycle", "ppo_curriculum_smart", "team_vs_2smart", "team_vs_def",
                 "team_vs_def_2smart", "team_vs_four_bots", "team_ppo_vs_ppo", "demo",
                 "team_vs_2smart_ippo", "team_vs_def_ippo", "team_vs_def_2smart_ippo",
                 "team_vs_four_bots_ippo", "team_ppo_vs_ppo_ippo"}


def roundtrip(cfg: TrainConfig) -> TrainConfig:
    return parse_run(tomllib.loads(run_toml(cfg)), "<text>")


@pytest.mark.parametrize("name", preset_names())
def test_every_preset_loads_fits_its_scenario_and_round_trips(name):
    cfg = get_preset(name)
    assert cfg.name == name and cfg.description
    sc = load_scenario(cfg.scenario)
    n = len(sc.learner_seats)
    assert learners_fit(run_learners(cfg, n), n, selfplay=bool(cfg.selfplay))
    assert roundtrip(cfg) == cfg
    assert TrainConfig.from_dict(cfg.to_dict()) == cfg  # the checkpoint path


def test_presets_keep_the_papers_settings():
    assert set(preset_names()) >= PAPER_PRESETS
    ppo, sac = PPOConfig(), SACConfig()
    sac_vs_ppo = get_preset("sac_vs_ppo")
    assert [(s.name, s.algo, s.seats) for s in sac_vs_ppo.learners] == [
        ("sac", "sac", (0,)), ("ppo", "ppo", (1,))]
    assert sac_vs_ppo.learners[0].config == sac  # Table 8
    assert sac_vs_ppo.learners[1].config == PPOConfig(clip_coef=0.1, ent_coef=0.02,
                                                      update_epochs=20)  # Table 9
    assert sac_vs_ppo.total_steps == 200_000 and sac_vs_ppo.scenario == "pair"
    assert get_preset("ppo_vs_random").learners[0].config == ppo  # Table 7
    for name in ("ppo_vs_smart", "ppo_vs_aggressive", "ppo_vs_dodge"):  # Table 3 rows as
        row = get_preset(name)  # shipped: Table 7 but 128 steps x 4 epochs, 15 min at most
        assert row.learners[0].config == PPOConfig(num_steps=128, update_epochs=4)
        assert row.time_limit_s == 900 and row.rewards == {} and "Table 7" in row.description
    for name in ("team_vs_2smart", "team_vs_def", "ppo_vs_defensive"):  # rows with other
        assert "not the paper's rewards" in get_preset(name).description  # rewards say so
    for name in ("team_vs_def_2smart", "team_vs_four_bots"):  # the paper's team env
        row = get_preset(name)
        assert row.rewards == {} and "paper rewards" in row.description
        assert load_scenario(row.scenario).game == {"random_spawns": True}
        assert row.imitate["bot"] == "smart" and row.observation == "egocentric_full"
        assert [(s.algo, s.seats) for s in row.learners] == [("ppo", (0, 1))]  # shared
    for name in ("team_vs_def_2smart", "team_vs_four_bots"):  # actions held 2 ticks
        assert get_preset(name).action_repeat == 2
    assert get_preset("team_vs_def_2smart").learners[0].config.hidden == 256  # as shipped
    assert get_preset("ppo_vs_smart").action_repeat == 1
    demo = get_preset("demo")
    assert demo.learners[0].config == PPOConfig(num_steps=128, update_epochs=4,
                                                num_minibatches=4, anneal_lr=True)
    assert (demo.num_workers, demo.checkpoint_every, demo.time_limit_s) == (2, 50, 480.0)
    assert get_preset("ppo_cycle").schedule == {
        "kind": "cycle", "pool": ["random", "aggressive", "defensive", "dodge"],
        "mode": "adaptive", "interval": 100_000}
    assert get_preset("ppo_curriculum_smart").schedule == {
        "kind": "curriculum", "start": 0.1, "end": 0.8, "shape": "sigmoid"}
    assert [s.seats for s in get_preset("team_ppo_vs_ppo_ippo").learners] == [
        (0,), (1,), (2,), (3,)]
    for name in ("team_vs_2smart", "team_vs_def", "team_vs_def_2smart", "team_vs_four_bots"):
        ippo = get_preset(f"{name}_ippo")  # the paper's rows: independent PPO, Table 5
        assert [(s.algo, s.seats) for s in ippo.learners] == [("ppo", (0,)), ("ppo", (1,))]
        assert ippo.rewards == {} and ippo.learners[0].config == ppo
    sp = get_preset("team_ppo_vs_ppo")  # self-play against a window of snapshots
    assert [(s.algo, s.seats) for s in sp.learners] == [("mappo", (0, 1))]
    assert sp.selfplay["window"] >= 1 and "not the paper's rewards" in sp.description


def test_every_setting_round_trips_including_none_and_tables(tmp_path):
    cfg = TrainConfig(
        "custom", "vs_smart", "all kinds of values", map="train", observation="egocentric",
        total_steps=123_456, seed=9, game={"max_steps": 300, "friendly_fire": False},
        rewards={"aim_streak": 5.0}, wandb="disabled", time_limit_s=12.5,
        learners=(LearnerSpec("p", "ppo", (0,), PPOConfig(target_kl=0.05, norm_adv=False)),))
    assert roundtrip(cfg) == cfg
    sac = TrainConfig("s", "pair", learners=(
        LearnerSpec("a", "sac", (0,), SACConfig(target_entropy=-1.5, utd_ratio=0.25)),
        LearnerSpec("b", "sac", (1,))))
    assert roundtrip(sac) == sac
    path = tmp_path / "mine.toml"
    path.write_text(run_toml(cfg))
    assert load_run(path) == cfg


def test_strings_with_quotes_newlines_and_control_characters_round_trip():
    """A DEL (\\x7f) was written raw: the file did not read back ('invalid TOML')."""
    odd = 'runs/"a" \\ b\n\tc\x7f\x00 é ☃'
    cfg = TrainConfig("odd", "vs_smart", init_from=odd, project="it's \"x\"", wandb="disabled")
    assert roundtrip(cfg) == cfg


def test_none_is_read_in_any_case_as_on_the_command_line():
    """'NONE' or 'null' was 'needs a float or none, got 'NONE'' (--hp reads them as none)."""
    for text in ("NONE", "None", "null"):
        cfg = parse_run({"scenario": "vs_smart", "learners": [
            {"name": "p", "config": {"target_kl": text, "clip_coef": 0.1}}]}, "<text>")
        assert cfg.learners[0].config == PPOConfig(target_kl=None, clip_coef=0.1)


def test_run_file_defaults_its_name_and_resolves_paths_beside_it(tmp_path):
    folder = tmp_path / "exp"
    folder.mkdir()
    (folder / "arena.toml").write_text(
        'name = "arena"\nmap = "open"\n[[seats]]\nteam = "A"\ncontroller = "learner"\n'
        '[[seats]]\nteam = "B"\ncontroller = "bot"\nbot = "dodge"\n')
    (folder / "run.toml").write_text('scenario = "arena.toml"\ntotal_steps = 1000\n')
    cfg = load_run(folder / "run.toml")
    assert cfg.name == "run" and cfg.learners == ()
    assert run_scenario(cfg).seats[1].bot == "dodge"
    # a folder of maps named without a '/' was looked up among the shipped maps only
    # ('unknown map 'mine''), where a scenario file's map finds it beside the file
    (folder / "mine").mkdir()
    (folder / "mine" / "a.txt").write_text(
        resources.files("alphatank.maps").joinpath("open.txt").read_text())
    (folder / "run2.toml").write_text('scenario = "vs_smart"\nmap = "mine"\n')
    assert run_scenario(load_run(folder / "run2.toml")).maps == (str(folder / "mine" / "a.txt"),)


def test_map_override_swaps_the_scenarios_map():
    cfg = dataclasses.replace(get_preset("ppo_vs_smart"), map="train")
    sc = run_scenario(cfg)
    assert len(sc.maps) == 16 and sc.seats == load_scenario("vs_smart").seats


BAD = [
    ("scenario = 'vs_smart'\ntotl_steps = 5\n", r"bad\.toml: totl_steps: unknown key; valid "
                                                r"keys: \[.*'total_steps'"),
    ("scenario = 'vs_smart'\ntotal_steps = -5\n", r"bad\.toml: total_steps: must be > 0, got -5"),
    ("scenario = 'vs_smart'\ntotal_steps = 'many'\n",
     r"bad\.toml: total_steps: needs an int, got 'many'"),
    ("scenario = 'vs_smart'\nwandb = 'cloud'\n",
     r"bad\.toml: wandb: must be one of offline, online, disabled, got 'cloud'"),
    ("total_steps = 5\n", r"bad\.toml: scenario: required"),
    # read as the current folder ('scenario: .: a folder, not a scenario file'), or an error
    # naming the scenario's file, not this one
    ("scenario = ''\n", r"bad\.toml: scenario: is empty; give a shipped scenario name or a "
                         r"path to a \.toml$"),
    ("scenario = 'vs_smart'\nmap = ''\n", r"bad\.toml: map: is empty; give a shipped map or "
                                           r"folder name or a path, or leave it out$"),
    ("scenario = 'pair'\n[[learners]]\nname = 'a'\n[[learners]]\nname = 'b'\nseats = [1]\n"
     "[learners.config]\nclip_coef = -1\n",
     r"bad\.toml: learners\[1\]\.config\.clip_coef: must be > 0, got -1\.0"),
    ("scenario = 'pair'\n[[learners]]\nname = 'a'\n[learners.config]\nclip = 1\n",
     r"bad\.toml: learners\[0\]\.config\.clip: unknown key; valid keys: \[.*'clip_coef'"),
    ("scenario = 'pair'\n[[learners]]\nname = 'a'\nalgo = 'dqn'\n",
     r"bad\.toml: learners\[0\]\.algo: unknown algorithm 'dqn'; registered: \[.*'ppo'"),
    # a list raised TypeError (unhashable) out of the algorithm table: a traceback
    ("scenario = 'pair'\n[[learners]]\nname = 'a'\nalgo = ['ppo']\n",
     r"bad\.toml: learners\[0\]\.algo: unknown algorithm \['ppo'\]; registered: \[.*'ppo'"),
    ("scenario = 'pair'\n[[learners]]\nname = 'a'\nseat = 1\n",
     r"bad\.toml: learners\[0\]\.seat: unknown key; valid keys: \['name', 'algo', 'seats'"),
    ("scenario = 'pair'\n[[learners]]\nname = 'a'\nseats = [0, 0]\n",
     r"bad\.toml: learners\[0\]: learner 'a': seats must be distinct"),
    ("scenario = 'pair'\n[[learners]]\nname = 'a'\n[[learners]]\nname = 'a'\nseats = [1]\n",
     r"bad\.toml: learners: names must be unique"),
    # said 'needs an int, got 2000000.0' only: TOML reads 2e6 as a float
    ("scenario = 'vs_smart'\ntotal_steps = 2e6\n",
     r"bad\.toml: total_steps: needs an int, got 2000000\.0 \(an integer is written without a "
     r"point or exponent: 2_000_000\)$"),
    ("scenario = 'vs_smart'\ntotal_steps = 1e300\n",
     r"bad\.toml: total_steps: needs an int, got 1e\+300$"),
    ("scenario = 'pair'\n[[learners]]\nname = 'a'\n[learners.config]\nupdate_epochs = 2.5\n",
     r"bad\.toml: learners\[0\]\.config\.update_epochs: needs an int, got 2\.5"),
    ("scenario = 'vs_smart'\n[schedule]\nkind = 'tournament'\n",
     r"bad\.toml: schedule: unknown schedule kind 'tournament'"),
    ("scenario = 'vs_smart'\n[schedule]\nkind = 'cycle'\npool = ['random']\nmode = 'often'\n",
     r"bad\.toml: schedule: cycle mode must be one of"),
    ("scenario = 'vs_smart'\n[schedule]\nkind = 'cycle'\npool = ['smart', 'nosuch']\n",
     r"bad\.toml: schedule: cycle pool: unknown bot 'nosuch'; valid bots: \[.*'dodge'"),
    ("scenario = 'vs_smart'\n[schedule]\nkind = 'cycle'\npool = ['smart']\nfoo = 1\n",
     r"bad\.toml: schedule: foo: unknown key for kind 'cycle'; valid keys: \[.*'interval'"),
    ("scenario = 'vs_smart'\n[schedule]\nkind = 'cycle'\nmode = 'random'\n",
     r"bad\.toml: schedule: pool: required for kind 'cycle'"),
    ("scenario = 'vs_smart'\n[schedule]\nkind = 'cycle'\npool = ['smart']\nweakness = 5.0\n",
     r"bad\.toml: schedule: weakness must be in \[0, 1\], got 5"),
    ("scenario = 'vs_smart'\n[schedule]\nkind = 'cycle'\npool = ['smart']\n"
     "scale_victory = 'no'\n",
     r"bad\.toml: schedule: scale_victory must be true or false, got 'no'"),
    ("scenario = 'vs_smart'\n[schedule]\nkind = 'cycle'\npool = ['smart']\ninterval = 1.5\n",
     r"bad\.toml: schedule: interval must be an integer, got 1\.5"),
    ("scenario = 'vs_smart'\n[schedule]\nkind = 'curriculum'\nstart = '0.1'\n",
     r"bad\.toml: schedule: start must be a number, got '0\.1'"),
    ("scenario = 'vs_smart'\n[game]\nmax_step = 5\n",
     r"bad\.toml: game\.max_step: unknown GameConfig key; valid keys: \[.*'max_steps'"),
    ("scenario = 'vs_smart'\n[rewards]\nvictory = 'big'\n",
     r"bad\.toml: rewards\.victory: needs a float, got 'big'"),
    ("scenario = 'vs_smart'\ngame = 3\n", r"bad\.toml: game: needs a table, got 3"),
    ("scenario = 'vs_smart\n", r"bad\.toml: invalid TOML"),
    # said 'must be a number'; a window past 2**63 raised OverflowError as the run started
    ("scenario = 'team'\n[selfplay]\nwindow = 1.5\n[[learners]]\nname = 't'\nseats = [0, 1]\n",
     r"bad\.toml: selfplay\.window: must be an integer, got 1\.5$"),
    ("scenario = 'team'\n[selfplay]\nwindow = 1e300\n[[learners]]\nname = 't'\nseats = [0, 1]\n",
     r"bad\.toml: selfplay: snapshot pool needs window >= 1 and at most 10,000 \(snapshots "
     r"kept\), got 1e\+300$"),
    ("scenario = 'team'\n[selfplay]\nevery = inf\n[[learners]]\nname = 't'\nseats = [0, 1]\n",
     r"bad\.toml: selfplay\.every: must be an integer, got inf$"),
    # wandb refused these with a traceback once the run had started
    ("scenario = 'vs_smart'\nproject = 'me/tanks'\n",
     r"bad\.toml: project: must be a wandb project name: at most 128 characters, none of "
     r"/ \\ # \? % :, got 'me/tanks'"),
    ("scenario = 'vs_smart'\nwandb = 'online'\nproject = '" + "p" * 129 + "'\n",
     r"bad\.toml: project: must be a wandb project name"),
]


@pytest.mark.parametrize("text,error", BAD)
def test_malformed_run_files_name_the_file_and_the_field(tmp_path, text, error):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=error) as info:
        load_run(path)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("text,near", [
    ("totl_steps = 5", "total_steps"),
    ("[[learners]]\nname = 'a'\nseat = [0]", "seats"),
    ("[[learners]]\nname = 'a'\nalgo = 'PPO'", "ppo"),
    ("[[learners]]\nname = 'a'\n[learners.config]\nlearningrate = 1.0", "learning_rate"),
    ("[schedule]\nkind = 'curriculm'", "curriculum"),
    ("[schedule]\nkind = 'curriculum'\nstrat = 0.1", "start"),
    ("[selfplay]\nwindw = 3", "window"),
    ("[game]\nmax_step = 5", "max_steps"),
    ("xyz = 1", None),
])
def test_a_misspelt_key_or_name_suggests_the_nearest_valid_one(tmp_path, text, near):
    """The errors listed the valid keys only (28 of them for the run's own)."""
    path = tmp_path / "typo.toml"
    path.write_text(f"scenario = 'vs_smart'\n{text}\n")
    with pytest.raises(ValueError, match=r"typo\.toml: .*(unknown|registered)") as info:
        load_run(path)
    message = str(info.value)
    if near is None:
        assert "did you mean" not in message
    else:
        assert message.endswith(f"; did you mean {near!r}?"), message


def test_unknown_preset_and_missing_file_are_named(tmp_path):
    with pytest.raises(ValueError, match=r"unknown training preset 'nope'; valid: \[.*'demo'"):
        get_preset("nope")
    with pytest.raises(ValueError, match=r"\]; did you mean 'ppo_vs_smart'\?$"):
        get_preset("ppo_vs_smrt")
    with pytest.raises(ValueError, match="missing.toml: no such run file"):
        load_run(tmp_path / "missing.toml")


def test_a_run_file_may_come_through_a_pipe(tmp_path):
    """``--config <(alphatank train --print-config ...)``: a pipe was 'no such run file'."""
    fifo = tmp_path / "piped.toml"
    os.mkfifo(fifo)
    writer = threading.Thread(target=fifo.write_text, args=("scenario = 'vs_smart'\n",))
    writer.start()
    try:
        cfg = load_run(fifo)
    finally:
        writer.join(timeout=10)
        if writer.is_alive():  # the pipe was never opened: release the writer's open()
            os.close(os.open(fifo, os.O_RDONLY | os.O_NONBLOCK))
            writer.join()
    assert (cfg.name, cfg.scenario) == ("piped", "vs_smart")
    with pytest.raises(ValueError, match=r"^/dev/null: not a file, nor a pipe$"):
        load_run("/dev/null")


def test_a_project_name_is_checked_only_for_a_run_that_logs_to_wandb(tmp_path):
    """Runs without wandb never used their project: such a run file (and its checkpoints)
    still loads."""
    path = tmp_path / "quiet.toml"
    path.write_text("scenario = 'vs_smart'\nwandb = 'disabled'\nproject = 'me/tanks'\n")
    assert load_run(path).project == "me/tanks"
