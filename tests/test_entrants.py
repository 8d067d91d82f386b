"""A policy trained anywhere enters the benchmark: a TorchScript or ONNX network, or a factory's
object, described by an entrant.yaml, judged on the protocol's worlds exactly as our checkpoints
are, with its training declared (not verified) and every bad input refused before a row is written."""

from __future__ import annotations

import importlib.util
import json
import textwrap
from pathlib import Path

import pytest
import yaml

import proteo_env
from proteo_env.config import ConfigError
from proteo_env.rollout import run_episode

torch = pytest.importorskip("torch")

from proteo_env.adapters.flatten import ObservationEncoder  # noqa: E402
from training.judging.judge import judge  # noqa: E402
from training.machinery.entrants import EntrantError  # noqa: E402
from training.machinery.evaluator import Controller, evaluate  # noqa: E402

CHAIN = {"n_modules": 12, "max_cycles": 300, "motion_model": "sphere"}  # protocol v7's chain settings


def relu_network(n_in: int, n_out: int, seed: int = 0) -> torch.nn.Module:
    """A ReLU network with large random weights (its choices matter), as a trainer elsewhere might write."""
    torch.manual_seed(seed)
    net = torch.nn.Sequential(torch.nn.Linear(n_in, 32), torch.nn.ReLU(), torch.nn.Linear(32, n_out))
    with torch.no_grad():
        for p in net.parameters():
            p.mul_(4.0)
    return net.eval()


def chain_encoder(**options) -> ObservationEncoder:
    return ObservationEncoder.for_env(proteo_env.make("chain-v1", **CHAIN, control="move"), **options)


def write_entrant(folder: Path, files: dict, **fields) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    entry = {
        "entrant": 1,
        "name": "outside-net",
        "task": "chain-v1",
        "control": "move",
        "format": "torchscript",
        "seeds": files,
        "observation": {"message_encoding": "compact"},
        "budget": {"agent_steps": 1000},
        "code": "https://example.org/outside-net",
        **fields,
    }
    entry = {k: v for k, v in entry.items() if v is not None}
    (folder / "entrant.yaml").write_text(yaml.safe_dump(entry, sort_keys=False))
    return folder / "entrant.yaml"


def torchscript_entrant(folder: Path, seeds=(0, 1), **fields) -> Path:
    encoder = chain_encoder(message_encoding="compact")
    folder.mkdir(parents=True, exist_ok=True)
    for s in seeds:
        torch.jit.save(torch.jit.script(relu_network(encoder.size, 13, seed=s)), folder / f"seed_{s}.pt")
    return write_entrant(folder, {s: f"seed_{s}.pt" for s in seeds}, **fields)


FACTORY = textwrap.dedent(
    '''
    import numpy as np

    class Walker:
        """Random legal moves, each world with a generator of its own seed."""

        def __init__(self, spec, mode):
            self.spec, self.mode, self.rngs = spec, mode, {}

        def reset(self, world, seed):
            self.rngs[world] = np.random.default_rng(seed)

        def act(self, observation):
            mask = observation["action_mask"]
            b, a = mask.shape[:2]
            out = np.zeros((b, a, len(self.spec.nvec)), dtype=np.int64)
            for w in range(b):
                noise = self.rngs[w].random((a, 13)) * mask[w]
                out[w, :, 0] = noise.argmax(axis=1)
            if self.mode == "illegal":
                out[:, :, 0] = np.where(mask[..., 1] == 0, 1, out[:, :, 0])
            if self.mode == "float":
                return out.astype(float)
            if self.mode == "shape":
                return out[:, :, 0]
            if self.mode == "range":
                out[0, 3, 0] = 13
            return out

    def make(spec):
        return Walker(spec, "legal")

    def make_illegal(spec):
        return Walker(spec, "illegal")

    def make_float(spec):
        return Walker(spec, "float")

    def make_shape(spec):
        return Walker(spec, "shape")

    def make_range(spec):
        return Walker(spec, "range")

    def make_raises(spec):
        raise RuntimeError("no weights here")

    def make_nothing(spec):
        return 42
    '''
)


@pytest.fixture
def walker(tmp_path, monkeypatch):
    (tmp_path / "walker_entrant.py").write_text(FACTORY)
    monkeypatch.syspath_prepend(str(tmp_path))
    return "walker_entrant"


def test_a_torchscript_relu_network_is_judged_as_it_was_trained(tmp_path):
    """The judge plays the network as saved (ReLU and all): the same episodes as the network itself
    through a policy built by hand from the public encoder, and each seed's file digest recorded."""
    from training.machinery.policies import LogitsPolicy

    entry = torchscript_entrant(tmp_path / "net")
    doc = judge("v7", entrant=entry, out=tmp_path / "bench", worlds_cap=3, workers=1, progress=False)
    rows = {r["split"]: r for r in doc["rows"]}
    assert set(rows) == {"heldout", "larger"}
    held = rows["heldout"]
    assert held["training"] == "declared" and held["policy"] == "outside-net" and held["kind"] == "learned"
    assert held["declared"] == {
        "name": "outside-net",
        "training_seeds": [0, 1],
        "budget": {"agent_steps": 1000},
        "code": "https://example.org/outside-net",
    }
    run = held["runs"][1]
    assert run["training_seed"] == 1 and run["agent_steps"] == 1000
    assert len(run["sha256"]) == 64 and run["sha256"] != held["runs"][0]["sha256"]

    env = proteo_env.make("chain-v1", **CHAIN, control="move")
    encoder = chain_encoder(message_encoding="compact")
    net = relu_network(encoder.size, 13, seed=1)

    def logits(features):
        with torch.no_grad():
            return net(torch.from_numpy(features)).numpy()

    for seed, cycles in zip(held["world_seeds"], run["cycles"]):
        policy = LogitsPolicy(env.action_layout, env.task.modes, encoder=encoder, logits_fn=logits, nvec=[13])
        assert run_episode(env, policy, seed=seed).cycles == cycles
    table, seeds = (tmp_path / "bench/benchmark.md").read_text().split("Each training seed on its own")
    assert table.count("| outside-net (declared) |") == 2  # one row per split, then each seed's
    assert seeds.count("| outside-net (") == 2 * len(held["runs"])


def test_an_onnx_export_of_the_network_plays_the_episodes_of_its_torchscript(tmp_path):
    pytest.importorskip("onnxruntime")
    encoder = chain_encoder(message_encoding="compact")
    (tmp_path / "onnx").mkdir()
    net = relu_network(encoder.size, 13, seed=0)
    torch.onnx.export(
        net,
        (torch.zeros(1, encoder.size),),
        str(tmp_path / "onnx/seed_0.onnx"),
        input_names=["features"],
        dynamic_axes={"features": {0: "n"}},
        dynamo=False,
    )
    onnx = write_entrant(tmp_path / "onnx", {0: "seed_0.onnx"}, format="onnx", actions="argmax")
    script = torchscript_entrant(tmp_path / "ts", seeds=(0,), actions="argmax")
    results = evaluate(
        "chain-v1",
        [Controller.from_entrant(onnx, training_seed=0), Controller.from_entrant(script, training_seed=0)],
        seeds=range(1000, 1004),
        env=CHAIN,
        level="move",
        workers=1,
    )
    assert [r.cycles for r in results[0]] == [r.cycles for r in results[1]]


def test_a_factory_entrant_plays_the_same_episodes_in_a_batch_as_alone(tmp_path, walker):
    """The object is told each world's seed: batched with others, or one world at a time through
    run_episode (the PettingZoo API), the same episodes."""
    from training.machinery.entrants import entrant_policy

    controller = Controller.from_entrant(f"{walker}:make")
    batched = evaluate("chain-v1", [controller], seeds=range(5), env=CHAIN, level="move", workers=1, batch_size=3)[0]
    env = proteo_env.make("chain-v1", **CHAIN, control="move")
    for seed, result in zip(range(5), batched):
        alone = run_episode(env, entrant_policy(f"{walker}:make", env, seed=seed, settings=CHAIN), seed=seed)
        assert (alone.cycles, alone.success, alone.total_reward) == (result.cycles, result.success, result.total_reward)


def test_a_bare_factory_enters_with_a_task_and_level_and_its_rows_say_undeclared(tmp_path, walker):
    doc = judge(
        "v7", entrant=f"{walker}:make", tasks=["chain"], level="move", out=tmp_path / "b", worlds_cap=2, workers=1,
        progress=False,
    )  # fmt: skip
    assert {r["training"] for r in doc["rows"]} == {"undeclared"}
    assert doc["rows"][0]["runs"][0]["training_seed"] is None
    with pytest.raises(ConfigError, match="--tasks TASK \\(one\\) and --level LEVEL"):
        judge("v7", entrant=f"{walker}:make", out=tmp_path / "c", worlds_cap=2, workers=1, progress=False)


@pytest.mark.parametrize(
    ("factory", "message"),
    [
        ("make_illegal", r"world seed 1000, agent module_\d+, cycle \d+: move = 1 is not allowed: the action mask"),
        ("make_float", r"returned actions of dtype float64; allowed: integers"),
        ("make_shape", r"returned actions of shape \(\d+, 12\); allowed: \(\d+, 12, 1\)"),
        ("make_range", r"world seed 1000, agent module_3, cycle 0: move = 13 is not allowed; allowed: 0 to 12"),
        ("make_raises", r"raised RuntimeError: no weights here"),
        ("make_nothing", r"returned 'int' without act\(\)"),
        ("make_missing", r"AttributeError"),
    ],
)
def test_an_entrant_that_breaks_the_interface_is_refused_before_any_row_is_written(tmp_path, walker, factory, message):
    with pytest.raises(EntrantError, match=message):
        judge(
            "v7", entrant=f"{walker}:{factory}", tasks=["chain"], level="move", out=tmp_path / "b", worlds_cap=2,
            workers=1, progress=False,
        )  # fmt: skip
    assert not (tmp_path / "b/benchmark.json").exists()


def _bad_entrants(tmp_path: Path) -> list[tuple[Path, str]]:
    net = torchscript_entrant(tmp_path / "net", seeds=(0,))
    cases = []

    def variant(case: str, message: str, files=None, **fields) -> None:
        folder = tmp_path / case
        folder.mkdir()
        (folder / "seed_0.pt").write_bytes((tmp_path / "net/seed_0.pt").read_bytes())
        cases.append((write_entrant(folder, files or {0: "seed_0.pt"}, **fields), message))

    variant(
        "budget",
        r"budget.agent_steps = 'a lot' is not allowed; allowed: a number >= 0",
        budget={"agent_steps": "a lot"},
    )
    variant("nobudget", r"budget is missing", budget=None)
    variant("key", r"key 'layers' = 3 is not allowed", layers=3)
    variant(
        "format",
        r"format = 'keras' is not allowed; allowed: torchscript, onnx, sb3, benchmarl, factory",
        format="keras",
    )
    variant("missing", r"seeds.0 = 'gone.pt' is not allowed; allowed: a file beside", files={0: "gone.pt"})
    variant("seed", r"seeds = -1 is not allowed; allowed: training seeds: integers >= 0", files={-1: "seed_0.pt"})
    variant("task", r"task = 'snake-v0' is not allowed; allowed: the tasks benchmark v7 holds", task="snake-v0")
    variant("level", r"control level = 'full' is not allowed; allowed: .*\(move\)", control="full")
    variant("name", r"name = 'ppo-move' is not allowed", name="ppo-move")
    variant("version", r"entrant = 2 is not allowed; allowed: 1", entrant=2)
    variant(
        "encoding", r"observation.message_encoding = 'words' is not allowed", observation={"message_encoding": "words"}
    )
    variant("onnx", r"is not an ONNX model", format="onnx")
    variant("sb3", r"is not a MaskablePPO model", format="sb3")
    benchmarl = importlib.util.find_spec("benchmarl") is not None  # its own environment (tests/test_benchmarl.py)
    variant("benchmarl", r"no config.pkl" if benchmarl else r"BenchMARL is not installed here", format="benchmarl")
    variant("size", r"failed on features of shape \(1, \d+\).*allowed: a network from", observation={})
    (tmp_path / "garbage").mkdir()
    (tmp_path / "garbage/seed_0.pt").write_bytes(b"\x00" * 100)
    cases.append((write_entrant(tmp_path / "garbage", {0: "seed_0.pt"}), r"is not a TorchScript file"))
    encoder = chain_encoder(message_encoding="compact")
    (tmp_path / "out").mkdir()
    torch.jit.save(torch.jit.script(relu_network(encoder.size, 40)), tmp_path / "out/seed_0.pt")
    cases.append(
        (
            write_entrant(tmp_path / "out", {0: "seed_0.pt"}),
            r"gave logits of shape \(1, 40\) for features \(1, 196\); allowed: \(1, 13\)",
        )
    )
    assert net.is_file()
    return cases


def test_bad_entrants_get_one_clear_error_naming_the_field_before_anything_is_written(tmp_path):
    for path, message in _bad_entrants(tmp_path):
        out = path.parent / "bench"
        with pytest.raises(ConfigError, match=message):  # an EntrantError, or the judge's own ConfigError
            judge("v7", entrant=path, out=out, worlds_cap=1, workers=1, progress=False)
        assert not out.exists(), path


def test_the_command_line_judges_an_entrant_and_refuses_a_bad_one(tmp_path, capsys):
    from training.cli import main

    entry = torchscript_entrant(tmp_path / "net", seeds=(0,))
    argv = ["eval", "--benchmark", "v7", "--entrant", str(entry.parent), "--worlds-cap", "1", "--workers", "1"]
    assert main([*argv, "--out", str(tmp_path / "ok")]) == 0
    assert json.loads((tmp_path / "ok/benchmark.json").read_text())["rows"][0]["training"] == "declared"
    assert main([*argv, "--out", str(tmp_path / "bad"), "--level", "full"]) == 2
    assert "--level 'full' is not allowed with entrant" in capsys.readouterr().err
    assert main(["eval", "--entrant", str(entry), "--out", str(tmp_path / "x")]) == 2
    assert "--entrant" in (err := capsys.readouterr().err) and "without --benchmark is not allowed" in err
