"""``proteo eval``: checkpoints trained with several seeds are one row with a stratified
bootstrap interval (training seeds, then episodes), each checkpoint runs at the control level it
was trained at, every table carries intervals, a results.json re-renders without running
episodes, and a bad eval config is one clear error."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from proteo_env.config import ConfigError
from training.judging.evaluate import load_config, run_evaluation
from training.judging.statistics import group_bootstrap, wilson

RUNS = [
    "checkpoints/v2/chain/cma_full/seed_0",
    "checkpoints/v1/chain/ppo_move/seed_0",
    "checkpoints/v3/chain/evolve_full/seed_0",
]


def _config(tmp_path, checkpoints):
    path = tmp_path / "eval.yaml"
    path.write_text(
        yaml.safe_dump(
            {
                "seeds": 2,
                "first_seed": 1000,
                "tasks": {
                    "chain": {
                        "env": {"n_modules": 12, "max_cycles": 300, "motion_model": "sphere"},
                        "checkpoints": checkpoints,
                    }
                },
            }
        )
    )
    return path


def test_a_group_of_training_seeds_is_one_row_with_the_spread_across_them(tmp_path):
    rows = run_evaluation(
        config=_config(tmp_path, [{"label": "three-runs", "runs": RUNS}]),
        tasks=["chain"],
        out=tmp_path / "out",
        progress=False,
        plots=False,
    )
    (group,) = [r for r in rows if r.group]
    assert [r.source for r in group.runs] == RUNS
    summary = group.summary()
    per_run = [r.summary() for r in group.each_run()]
    assert summary["training_seeds"] == 3 and summary["episodes"] == 6
    assert summary["interval"] == "stratified bootstrap"
    boot = group_bootstrap(
        [r.successes for r in group.runs], [r.cycles for r in group.runs], [r.returns for r in group.runs]
    )
    k = sum(s["successes"] for s in per_run)
    assert summary["successes"] == k and summary["success_rate"] == pytest.approx(k / 6)  # pooled
    assert summary["return_mean"] == pytest.approx(np.mean([x for r in group.runs for x in r.returns]))
    assert (summary["return_lo"], summary["return_hi"]) == pytest.approx((boot["return_lo"], boot["return_hi"]))
    lo, hi = wilson(k, 6)  # the bootstrap interval, at least as wide as the pooled Wilson one
    assert summary["success_lo"] == pytest.approx(min(lo, boot["success_lo"]))
    assert summary["success_hi"] == pytest.approx(max(hi, boot["success_hi"]))
    assert summary["success_lo"] <= summary["success_rate"] <= summary["success_hi"]
    text = (tmp_path / "out" / "results.md").read_text()
    assert "three-runs" in text.split("Each training seed")[0]  # the group's row
    assert text.count("three-runs (") == 3  # and one row per training seed below


def test_a_bad_checkpoint_entry_is_one_clear_error(tmp_path):
    with pytest.raises(
        ConfigError,
        match=r"tasks.chain.checkpoints\[0\] = \{'label': 'x'\} is not allowed; "
        r"allowed: a checkpoint path, or \{label: NAME, runs: \[PATH, ...\]\}",
    ):
        run_evaluation(
            config=_config(tmp_path, [{"label": "x"}]),
            tasks=["chain"],
            out=tmp_path / "out",
            progress=False,
            plots=False,
        )


def test_publish_puts_the_table_and_the_summary_between_their_markers_and_refuses_a_page_without_them(tmp_path):
    from training.judging.report import (
        INTERVALS,
        PUBLISH_END,
        Result,
        Run,
        markdown_table,
        publish_evaluation,
        summary_table,
    )

    def result(task, policy, kind, successes, cycles, level="move"):
        run = Run(source="", returns=[1.0] * len(cycles), successes=successes, cycles=cycles)
        return Result(task=task, policy=policy, kind=kind, level=level, runs=[run])

    results = [
        result("chain-v1", "chain", "hand-coded", [True, True], [80, 90], level="full"),
        result("chain-v1", "chain", "hand-coded", [True, False], [70, 300]),
        result("chain-v1", "random", "random", [False, False], [300, 300]),
        result("chain-v1", "ppo-move", "learned", [True, False], [40, 300]),
        result("grasp-v0", "grasp", "hand-coded", [False, True], [300, 100], level="full"),
    ]
    assert summary_table(results).splitlines() == [  # the rules at move are their own column
        "| task (95 % CI) | rules | rules-move | ppo-move |",
        "|---|---|---|---|",
        "| chain-v1 | 2/2 (0.34–1.00), 85 (21–149) | 1/2 (0.09–0.91), 70 | 1/2 (0.09–0.91), 40 |",
        "| grasp-v0 | 1/2 (0.09–0.91), 100 | – | – |",
    ]
    assert markdown_table(results).splitlines()[2] == (
        "| chain-v1 | chain | hand-coded | full | – | 2 | 1.000 (1.000–1.000) | 2/2 (0.34–1.00) | 85 (21–149) | 0.0 |"
    )
    page = tmp_path / "page.md"
    page.write_text(
        "intro\n<!-- proteo eval --out docs/eval/x --summary -->\nold\n<!-- end of proteo eval table -->\n"
        "middle\n<!-- proteo eval --out docs/eval/x -->\nold table\n<!-- end of proteo eval table -->\nrest\n"
    )
    publish_evaluation(results, "docs/eval/x", [page])
    assert page.read_text() == (
        f"intro\n<!-- proteo eval --out docs/eval/x --summary -->\n{summary_table(results)}\n"
        f"{PUBLISH_END}\nmiddle\n<!-- proteo eval --out docs/eval/x -->\n{markdown_table(results)}\n\n"
        f"{INTERVALS}\n{PUBLISH_END}\nrest\n"
    )
    other = tmp_path / "other.md"
    other.write_text("no markers\n")
    before = page.read_text()
    with pytest.raises(ValueError, match="no '<!-- proteo eval --out docs/eval/y -->'"):
        publish_evaluation(results, "docs/eval/y", [page, other])
    assert page.read_text() == before  # nothing written when one file lacks the markers


def _run(successes, cycles, source):
    from training.judging.report import Run

    return Run(
        source=source,
        returns=[2.0 + c / 1000 for c in cycles],
        successes=successes,
        cycles=cycles,
        seeds=list(range(1000, 1000 + len(cycles))),
        metrics=[{"coverage": 0.5}] * len(cycles),
        seconds=1.0,
    )


def _rules():
    """The rules on grasp: 9/10."""
    from training.judging.report import Result

    run = _run([True] * 9 + [False], [100 + j for j in range(9)] + [300], "baselines.grasp")
    return Result(task="grasp-v0", policy="grasp", kind="hand-coded", level="full", runs=[run])


def _kickstart():
    """The study's kickstart on grasp: three training seeds, each 8/10."""
    from training.judging.report import Result

    runs = [
        _run([True] * 8 + [False] * 2, [won_in + j for j in range(8)] + [300, 300], f"ks/seed_{i}")
        for i, won_in in enumerate((153, 94, 114))
    ]
    return Result(task="grasp-v0", policy="kickstart-move", kind="learned", level="move", runs=runs, group=True)


def test_a_group_of_three_seeds_of_8_10_gets_an_interval_not_a_zero_half_width():
    from training.judging.report import markdown_table, summary_table

    rows = [_rules(), _kickstart()]
    s = rows[1].summary()
    assert s["successes"] == 24 and s["success_rate"] == pytest.approx(0.8)
    assert s["success_lo"] <= wilson(24, 30)[0] and s["success_hi"] >= wilson(24, 30)[1]
    assert s["cycles_lo"] < s["cycles_to_success"] < s["cycles_hi"]
    row = markdown_table(rows).splitlines()[3]
    assert f"| 24/30 ({s['success_lo']:.2f}–{s['success_hi']:.2f}) |" in row and "±" not in row
    assert row.split(" | ")[8] == f"{s['cycles_to_success']:.0f} ({s['cycles_lo']:.0f}–{s['cycles_hi']:.0f})"
    assert summary_table(rows).splitlines()[2] == (
        f"| grasp-v0 | 9/10 (0.60–0.98), 104 (102–106) | "
        f"24/30 ({s['success_lo']:.2f}–{s['success_hi']:.2f}), "
        f"{s['cycles_to_success']:.0f} ({s['cycles_lo']:.0f}–{s['cycles_hi']:.0f}) |"
    )


def _written(tmp_path, results, name="first"):
    """A results.json as proteo eval writes it, of ``results``, in ``tmp_path / name``."""
    from training.judging import record

    out = tmp_path / name
    record.write(record.document(results, judgement="evaluation", seconds=1.0), out)
    return out


def _written_before_version_2(tmp_path, results):
    """A results.json as proteo eval wrote it before its schema was versioned: a row per run,
    its group's label beside it; the first row also from before control levels and groups."""
    from dataclasses import asdict

    rows = [
        {"task": r.task, "policy": r.policy, "kind": r.kind, "level": r.level, "group": r.policy if r.group else "",
         **asdict(run), "summary": {}}
        for r in results
        for run in r.runs
    ]  # fmt: skip
    rows[0].pop("level")
    rows[0].pop("group")
    out = tmp_path / "before"
    out.mkdir()
    seeds = results[0].world_seeds
    (out / "results.json").write_text(
        json.dumps({"seeds": seeds, "settings": {"grasp": {}}, "deterministic": False, "results": rows, "groups": []})
    )
    (out / "results.md").write_text("an old table\n")
    return out


def test_from_results_re_renders_the_tables_and_the_published_pages_without_running_episodes(tmp_path, monkeypatch):
    import training.judging.report as ev
    from training.cli import main
    from training.judging import episodes
    from training.machinery import evaluator

    results = [_rules(), _kickstart()]
    first = _written_before_version_2(tmp_path, results)
    page = tmp_path / "page.md"
    page.write_text(f"a\n{ev.PUBLISH_SUMMARY_BEGIN.format(out=first.as_posix())}\nold\n{ev.PUBLISH_END}\nb\n")
    monkeypatch.setattr(episodes, "run_alone", lambda job: pytest.fail("no episode may run"))
    monkeypatch.setattr(evaluator, "run_episodes", lambda *a, **k: pytest.fail("no episode may run"))
    argv = ["eval", "--from-results", str(first / "results.json"), "--out", str(first), "--no-plots"]
    assert main([*argv, "--publish", str(page)]) == 0
    again = _written(tmp_path, results, "again")
    # the same tables; only the header's provenance differs (a file from before records none)
    assert (first / "results.md").read_text().split("\n", 1)[1] == (again / "results.md").read_text().split("\n", 1)[1]
    written, direct = (json.loads((folder / "results.json").read_text()) for folder in (first, again))
    assert written["schema"] == "proteo-results" and written["schema_version"] == 2
    assert written["rows"] == direct["rows"]  # every episode kept, one row per group, summaries anew
    assert page.read_text() == f"a\n{ev.PUBLISH_SUMMARY_BEGIN.format(out=first.as_posix())}\n" + (
        f"{ev.summary_table(results)}\n{ev.PUBLISH_END}\nb\n"
    )
    # written again from the current version: the same file, bit for bit
    assert (
        main(["eval", "--from-results", str(again / "results.json"), "--out", str(tmp_path / "third"), "--no-plots"])
        == 0
    )
    assert (tmp_path / "third" / "results.json").read_text() == (again / "results.json").read_text()
    # a page without markers: nothing written, not even results.md
    (first / "results.md").write_text("kept\n")
    bare = tmp_path / "bare.md"
    bare.write_text("no markers\n")
    assert main([*argv, "--publish", str(bare)]) == 2
    assert (first / "results.md").read_text() == "kept\n"


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--seeds", "3"], "--from-results with --seeds is not allowed (no episode runs); allowed with --from-results"),
        (["--tasks", "grasp"], "--from-results with --tasks is not allowed"),
    ],
)
def test_from_results_refuses_flags_that_run_episodes(tmp_path, capsys, flags, message):
    from training.cli import main

    first = _written(tmp_path, [_kickstart()])
    assert main(["eval", "--from-results", str(first / "results.json"), "--out", str(first), *flags]) == 2
    assert message in capsys.readouterr().err


def test_from_results_refuses_a_file_that_is_not_a_results_json(tmp_path, capsys):
    from training.cli import main

    bad = tmp_path / "results.json"
    bad.write_text('{"seeds": [1]}')
    assert main(["eval", "--from-results", str(bad), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert f"--from-results={str(bad)!r} is not allowed (ValueError: schema None" in err
    assert "allowed: a results.json or benchmark.json written by proteo eval (schema proteo-results version 2" in err
    assert not (tmp_path / "out").exists()


BAD_CONFIGS = [
    (
        {"seeds": 2, "tasks": {"chian": {}}},
        r"tasks: unknown task 'chian' \(did you mean 'chain'\?\); allowed: branch, chain, grasp, locomotion, snake, table",
    ),
    (
        {"seeds": 2, "taks": {}},
        r"top level: unknown key 'taks' \(did you mean 'tasks'\?\); allowed: first_seed, seeds, tasks",
    ),
    (
        {"tasks": {"chain": {"envs": {}}}},
        r"tasks.chain: unknown key 'envs' \(did you mean 'env'\?\); allowed: checkpoints, env, task",
    ),
    (
        {"tasks": {"chain": {"checkpoints": [{"label": "x", "runs": ["a"], "seed": 3}]}}},
        r"tasks.chain.checkpoints\[0\]: unknown key 'seed'; allowed: label, runs",
    ),
    ({"seeds": "ten"}, r"seeds = 'ten' is not allowed; allowed: an integer >= 1"),
    ({"seeds": 0}, r"seeds = 0 is not allowed; allowed: an integer >= 1"),
    ({"first_seed": -1}, r"first_seed = -1 is not allowed; allowed: an integer >= 0"),
    ({"tasks": ["chain"]}, r"tasks = \['chain'\] is not allowed; allowed: a mapping of task names to settings"),
    ({"tasks": {"chain": 3}}, r"tasks.chain = 3 is not allowed; allowed: a mapping with keys checkpoints, env, task"),
    ({"tasks": {"chain": {"env": 12}}}, r"tasks.chain.env = 12 is not allowed; allowed: a mapping"),
    ({"tasks": {"chain": {"checkpoints": "a"}}}, r"tasks.chain.checkpoints = 'a' is not allowed; allowed: a list"),
    ({"tasks": {"sandbox": {}}}, r"tasks: unknown task 'sandbox'; allowed: branch, chain"),
    (["seeds"], r"\['seeds'\] is not allowed; allowed: a mapping with keys first_seed, seeds, tasks"),
]


@pytest.mark.parametrize(("config", "message"), BAD_CONFIGS)
def test_a_bad_eval_config_is_one_clear_error_before_anything_is_written(tmp_path, config, message):
    path = tmp_path / "eval.yaml"
    path.write_text(yaml.safe_dump(config))
    with pytest.raises(ConfigError, match=f"eval config {str(path)!r}: " + message) as caught:
        load_config(path)
    assert str(caught.value).count("allowed: ") == 1  # one message, one list of what is allowed
    with pytest.raises(ConfigError, match=message):
        run_evaluation(config=path, tasks=["chain"], out=tmp_path / "out", progress=False, plots=False)
    assert not (tmp_path / "out").exists()


def test_the_committed_eval_configs_are_accepted():
    from pathlib import Path

    configs = sorted(Path("configs").glob("eval*.yaml"))
    assert configs and all(load_config(p)["tasks"] for p in configs)
