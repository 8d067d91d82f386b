"""The benchmark protocol (training/judging/protocol.py and judge.py, configs/benchmark/v1.yaml, proteo eval --benchmark):
the v1 file loads and is checked, bad input is one ConfigError before anything is written, every
policy is judged on the same first world seeds, and a tiny end-to-end run (--worlds-cap) writes
benchmark.json with the documented schema and the episodes a direct re-run gives."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from proteo_env.config import ConfigError
from training.judging import judge
from training.judging.protocol import load_protocol, versions

ROOT = Path(__file__).resolve().parents[1]
CHAIN_CHECKPOINT = "checkpoints/v1/chain/kickstart_move/seed_0"
STUDY_TASKS = {
    "chain": "chain-v1",
    "branch": "branch-v0",
    "table": "table-v1",
    "grasp": "grasp-v0",
    "locomotion": "locomotion-v0",
}


def test_v1_loads_and_fixes_the_study():
    import proteo_env

    p = load_protocol("v1")
    assert p.version == "v1" and "v1" in versions()
    assert {name: t.task_id for name, t in p.tasks.items()} == STUDY_TASKS
    assert p.reference >= 100 and p.per_training_seed >= 20 and p.training_seeds >= 5
    assert p.first_seed == 1000
    for name, t in p.tasks.items():
        splits = [s.name for s in t.splits]
        assert splits[:2] == ["heldout", "larger"], name
        assert t.levels == {"learned": ["move"], "rules": ["full", "move"], "random": ["move"], "evolved": ["move"]}
        assert t.splits[0].env == t.env  # heldout: the training size
        for recipe in t.recipes.values():
            assert (ROOT / recipe["config"]).is_file()
        for s in t.splits:
            proteo_env.make(t.task_id, **s.env).close()  # every split's settings make an env
    assert len(p.tasks["grasp"].splits) == 5 and len(p.tasks["chain"].splits) == 2


def test_every_policy_takes_the_same_first_world_seeds():
    p = load_protocol("v1")
    rules, learned = p.worlds("hand-coded"), p.worlds("learned")
    assert rules == 100 and learned == 20
    assert p.world_seeds(learned) == p.world_seeds(rules)[:learned] == list(range(1000, 1020))
    assert p.worlds("random", cap=3) == 3 and p.worlds("learned", cap=50) == 20


def _protocol_copy(tmp_path: Path, edit) -> Path:
    """A repository root holding configs/benchmark/v1.yaml changed by ``edit(data)``."""
    data = yaml.safe_load((ROOT / "configs/benchmark/v1.yaml").read_text())
    edit(data)
    (tmp_path / "configs/benchmark").mkdir(parents=True)
    (tmp_path / "configs/train").symlink_to(ROOT / "configs/train")
    (tmp_path / "configs/benchmark/v1.yaml").write_text(yaml.safe_dump(data))
    return tmp_path


def test_a_protocol_fixes_an_equivalence_margin_or_makes_no_equivalence_claims(tmp_path):
    assert load_protocol("v1").equivalence_margin is None
    root = _protocol_copy(tmp_path, lambda d: d.update(equivalence_margin=0.05))
    assert load_protocol("v1", root=root).equivalence_margin == 0.05


@pytest.mark.parametrize(
    "edit, names",
    [
        (lambda d: d.update(extra=1), ["top level", "'extra'", "version, worlds, equivalence_margin, tasks"]),
        (lambda d: d["worlds"].update(world=5), ["worlds", "'world'", "first_seed"]),
        (lambda d: d["tasks"]["chain"].update(budget=1), ["tasks.chain", "'budget'", "recipes"]),
        (lambda d: d["tasks"]["grasp"]["levels"].update(evolve=["move"]), ["tasks.grasp.levels", "'evolve'"]),
        (
            lambda d: d["tasks"]["table"]["recipes"]["ppo-move"].update(steps=3),
            ["tasks.table.recipes.ppo-move", "'steps'", "agent_steps"],
        ),
        (lambda d: d["tasks"]["branch"]["splits"]["larger"].update(seeds=3), ["tasks.branch.splits.larger", "'seeds'"]),
        (
            lambda d: d["tasks"]["locomotion"]["splits"]["step1"]["env"].update(stair=1),
            ["tasks.locomotion.splits.step1.env", "'stair'", "step_height"],
        ),
        (lambda d: d["tasks"].update(chian={}), ["tasks", "'chian'", "did you mean 'chain'"]),
        (lambda d: d["tasks"]["chain"].update(task="chain-v7"), ["tasks.chain.task", "'chain-v7'", "chain-v1"]),
        (lambda d: d["tasks"]["chain"]["levels"].update(rules=["fast"]), ["tasks.chain.levels.rules", "'fast'"]),
        (lambda d: d["worlds"].update(reference=50), ["worlds.reference", "50", ">= 100"]),
        (lambda d: d["worlds"].update(per_training_seed=10), ["worlds.per_training_seed", "10", ">= 20"]),
        (lambda d: d["worlds"].update(training_seeds=1), ["worlds.training_seeds", "1", ">= 5"]),
        (lambda d: d["tasks"]["grasp"]["splits"].pop("larger"), ["tasks.grasp.splits", "larger"]),
        (lambda d: d.update(version="v2"), ["version", "'v2'", "'v1'"]),
        (lambda d: d.update(equivalence_margin=5), ["equivalence_margin", "5", "between 0 and 1"]),
    ],
)
def test_bad_protocol_file_is_one_config_error_naming_the_field(tmp_path, edit, names):
    root = _protocol_copy(tmp_path, edit)
    with pytest.raises(ConfigError) as err:
        judge.judge("v1", policy="rules", out=tmp_path / "out", root=root, progress=False)
    for name in names:
        assert name in str(err.value), (name, str(err.value))
    assert not (tmp_path / "out").exists()


def test_v2_extends_v1_with_the_evolved_recipes_only():
    """v2 adds the evolved level (full) and the CMA-ES recipe to chain, branch, table and grasp;
    everything v1 fixes stays, so v1's results hold under v2."""
    v1, v2 = load_protocol("v1"), load_protocol("v2")
    assert [v for v, _ in v2.lineage] == ["v1", "v2"] and v2.lineage[0] == v1.lineage[0]
    assert (v2.first_seed, v2.reference, v2.per_training_seed, v2.training_seeds) == (
        v1.first_seed,
        v1.reference,
        v1.per_training_seed,
        v1.training_seeds,
    )
    for name, t in v2.tasks.items():
        before = v1.tasks[name]
        assert (t.task_id, t.trained_on, t.env, t.splits) == (
            before.task_id,
            before.trained_on,
            before.env,
            before.splits,
        )
        added = {k: v for k, v in t.recipes.items() if k not in before.recipes}
        assert {k: t.recipes[k] for k in before.recipes} == before.recipes
        evolved = name != "locomotion"
        assert t.levels == {**before.levels, "evolved": ["full"] if evolved else ["move"]}
        assert list(added) == (["cma-full"] if evolved else [])
        for recipe in added.values():
            assert (ROOT / recipe["config"]).is_file()


def assert_adds_only_recipes(parent: str, child: str, added_by_task: dict) -> None:
    """Protocol ``child`` extends ``parent``, keeps everything it fixes, and adds exactly the recipes
    ``added_by_task`` (task -> recipe names), each with a config and the config's own budget."""
    before_all, after_all = load_protocol(parent), load_protocol(child)
    assert [v for v, _ in after_all.lineage][-2:] == [parent, child]
    assert after_all.lineage[:-1] == before_all.lineage
    for name, t in after_all.tasks.items():
        before = before_all.tasks[name]
        assert (t.task_id, t.trained_on, t.env, t.splits, t.levels) == (
            before.task_id,
            before.trained_on,
            before.env,
            before.splits,
            before.levels,
        )
        added = {k: v for k, v in t.recipes.items() if k not in before.recipes}
        assert {k: t.recipes[k] for k in before.recipes} == before.recipes
        assert sorted(added) == added_by_task.get(name, [])
        for recipe in added.values():
            assert (ROOT / recipe["config"]).is_file() and recipe["agent_steps"] is None


def test_v3_extends_v2_with_the_program_evolution_recipes_on_chain_only():
    """v3 adds the two recipes that evolve programs (from random ones and from the paper's) to
    chain, judged at v2's evolved level; everything v2 fixes stays."""
    assert_adds_only_recipes("v2", "v3", {"chain": ["evolve-full", "evolve-paper-full"]})


def test_v4_extends_v3_with_evolution_from_the_paper_programs_on_branch_table_and_grasp():
    """v4 adds evolution from the paper's programs on branch, table and grasp, judged at v2's
    evolved level; everything v3 fixes stays."""
    assert_adds_only_recipes(
        "v3",
        "v4",
        {
            "branch": ["evolve-paper-full"],
            "table": ["evolve-paper-full"],
            "grasp": ["evolve-paper-full"],
        },
    )


def test_v5_extends_v4_with_evolution_from_random_programs_on_branch_table_and_grasp():
    """v5 adds evolution from random programs on branch, table and grasp, whose configs are v4's
    evolution from the paper's program without the seed program; everything v4 fixes stays."""
    assert_adds_only_recipes(
        "v4", "v5", {"branch": ["evolve-full"], "table": ["evolve-full"], "grasp": ["evolve-full"]}
    )
    for task in ("branch", "table", "grasp"):
        scratch = yaml.safe_load((ROOT / f"configs/train/evolve_{task}_full.yaml").read_text())
        paper = yaml.safe_load((ROOT / f"configs/train/evolve_paper_{task}_full.yaml").read_text())
        assert paper.pop("seed_program") == task and scratch == paper


def test_v6_extends_v5_with_evolution_of_ten_times_the_episodes_per_generation():
    """v6 adds evolve-large-full and evolve-large-paper-full on chain, branch, table and grasp: v3
    to v5's evolution configs with 80 parents and 160 children a generation, and on branch and
    table the fitness with partial credit; nothing else differs."""
    added = ["evolve-large-full", "evolve-large-paper-full"]
    assert_adds_only_recipes("v5", "v6", {task: added for task in ("chain", "branch", "table", "grasp")})
    for task in ("chain", "branch", "table", "grasp"):
        for start in ("", "paper_"):
            large = yaml.safe_load((ROOT / f"configs/train/evolve_large_{start}{task}_full.yaml").read_text())
            small = yaml.safe_load((ROOT / f"configs/train/evolve_{start}{task}_full.yaml").read_text())
            assert (large.pop("population"), large.pop("offspring")) == (80, 160)
            assert (small.pop("population"), small.pop("offspring")) == (8, 16)
            if task in ("branch", "table"):
                assert large.pop("fitness") == "progress"
                small.pop("fitness", None)
            assert large == small


def _recipe_checkpoint(tmp_path: Path, source: str, folder: str, **changes) -> str:
    """A copy of the published checkpoint ``source`` in ``tmp_path/<folder>/seed_0`` with its
    ``proteo.json`` changed (``args`` entries under ``args``)."""
    import shutil

    target = tmp_path / folder / "seed_0"
    shutil.copytree(ROOT / source, target)
    meta = json.loads((target / "proteo.json").read_text())
    meta["args"].update(changes.pop("args", {}))
    meta.update(changes)
    (target / "proteo.json").write_text(json.dumps({k: v for k, v in meta.items() if v is not None}))
    return str(target)


@pytest.mark.parametrize(
    "source, folder, changes, named",
    [
        (
            "checkpoints/v1/grasp/kickstart_move/seed_0",
            "kickstart_move",
            {"agent_steps": 604160},
            "agent_steps = 604160",
        ),
        (
            "checkpoints/v1/grasp/kickstart_move/seed_0",
            "kickstart_move",
            {"agent_steps": 12083200},
            "6000000 to 6300000",
        ),
        ("checkpoints/v1/grasp/kickstart_move/seed_0", "kickstart_move", {"seed": 7}, "training seed = 7"),
        (
            "checkpoints/v1/grasp/kickstart_move/seed_0",
            "kickstart_move",
            {"args": {"learning_rate": 0.1}},
            "learning_rate = 0.1",
        ),
        ("checkpoints/v5/grasp/evolve_full/seed_0", "evolve_full", {"generation": 12}, "12 generations"),
        ("checkpoints/v1/grasp/imitation_move/seed_0", "imitation_move", {"last_round": {"round": 1}}, "1 rounds"),
    ],
)
def test_a_recipe_checkpoint_off_the_protocol_is_refused(tmp_path, source, folder, changes, named):
    """A checkpoint judged as a protocol recipe must be one of its training seeds, trained by its
    config, for its budget: relabelled with a tenth of the steps, trained twice as long, with
    seed 7 (train ten, submit the best five), another setting, or stopped early, it is refused."""
    path = _recipe_checkpoint(tmp_path, source, folder, **changes)
    with pytest.raises(ConfigError, match=named):
        judge.candidates(load_protocol("v6"), checkpoints=[path])


def test_a_recipe_is_recognised_by_what_its_checkpoint_records_not_by_its_folder(tmp_path):
    """The published checkpoint in a folder named otherwise is still its recipe, and checked as one
    (with seed 12345 and one agent-step it is refused); without the record, in a folder named like a
    recipe, it is judged but its rows say that its training was not checked."""
    source = "checkpoints/v7/chain/ppo_move/seed_0"
    protocol = load_protocol("v7")
    renamed = _recipe_checkpoint(tmp_path / "a", source, "my_run")
    (candidate,) = judge.candidates(protocol, checkpoints=[renamed])
    assert (candidate.recipe, candidate.label, candidate.training) == ("ppo-move", "ppo-move", "protocol")
    off = _recipe_checkpoint(tmp_path / "b", source, "my_run", seed=12345, agent_steps=1)
    with pytest.raises(ConfigError, match="training seed = 12345 is not allowed"):
        judge.candidates(protocol, checkpoints=[off])
    unrecorded = _recipe_checkpoint(tmp_path / "c", source, "ppo_move", seed=12345, agent_steps=1, recipe=None)
    (candidate,) = judge.candidates(protocol, checkpoints=[unrecorded])
    assert (candidate.recipe, candidate.label, candidate.training) == (None, "ppo_move", "unchecked")


def test_every_published_recipe_checkpoint_is_a_run_of_its_recipe():
    for folder in sorted(ROOT.glob("checkpoints/v[1-9]/*/*_*")):
        protocol = load_protocol(folder.parent.parent.name)  # the tree's own protocol (v7 extends none)
        seeds = sorted(str(p) for p in folder.glob("seed_*"))
        (entrant,) = judge.candidates(protocol, checkpoints=seeds)
        assert entrant.recipe is not None and len(entrant.checkpoints) == protocol.training_seeds


def _extension(tmp_path: Path, text: str) -> Path:
    """A repository root holding configs/benchmark/v1.yaml and an extension v2.yaml of ``text``."""
    (tmp_path / "configs/benchmark").mkdir(parents=True)
    (tmp_path / "configs/train").symlink_to(ROOT / "configs/train")
    (tmp_path / "configs/benchmark/v1.yaml").write_bytes((ROOT / "configs/benchmark/v1.yaml").read_bytes())
    (tmp_path / "configs/benchmark/v2.yaml").write_text(text)
    return tmp_path


@pytest.mark.parametrize(
    "text, names",
    [
        ("version: v2\nextends: v1\nworlds: {reference: 200}\n", ["top level", "'worlds'", "version, extends, tasks"]),
        (
            "version: v2\nextends: v1\ntasks: {chain: {env: {n_modules: 4}}}\n",
            ["tasks.chain", "'env'", "levels, recipes, splits"],
        ),
        (
            "version: v2\nextends: v1\ntasks: {chain: {splits: {larger: {env: {n_modules: 30}}}}}\n",
            ["tasks.chain.splits.larger", "v1 already fixes it"],
        ),
        (
            "version: v2\nextends: v1\ntasks: {chain: {splits: {x10: {worlds: {reference: 5, per_training_seed: 5}}}}}\n",
            ["tasks.chain.splits.x10.worlds.reference = 5", "from 20 to 100", "may take fewer, not more"],
        ),
        (
            "version: v2\nextends: v1\ntasks: {chain: {splits: {x10: {worlds: {reference: 20, per_training_seed: 50}}}}}\n",
            ["tasks.chain.splits.x10.worlds.per_training_seed = 50", "from 5 to 20"],
        ),
        (
            "version: v2\nextends: v1\ntasks: {chain: {splits: {x10: {worlds: {reference: 20}}}}}\n",
            ["tasks.chain.splits.x10.worlds.per_training_seed = None", "from 5 to 20"],
        ),
        (
            "version: v2\nextends: v1\ntasks: {chain: {splits: {x10: {worlds: {referense: 20}}}}}\n",
            ["tasks.chain.splits.x10.worlds", "'referense'", "did you mean 'reference'"],
        ),
        (
            "version: v2\nextends: v1\ntasks: {chain: {splits: {x10: {env: {n_modules: 120, max_cycles: 0}}}}}\n",
            ["tasks.chain.splits.x10.env", "max_cycles=0 is not allowed; allowed: an integer >= 1"],
        ),
        (
            "version: v2\nextends: v1\ntasks: {table: {splits: {x10: {env: {n_modules: 120}}}}}\n",
            ["tasks.table.splits.x10.env", "unknown key 'n_modules'", "board_size"],
        ),
        (
            "version: v2\nextends: v1\ntasks: {chain: {levels: {learned: [full]}}}\n",
            ["tasks.chain.levels.learned", "v1 already fixes it"],
        ),
        (
            "version: v2\nextends: v1\ntasks: {chain: {recipes: {ppo-move: {config: configs/train/ppo_chain_move.yaml}}}}\n",
            ["tasks.chain.recipes.ppo-move", "v1 already fixes it"],
        ),
        ("version: v2\nextends: v1\ntasks: {chian: {}}\n", ["tasks", "'chian'", "did you mean 'chain'"]),
        ("version: v2\nextends: v99\ntasks: {}\n", ["extends 'v99'", "allowed: v1"]),
        ("version: v2\nextends: v2\ntasks: {}\n", ["extends = 'v2'", "a cycle (v2 -> v2)"]),
        (
            "version: v2\nextends: v1\ntasks: {chain: {levels: {evolved: [fast]}}}\n",
            ["tasks.chain.levels.evolved", "'fast'", "full"],
        ),
    ],
)
def test_bad_extension_is_one_config_error_naming_the_field(tmp_path, text, names):
    root = _extension(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        judge.judge("v2", policy="rules", out=tmp_path / "out", root=root, progress=False)
    for name in names:
        assert name in str(err.value), (name, str(err.value))
    assert not (tmp_path / "out").exists()


def test_an_extension_adds_splits_with_fewer_worlds_and_the_judge_judges_them_alone(tmp_path):
    """A protocol may add splits to the one it extends, each with its own (smaller) world counts;
    ``--splits`` judges those splits only, on their own worlds, and a split a task lacks is refused."""
    text = (
        "version: v2\nextends: v1\ntasks:\n  chain:\n    splits:\n"
        "      wider: {about: fourteen modules, env: {n_modules: 14}, worlds: {reference: 20, per_training_seed: 5}}\n"
    )
    root = _extension(tmp_path, text)
    protocol = load_protocol("v2", root=root)
    wider = protocol.tasks["chain"].splits[-1]
    assert wider.name == "wider" and wider.env["n_modules"] == 14 and wider.worlds["reference"] == 20
    assert [s.name for s in protocol.tasks["chain"].splits[:-1]] == [
        s.name for s in load_protocol("v1").tasks["chain"].splits
    ]
    assert protocol.worlds("hand-coded", split=wider) == 20 and protocol.worlds("learned", split=wider) == 5
    assert protocol.worlds("hand-coded") == protocol.reference and protocol.worlds("learned", 3, wider) == 3
    doc = judge.judge(
        "v2", policy="rules", tasks=["chain"], level="full", splits=["wider"], out=tmp_path / "out", root=root,
        progress=False, workers=1,
    )  # fmt: skip
    (row,) = doc["rows"]
    assert (row["split"], row["world_seeds"], row["complete"]) == ("wider", list(range(1000, 1020)), True)
    assert len(row["runs"][0]["successes"]) == 20
    with pytest.raises(ConfigError, match=r"--splits 'wider' is not allowed for branch; allowed: its splits"):
        judge.judge("v2", policy="rules", tasks=["branch"], splits=["wider"], out=tmp_path / "o2", root=root)
    assert not (tmp_path / "o2").exists()


@pytest.mark.parametrize(
    "argv, names",
    [
        (["--benchmark", "v99", "--policy", "rules"], ["'v99'", "allowed: v1"]),
        (["--benchmark", "v1", "--checkpoint", "checkpoints/exhibits/winding_chain"], ["'chain-v0'", "chain-v1"]),
        (["--benchmark", "v1", "--checkpoint", "checkpoints/v2/chain/cma_full/seed_0"], ["'full'", "move"]),
        (["--benchmark", "v1", "--policy", "ppo"], ["--policy 'ppo'", "rules, random"]),
        (["--benchmark", "v1", "--policy", "rules", "--level", "move+mode"], ["'move+mode'", "full, move"]),
        (["--benchmark", "v1", "--policy", "rules", "--worlds-cap", "0"], ["--worlds-cap = 0", ">= 1"]),
        (["--benchmark", "v1", "--policy", "rules", "--tasks", "snake"], ["--tasks 'snake'", "chain"]),
        (["--benchmark", "v1"], ["none of --checkpoint, --policy, --entrant"]),
        (["--benchmark", "v1", "--policy", "rules", "--entrant", "x:y"], ["--policy and --entrant", "allowed: one of"]),
        (["--benchmark", "v1", "--policy", "rules", "--seeds", "3"], ["--seeds", "not allowed"]),
        (
            [
                "--benchmark",
                "v1",
                "--checkpoint",
                CHAIN_CHECKPOINT,
                "--checkpoint",
                "checkpoints/v1/grasp/ppo_move/seed_0",
            ],
            ["chain, grasp", "one recipe"],
        ),
        (["--benchmark", "v1", "--checkpoint", CHAIN_CHECKPOINT, "--checkpoint", CHAIN_CHECKPOINT], ["twice"]),
        (["--policy", "rules"], ["without --benchmark"]),
        (["--splits", "x10"], ["--splits 'x10' without --benchmark is not allowed"]),
        (
            ["--benchmark", "v1", "--policy", "rules", "--splits", "x10"],
            ["--splits 'x10' is not allowed for", "heldout"],
        ),
    ],
)
def test_bad_command_line_is_one_error_and_nothing_is_written(tmp_path, capsys, monkeypatch, argv, names):
    from training.cli import main

    monkeypatch.chdir(ROOT)
    out = tmp_path / "out"
    assert main(["eval", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("proteo: error:") == 1
    for name in names:
        assert name in err, (name, err)
    assert not out.exists()


def _direct(source: str, task_id: str, env: dict, level: str, seed: int):
    """One episode re-run outside the benchmark: load_controller and run_episode."""
    from proteo_env.rollout import run_episode
    from training import load_controller

    if source.startswith("baselines."):
        env_, policy = load_controller(f"rules:{task_id}", seed=1000, **env, control=level)
    else:
        env_, policy = load_controller(source, seed=1000, **env)
    episode = run_episode(env_, policy, seed=seed)
    env_.close()
    return episode


def _check_schema(doc: dict) -> None:
    assert doc["schema"] == "proteo-results" and doc["schema_version"] == 2 and doc["judgement"] == "benchmark"
    assert doc["protocol"] == "v1" and doc["protocol_file"] == "configs/benchmark/v1.yaml"
    assert len(doc["protocol_sha256"]) == 64
    for key in ("proteo_version", "commit", "created", "worlds_cap", "complete", "notes", "rows"):
        assert key in doc
    for row in doc["rows"]:
        for key in (
            "task",
            "split",
            "about",
            "env",
            "policy",
            "kind",
            "level",
            "group",
            "recipe",
            "world_seeds",
            "runs",
        ):
            assert key in row
        for run in row["runs"]:
            assert len(run["successes"]) == len(run["cycles"]) == len(run["returns"]) == len(row["world_seeds"])
        s = row["summary"]
        assert s["successes"] == sum(sum(r["successes"]) for r in row["runs"])
        assert s["episodes"] == len(row["runs"]) * len(row["world_seeds"])
        assert 0.0 <= s["success_lo"] <= s["success_rate"] <= s["success_hi"] <= 1.0


def test_rules_and_a_checkpoint_end_to_end(tmp_path, monkeypatch):
    from training.cli import main

    monkeypatch.chdir(ROOT)
    rules_out, ckpt_out = tmp_path / "rules", tmp_path / "ckpt"
    assert main(["eval", "--benchmark", "v1", "--policy", "rules", "--tasks", "chain", "--worlds-cap", "3"]
                + ["--out", str(rules_out)]) == 0  # fmt: skip
    assert main(["eval", "--benchmark", "v1", "--checkpoint", CHAIN_CHECKPOINT, "--worlds-cap", "2"]
                + ["--out", str(ckpt_out)]) == 0  # fmt: skip
    rules = json.loads((rules_out / "benchmark.json").read_text())
    ckpt = json.loads((ckpt_out / "benchmark.json").read_text())
    for doc in (rules, ckpt):
        _check_schema(doc)
        assert doc["worlds_cap"] is not None and not doc["complete"] and doc["notes"]
    assert "| chain-v1 | larger |" in (rules_out / "benchmark.md").read_text()
    assert [(r["split"], r["policy"], r["level"]) for r in rules["rows"]] == [
        ("heldout", "rules", "full"),
        ("larger", "rules", "full"),
        ("heldout", "rules-move", "move"),
        ("larger", "rules-move", "move"),
    ]
    assert [(r["split"], r["policy"], r["recipe"], r["kind"]) for r in ckpt["rows"]] == [
        ("heldout", "kickstart-move", "kickstart-move", "learned"),
        ("larger", "kickstart-move", "kickstart-move", "learned"),
    ]
    # the same first world seeds: the policy judged on fewer worlds takes the first ones
    for r in rules["rows"]:
        assert r["world_seeds"] == [1000, 1001, 1002]
    for r in ckpt["rows"]:
        assert r["world_seeds"] == [1000, 1001] == rules["rows"][0]["world_seeds"][:2]
        assert r["runs"][0]["training_seed"] == 0 and r["summary"]["interval"] == "wilson, t"
    # the success and cycles recorded are those of a direct re-run of the episode
    for doc in (rules, ckpt):
        for row in (doc["rows"][0], doc["rows"][-1]):
            run, seed = row["runs"][0], row["world_seeds"][-1]
            episode = _direct(run["source"], row["task"], row["env"], row["level"], seed)
            assert (episode.success, episode.cycles) == (run["successes"][-1], run["cycles"][-1])
            assert row["summary"]["successes"] == sum(run["successes"])


def test_several_training_seeds_are_one_row_with_the_stratified_bootstrap(tmp_path):
    seeds = [f"checkpoints/v1/chain/kickstart_move/seed_{k}" for k in (0, 1)]
    doc = judge.judge(
        "v1", checkpoints=[str(ROOT / s) for s in seeds], out=tmp_path / "out", worlds_cap=2, progress=False
    )
    _check_schema(doc)
    assert len(doc["rows"]) == 2
    for row in doc["rows"]:
        assert [r["training_seed"] for r in row["runs"]] == [0, 1]
        assert row["summary"]["interval"] == "stratified bootstrap" and row["summary"]["training_seeds"] == 2
        assert not row["complete"]  # 2 training seeds of the 5 the protocol asks for
    assert any("2 training seed(s)" in n for n in doc["notes"])


def test_every_published_judgement_was_made_under_the_protocol_file_as_it_is_now():
    # A protocol is fixed once and never changed (a comment counts): editing one strands its published rows.
    import hashlib

    published = sorted(ROOT.glob("docs/benchmark/v*/*/*/benchmark.json"))
    assert published
    for path in published:
        document = json.loads(path.read_text())
        now = hashlib.sha256((ROOT / document["protocol_file"]).read_bytes()).hexdigest()
        assert document["protocol_sha256"] == now, f"{document['protocol_file']} changed since {path} was judged"


def test_v7_judges_ten_seeds_on_a_hundred_worlds_and_a_run_on_its_task_id_passes_the_config_check():
    protocol = load_protocol("v7")
    assert (protocol.training_seeds, protocol.per_training_seed, protocol.reference) == (10, 100, 100)
    assert protocol.equivalence_margin == 0.05
    table = protocol.tasks["table"]
    assert table.task_id == "table-v2" and "threshold_T6" not in protocol.tasks["branch"].splits
    config = yaml.safe_load((ROOT / "configs/train/kickstart_table_move.yaml").read_text())
    assert config["task"] == "table-v1"  # v1's config; a study for v7 trains it with --task table-v2
    meta = {"seed": 9, "args": {**config, "task": "table-v2"}, "agent_steps": 6_000_000}
    judge.check_recipe_run(protocol, table, "kickstart-move", "run", meta)
    with pytest.raises(ConfigError, match="training seed = 10 is not allowed; allowed: .* 0 to 9"):
        judge.check_recipe_run(protocol, table, "kickstart-move", "run", {**meta, "seed": 10})
