"""``proteo eval``: checkpoints trained with several seeds are one row with the spread across
training seeds, and each checkpoint runs at the control level it was trained at."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from proteo_env.config import ConfigError
from training.evaluate import GroupResult, evaluate, mean_ci

RUNS = ["checkpoints/chain/cma_rules", "checkpoints/chain/cma_neural", "checkpoints/chain/sb3_ppo"]


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
    rows = evaluate(
        config=_config(tmp_path, [{"label": "three-runs", "runs": RUNS}]),
        tasks=["chain"],
        out=tmp_path / "out",
        progress=False,
        plots=False,
    )
    (group,) = [r for r in rows if isinstance(r, GroupResult)]
    assert [r.source for r in group.runs] == RUNS
    summary = group.summary()
    per_run = [r.summary() for r in group.runs]
    assert summary["training_seeds"] == 3 and summary["episodes"] == 6
    mean, half = mean_ci([s["return_mean"] for s in per_run])
    assert summary["return_mean"] == pytest.approx(mean) and summary["return_ci"] == pytest.approx(half)
    assert summary["success_rate"] == pytest.approx(np.mean([s["success_rate"] for s in per_run]))
    assert summary["successes"] == sum(s["successes"] for s in per_run)
    text = (tmp_path / "out" / "results.md").read_text()
    assert "three-runs" in text.split("Each training seed")[0]  # the group's row
    assert text.count("three-runs (") == 3  # and one row per training seed below


def test_a_bad_checkpoint_entry_is_one_clear_error(tmp_path):
    with pytest.raises(
        ConfigError,
        match=r"tasks.chain.checkpoints\[0\] = \{'label': 'x'\} is not allowed; "
        r"allowed: a checkpoint path, or \{label: NAME, runs: \[PATH, ...\]\}",
    ):
        evaluate(
            config=_config(tmp_path, [{"label": "x"}]),
            tasks=["chain"],
            out=tmp_path / "out",
            progress=False,
            plots=False,
        )


def test_publish_puts_the_table_and_the_summary_between_their_markers_and_refuses_a_page_without_them(tmp_path):
    from training.evaluate import PUBLISH_END, PolicyResult, markdown_table, publish, summary_table

    def result(task, policy, kind, successes, cycles, level="move"):
        return PolicyResult(
            task=task,
            policy=policy,
            kind=kind,
            source="",
            level=level,
            returns=[1.0] * len(cycles),
            successes=successes,
            cycles=cycles,
        )

    results = [
        result("chain-v1", "chain", "hand-coded", [True, True], [80, 90], level="full"),
        result("chain-v1", "chain", "hand-coded", [True, False], [70, 300]),
        result("chain-v1", "random", "random", [False, False], [300, 300]),
        result("chain-v1", "ppo-move", "learned", [True, False], [40, 300]),
        result("grasp-v0", "grasp", "hand-coded", [False, True], [300, 100], level="full"),
    ]
    assert summary_table(results).splitlines() == [  # the rules at move are their own column
        "| task | rules | rules-move | ppo-move |",
        "|---|---|---|---|",
        "| chain-v1 | 2/2, 85 | 1/2, 70 | 1/2, 40 |",
        "| grasp-v0 | 1/2, 100 | – | – |",
    ]
    page = tmp_path / "page.md"
    page.write_text(
        "intro\n<!-- proteo eval --out docs/eval/x --summary -->\nold\n<!-- end of proteo eval table -->\n"
        "middle\n<!-- proteo eval --out docs/eval/x -->\nold table\n<!-- end of proteo eval table -->\nrest\n"
    )
    publish(results, "docs/eval/x", [page])
    assert page.read_text() == (
        f"intro\n<!-- proteo eval --out docs/eval/x --summary -->\n{summary_table(results)}\n{PUBLISH_END}\n"
        f"middle\n<!-- proteo eval --out docs/eval/x -->\n{markdown_table(results)}\n{PUBLISH_END}\nrest\n"
    )
    other = tmp_path / "other.md"
    other.write_text("no markers\n")
    before = page.read_text()
    with pytest.raises(ValueError, match="no '<!-- proteo eval --out docs/eval/y -->'"):
        publish(results, "docs/eval/y", [page, other])
    assert page.read_text() == before  # nothing written when one file lacks the markers
