"""Episodes as jobs: serial and Ray runs agree, interrupted runs resume, sweeps check their
configs, and RLlib trains one iteration whose checkpoint ``proteo eval`` loads.

Ray runs here on a local instance with 2 CPUs (tests/test_ray_cluster.py simulates two nodes).
"""

from __future__ import annotations

import csv
import json

import pytest

from proteo_env.config import ConfigError

ray = pytest.importorskip("ray")
pytestmark = pytest.mark.slow  # Ray: make test-all

EVAL_CONFIG = {
    "seeds": 3,
    "first_seed": 5,
    "tasks": {
        "chain": {"env": {"n_modules": 8, "max_cycles": 60}},
        "table": {"env": {"board_size": 6, "depth": 2, "n_spares": 8, "motion_model": "minimal", "max_cycles": 40}},
    },
}
TASKS = ["chain", "table"]
CMA = [
    "--config",
    "configs/train/cma_rules_chain_full.yaml",
    "--generations",
    "2",
    "--popsize",
    "4",
    "--episodes-per-candidate",
    "2",
    "--env",
    "{n_modules: 8, max_cycles: 60}",
    "--tensorboard",
    "false",
]


@pytest.fixture(scope="module")
def local_ray():
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def _eval_config(tmp_path):
    path = tmp_path / "eval.yaml"
    path.write_text(json.dumps(EVAL_CONFIG))
    return path


def _episodes(out) -> list:
    """Every episode of an evaluation, without its wall-clock time."""
    data = json.loads((out / "results.json").read_text())
    return [
        {k: v for k, v in run.items() if k != "seconds"} | {"task": row["task"], "policy": row["policy"]}
        for row in data["rows"]
        for run in row["runs"]
    ]


def _progress(run_dir) -> list:
    with (run_dir / "progress.csv").open() as fh:
        return [{k: v for k, v in row.items() if k != "seconds"} for row in csv.DictReader(fh)]


class Interrupt(Exception):
    """Stands for Ctrl-C or a killed driver in the middle of a run."""


def _interrupting(fn, after: int, calls: list):
    """``fn`` (the evaluator's ``run_batch``), raising :class:`Interrupt` at its call ``after + 1``;
    ``calls`` gets the episodes of each batch that ran."""

    def wrapped(episodes, *args, **kwargs):
        if len(calls) == after:
            raise Interrupt
        calls.append(len(episodes))
        return fn(episodes, *args, **kwargs)

    return wrapped


# ---------------------------------------------------------------------- resume (one process)
def test_interrupted_eval_resumes_without_losing_or_repeating_episodes(tmp_path, monkeypatch):
    from training.judging import evaluate as ev
    from training.machinery import evaluator

    config = _eval_config(tmp_path)
    run = {"config": config, "tasks": TASKS, "progress": False, "plots": False, "workers": 1}
    ev.run_evaluation(**run, out=tmp_path / "whole")
    original, calls = evaluator.run_batch, []
    monkeypatch.setattr(evaluator, "run_batch", _interrupting(original, 2, calls))  # 4 batches: 2 tasks x 2 policies
    with pytest.raises(Interrupt):
        ev.run_evaluation(**run, out=tmp_path / "cut")
    assert not (tmp_path / "cut" / "results.md").exists()  # no partial table
    with (tmp_path / "cut" / "episodes.jsonl").open("a") as fh:
        fh.write('{"key": "torn')  # the driver died while writing
    with pytest.raises(ConfigError, match="unfinished evaluation with other settings.*seeds"):
        ev.run_evaluation(**{**run, "seeds": 2}, out=tmp_path / "cut")
    calls.clear()
    monkeypatch.setattr(evaluator, "run_batch", _interrupting(original, 10**6, calls))
    ev.run_evaluation(**run, out=tmp_path / "cut")
    total = len(_episodes(tmp_path / "whole")) * 3
    assert sum(calls) == total - 6  # only the missing episodes ran
    assert _episodes(tmp_path / "cut") == _episodes(tmp_path / "whole")
    calls.clear()
    ev.run_evaluation(**run, out=tmp_path / "cut")
    assert sum(calls) == total  # a finished evaluation runs anew


def test_interrupted_cma_es_resumes_the_interrupted_generation(tmp_path, monkeypatch):
    from training.machinery import evaluator
    from training.trainers import cma_es

    cma = [*CMA, "--workers", "1"]
    cma_es.main([*cma, "--run-dir", str(tmp_path / "whole")])
    original, calls = evaluator.run_batch, []
    monkeypatch.setattr(evaluator, "run_batch", _interrupting(original, 1, calls))  # one batch per generation
    with pytest.raises(Interrupt):
        cma_es.main([*cma, "--run-dir", str(tmp_path / "cut")])
    calls.clear()
    monkeypatch.setattr(evaluator, "run_batch", _interrupting(original, 10**6, calls))
    cma_es.main([*cma, "--run-dir", str(tmp_path / "cut")])
    assert calls == [8]  # generation 2 only: 4 candidates x 2 worlds
    assert _progress(tmp_path / "cut") == _progress(tmp_path / "whole")
    with pytest.raises(ConfigError, match="not empty"):  # a finished run is not resumed by accident
        cma_es.main([*cma, "--run-dir", str(tmp_path / "cut")])


def test_cma_es_resumed_from_a_checkpoint_goes_on_as_the_whole_run_and_refuses_other_arguments(tmp_path):
    """The run base (training/machinery/runs.py) gives CMA-ES what evolution has: ``--resume CHECKPOINT``
    restores the search and its world stream, and arguments the results depend on must match."""
    from training.trainers import cma_es

    cma = [*CMA[:2], *CMA[4:], "--workers", "1", "--checkpoint-every", "1"]
    whole = cma_es.main([*cma, "--generations", "2", "--run-dir", str(tmp_path / "whole")])
    cma_es.main([*cma, "--generations", "1", "--run-dir", str(tmp_path / "cut")])
    resumed = cma_es.main(
        [*cma, "--generations", "2", "--run-dir", str(tmp_path / "on"), "--resume", str(tmp_path / "cut")]
    )
    assert (
        json.loads((resumed / "proteo.json").read_text())["params"]
        == json.loads((whole / "proteo.json").read_text())["params"]
    )
    assert _progress(tmp_path / "on")[-1:] == _progress(tmp_path / "whole")[-1:]
    with pytest.raises(ConfigError, match=r"other arguments \(differing: sigma0\)"):
        cma_es.main(
            [
                *cma,
                "--generations",
                "2",
                "--sigma0",
                "0.3",
                "--run-dir",
                str(tmp_path / "no"),
                "--resume",
                str(tmp_path / "cut"),
            ]
        )


# ---------------------------------------------------------------------- Ray == one process
def test_eval_on_ray_equals_serial(tmp_path, local_ray, capsys):
    from training.cli import main

    config = _eval_config(tmp_path)
    flags = ["eval", "--config", str(config), "--tasks", ",".join(TASKS), "--no-plots"]
    assert main([*flags, "--out", str(tmp_path / "serial"), "--workers", "1"]) == 0
    assert main([*flags, "--out", str(tmp_path / "ray"), "--ray", "--workers", "2"]) == 0
    assert _episodes(tmp_path / "ray") == _episodes(tmp_path / "serial")
    assert [len(r["returns"]) for r in _episodes(tmp_path / "ray")] == [3] * 4  # 2 tasks x hand-coded, random


def test_cma_es_on_ray_equals_serial(tmp_path, local_ray):
    from training.trainers import cma_es

    cma_es.main([*CMA, "--run-dir", str(tmp_path / "serial")])
    cma_es.main([*CMA, "--run-dir", str(tmp_path / "ray"), "--ray", "true"])
    assert _progress(tmp_path / "ray") == _progress(tmp_path / "serial")
    meta = [json.loads((tmp_path / d / "final" / "proteo.json").read_text()) for d in ("serial", "ray")]
    assert meta[0]["params"] == meta[1]["params"]


# ---------------------------------------------------------------------- sweep configs
SWEEP = "task: chain-v1\nenv: {max_cycles: 40}\ngrid:\n  n_modules: [6, 8]\nseeds: 2\nplot: {x: n_modules}\n"


@pytest.mark.parametrize(
    "text, message",
    [
        (SWEEP + "colour: red\n", "unknown key 'colour'; allowed: env, first_seed, grid"),
        (SWEEP.replace("[6, 8]", "[]"), r"grid.n_modules=\[\] is not allowed; allowed: a non-empty list"),
        ("task: chain-v1\ngrid: {}\n", "grid={} is empty"),
        (SWEEP.replace("n_modules", "n_modlues"), "grid point .*unknown key 'n_modlues'"),
        (SWEEP + "search: random\nsamples: 5\n", r"samples=5 is not allowed with search: random; allowed: 1..2"),
        (
            SWEEP.replace("seeds: 2", "seeds: 2\npolicies: [chian]"),
            "policies: 'chian' is not allowed; allowed: default, branch, chain",
        ),
        (SWEEP.replace("{x: n_modules}", "{x: size}"), "plot.x='size' is not allowed; allowed: n_modules, policy"),
    ],
)
def test_bad_sweep_config_is_one_clear_error(tmp_path, text, message):
    from training.sweep import sweep

    path = tmp_path / "sweep.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        sweep(path, out=tmp_path / "out", progress=False)
    assert not (tmp_path / "out" / "summary.csv").exists()


def test_sweep_tables_tie_settings_and_sample_points(tmp_path):
    from training.sweep import sweep

    path = tmp_path / "sweep.yaml"
    path.write_text(
        "task: table-v1\nenv: {board_size: 6, depth: 2, n_spares: 8, motion_model: minimal, "
        "max_cycles: 30}\ngrid:\n  p_max=p_min: [0.1, 0.5, 0.9]\n  f_max: [2.0, 3.0]\nseeds: 2\n"
        "search: random\nsamples: 3\nplot: {x: p_max=p_min, y: support, hue: f_max}\n"
    )
    summary = sweep(path, out=tmp_path / "out", progress=False)
    assert len(summary) == 3 and all(r["episodes"] == 2 and r["y"] == "support" for r in summary)
    with (tmp_path / "out" / "episodes.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6 and {"p_max=p_min", "f_max", "seed", "return", "success", "support"} <= set(rows[0])
    assert (tmp_path / "out" / "sweep.png").stat().st_size > 1000


# ---------------------------------------------------------------------- RLlib
def test_rllib_one_iteration_checkpoint_loads_in_eval(tmp_path, local_ray):
    from training.judging.evaluate import run_evaluation
    from training.trainers import rllib_ppo

    final = rllib_ppo.main(
        [
            "--iterations",
            "1",
            "--env-runners",
            "2",
            "--train-batch-size",
            "128",
            "--minibatch-size",
            "64",
            "--n-epochs",
            "1",
            "--env",
            "{n_modules: 6, max_cycles: 16}",
            "--run-dir",
            str(tmp_path / "run"),
            "--tensorboard",
            "false",
        ]
    )
    meta = json.loads((final / "proteo.json").read_text())
    assert meta["algorithm"] == "rllib-ppo" and meta["control"] == "move" and meta["agent_steps"] >= 128 * 6
    assert (final / "rllib").is_dir()
    config = tmp_path / "eval.yaml"
    config.write_text(json.dumps({"tasks": {"chain": {"env": {"n_modules": 6, "max_cycles": 16}}}}))
    rows = run_evaluation(
        config=config,
        tasks=["chain"],
        seeds=2,
        checkpoints=[str(final)],
        out=tmp_path / "eval",
        progress=False,
        plots=False,
    )
    learned = [r for r in rows if r.kind == "learned"]
    assert len(learned) == 1 and learned[0].level == "move" and learned[0].n == 2


class _RayWhoseFirstLedgerIsDead:
    """Enough of the ``ray`` module for :func:`training.machinery.distributed._ledger`: the kept ledger of
    the first name has died (clearing it raises Ray's actor error), a ledger of another name is alive."""

    exceptions = ray.exceptions

    def __init__(self):
        self.names = []

    def get_runtime_context(self):
        return type("Context", (), {"get_job_id": lambda _: "01000000"})()

    def remote(self, num_cpus):
        outer = self

        class Actor:
            def __init__(self, name):
                self.name = name
                self.clear = type("Method", (), {"remote": lambda _: name})()

        class Options:
            def options(self, name, get_if_exists):
                outer.names.append(name)
                return type("Handle", (), {"remote": lambda _: Actor(name)})()

        return lambda cls: Options()

    def get(self, name):
        if name == "proteo-ledger-01000000":
            raise ray.exceptions.ActorDiedError()
        return None


def test_a_dead_kept_ledger_is_replaced_by_one_of_a_new_name():
    """Ray can hand back the driver's kept ledger after its process died (CI saw ActorDiedError when
    a second run cleared it); the run then starts a new ledger instead of failing."""
    from training.machinery.distributed import _ledger

    fake = _RayWhoseFirstLedgerIsDead()
    ledger = _ledger(fake)
    assert fake.names == ["proteo-ledger-01000000", "proteo-ledger-01000000-1"] and ledger.name == fake.names[-1]
