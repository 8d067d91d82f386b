"""The results page (training/judging/results.py): built from benchmark.json files, it states a
difference only where the paired interval (a recipe against the rules on the same worlds)
excludes 0."""

from __future__ import annotations

import json

import numpy as np
import pytest

from proteo_env.config import ConfigError
from training.judging import results
from training.judging import statistics as st
from training.judging.protocol import load_protocol
from training.judging.statistics import group_bootstrap, wilson


def _summary(runs: list[dict]) -> dict:
    wins = sum(sum(r["successes"]) for r in runs)
    n = sum(len(r["successes"]) for r in runs)
    cycles = [c for r in runs for c, s in zip(r["cycles"], r["successes"]) if s]
    if len(runs) == 1:
        lo, hi = wilson(wins, n)
        clo, chi = (min(cycles), max(cycles)) if cycles else (float("nan"), float("nan"))
        return {
            "episodes": n,
            "successes": wins,
            "success_rate": wins / n,
            "success_lo": lo,
            "success_hi": hi,
            "cycles_to_success": float(np.mean(cycles)) if cycles else float("nan"),
            "cycles_lo": clo,
            "cycles_hi": chi,
        }
    boot = group_bootstrap([r["successes"] for r in runs], [r["cycles"] for r in runs])
    return {"episodes": n, "successes": wins, **boot}


def _write(folder, task: str, policy: str, kind: str, level: str, per_split: dict, protocol: str = "v1") -> None:
    """A benchmark.json of one policy as the v1 to v7 judgements were published (schema version 1):
    ``per_split`` maps a split to a list of runs' success lists."""
    rows = []
    for split, runs in per_split.items():
        run_dicts = [
            {
                "source": f"checkpoints/{policy}/seed_{k}" if kind in ("learned", "evolved") else f"baselines.{policy}",
                "successes": s,
                "cycles": [50 if ok else 300 for ok in s],
                "returns": [0.0] * len(s),
                "seconds": 0.0,
                "training_seed": k if kind in ("learned", "evolved") else None,
                "agent_steps": 1000 if kind in ("learned", "evolved") else None,
            }
            for k, s in enumerate(runs)
        ]
        rows.append(
            {
                "task": task,
                "task_name": task,
                "split": split,
                "about": "",
                "policy": policy,
                "kind": kind,
                "level": level,
                "recipe": policy if kind in ("learned", "evolved") else None,
                "env": {"max_cycles": 300},
                "world_seeds": list(range(1000, 1000 + len(runs[0]))),
                "complete": True,
                "runs": run_dicts,
                "summary": _summary(run_dicts),
            }
        )
    out = folder / task / policy
    out.mkdir(parents=True)
    document = {
        "schema": "proteo-benchmark-results",
        "schema_version": 1,
        "protocol": protocol,
        "protocol_sha256": load_protocol(protocol).sha256,
        "commit": "abc",
        "complete": True,
        "worlds_cap": None,
        "rows": rows,
    }
    (out / "benchmark.json").write_text(json.dumps(document))


def _bench(tmp_path, learned_rate: float):
    """Grasp: rules 90/100, random 0/100, a recipe of 5 seeds x 20 worlds at ``learned_rate``."""
    folder = tmp_path / "bench" / "v1"
    rules = [[True] * 90 + [False] * 10]
    _write(folder, "grasp", "rules", "hand-coded", "full", {"heldout": rules, "larger": rules})
    _write(folder, "grasp", "random", "random", "move", {"heldout": [[False] * 100], "larger": [[False] * 100]})
    k = int(round(learned_rate * 20))
    seeds = [[True] * k + [False] * (20 - k) for _ in range(5)]
    _write(folder, "grasp", "clone", "learned", "move", {"heldout": seeds, "larger": seeds})
    return folder


def _page(tmp_path, learned_rate: float) -> str:
    """The results page of :func:`_bench` (figures under ``tmp_path/docs/results``)."""
    rows, headers = results.read_rows(_bench(tmp_path, learned_rate).parent, load_protocol("v1").lineage)
    return results.render(
        rows, headers, "v1", tmp_path / "bench", tmp_path / "docs" / "results.md", load_protocol("v1")
    )


def test_a_recipe_below_the_rules_is_said_to_be_below(tmp_path):
    text = _page(tmp_path, 0.3)
    assert "clone succeeds below the rules on the same 20 worlds: 0.30 against 1.00, difference -0.70 (" in text
    assert "| clone (move, 5 seeds) | 30/100 (" in text
    assert (
        "| grasp | heldout | clone | 5 | 0.30-0.30 | 0.30 | 0.30-0.30 |" in text
    )  # seeds alike: a new one lands there too
    assert (tmp_path / "docs" / "results" / "profiles.png").is_file()


def test_the_same_success_on_the_same_worlds_is_no_detectable_difference(tmp_path):
    """Every seed succeeds on exactly the rules' worlds: difference 0, interval 0 to 0."""
    folder = tmp_path / "bench" / "v1"
    rules = [[True] * 90 + [False] * 10]
    _write(folder, "grasp", "rules", "hand-coded", "full", {"heldout": rules})
    _write(folder, "grasp", "random", "random", "move", {"heldout": [[False] * 100]})
    _write(folder, "grasp", "clone", "learned", "move", {"heldout": [[True] * 20] * 5})
    rows, headers = results.read_rows(folder.parent, load_protocol("v1").lineage)
    text = results.render(rows, headers, "v1", folder.parent, tmp_path / "results.md", load_protocol("v1"))
    assert "clone: no detectable difference in success from the rules on the same 20 worlds: 1.00 against 1.00" in text
    assert "difference +0.00 (+0.00 to +0.00)" in text
    assert "success detectably above the rules: none; below them: none" in text


def test_the_paired_test_finds_a_difference_that_overlapping_intervals_hide(tmp_path):
    """The rules succeed on 75 of 100 worlds but on 18 of the first 20, which every seed plays;
    each seed fails the rules' two failures and five more. The two rows' own intervals overlap
    (the former rule said "no detectable difference"); paired on the same worlds the recipe is
    below the rules."""
    folder = tmp_path / "bench" / "v1"
    rules = [[False] * 2 + [True] * 18 + [True] * 57 + [False] * 23]
    _write(folder, "grasp", "rules", "hand-coded", "full", {"heldout": rules})
    _write(folder, "grasp", "random", "random", "move", {"heldout": [[False] * 100]})
    seeds = [[False] * 7 + [True] * 13 for _ in range(5)]
    _write(folder, "grasp", "clone", "learned", "move", {"heldout": seeds})
    rows, headers = results.read_rows(folder.parent, load_protocol("v1").lineage)
    by_key = {(r.policy): r for r in rows}
    clone, rule = by_key["clone"].summary(), by_key["rules"].summary()
    assert not (clone["success_hi"] < rule["success_lo"])  # the intervals overlap
    text = results.render(rows, headers, "v1", folder.parent, tmp_path / "results.md", load_protocol("v1"))
    assert "clone succeeds below the rules on the same 20 worlds: 0.65 against 0.90, difference -0.25 (" in text
    # the cycles of the five extra failures count at the limit (300 against the rules' 50)
    assert "done later counting a failure at the cycle limit, +62 (" in text
    assert "success detectably above the rules: none; below them: grasp clone" in text


def test_a_move_level_recipe_is_compared_with_the_rules_at_move(tmp_path):
    folder = _bench(tmp_path, 0.3)
    _write(folder, "grasp", "rules-move", "hand-coded", "move", {"heldout": [[True] * 20 + [False] * 80]})
    rows, headers = results.read_rows(folder.parent, load_protocol("v1").lineage)
    reference = results.reference_of(
        next(r for r in rows if r.policy == "clone"), {(r.task, r.split, r.policy): r for r in rows}
    )
    assert reference.policy == "rules-move"
    text = results.render(rows, headers, "v1", folder.parent, tmp_path / "results.md", load_protocol("v1"))
    assert "clone succeeds below the rules at move on the same 20 worlds" in text


def test_the_aggregate_normalises_by_the_rules_and_random(tmp_path):
    """Every seed at 0.85 against rules 0.9 and random 0: every score 0.85 / 0.9, so the IQM is
    that; the rules' first 20 worlds are all successes, so no seed beats them."""
    rows, _ = results.read_rows(_bench(tmp_path, 0.85).parent, load_protocol("v1").lineage)
    agg = results.aggregate(rows)[("clone", "grasp")]
    assert agg["scores"].shape == (5, 2) and agg["splits"] == ["heldout", "larger"]
    assert agg["iqm"][0] == pytest.approx(0.85 / 0.9)
    assert agg["improvement"][0] == pytest.approx(0.0) and agg["ties"] == pytest.approx(0.0)


def test_the_aggregate_leaves_the_scale_splits_to_their_own_section(tmp_path):
    """A recipe judged on a scale split too (x10) is aggregated over the splits every recipe of
    the task is judged on, so that it compares with one judged on those alone."""
    folder = _bench(tmp_path, 0.85)
    _write(folder / "x10", "grasp", "rules", "hand-coded", "full", {"x10": [[True] * 20]})
    _write(folder / "x10", "grasp", "random", "random", "move", {"x10": [[False] * 20]})
    _write(folder / "x10", "grasp", "clone", "learned", "move", {"x10": [[False] * 20 for _ in range(5)]})
    rows, _ = results.read_rows(folder.parent, load_protocol("v1").lineage)
    assert any(r.split == "x10" and r.policy == "clone" for r in rows)
    agg = results.aggregate(rows)[("clone", "grasp")]
    assert agg["splits"] == ["heldout", "larger"] and agg["iqm"][0] == pytest.approx(0.85 / 0.9)


def test_the_aggregate_is_per_task_and_reports_ties_apart(tmp_path):
    """A recipe judged on two tasks gets one aggregate per task, never one over its own mix of
    tasks; a seed that equals the rules on the same worlds is a tie, not half a win."""
    folder = _bench(tmp_path, 1.0)
    _write(folder, "chain", "rules", "hand-coded", "full", {"heldout": [[True] * 100], "larger": [[True] * 100]})
    _write(folder, "chain", "random", "random", "move", {"heldout": [[False] * 100], "larger": [[False] * 100]})
    seeds = [[True] * 10 + [False] * 10 for _ in range(5)]
    _write(folder, "chain", "clone", "learned", "move", {"heldout": seeds, "larger": seeds})
    rows, headers = results.read_rows(folder.parent, load_protocol("v1").lineage)
    agg = results.aggregate(rows)
    assert set(agg) == {("clone", "grasp"), ("clone", "chain")}
    grasp, chain = agg[("clone", "grasp")], agg[("clone", "chain")]
    assert grasp["improvement"][0] == 0.0 and grasp["ties"] == 1.0  # 20/20 against the rules' 20/20
    assert chain["iqm"][0] == pytest.approx(0.5) and chain["ties"] == 0.0
    text = results.render(rows, headers, "v1", folder.parent, tmp_path / "results.md", load_protocol("v1"))
    assert "IQM normalised score over each task's splits (rules = 1) chain 0.50 (0.50-0.50), grasp" in text
    assert "**grasp**" in text and "**chain**" in text


def test_a_folder_without_results_is_one_clear_error(tmp_path):
    with pytest.raises(ConfigError, match="hold no benchmark.json"):
        results.read_rows(tmp_path, load_protocol("v1").lineage)


def test_a_result_judged_under_a_changed_protocol_file_is_refused(tmp_path):
    folder = _bench(tmp_path, 0.3)
    file = folder / "grasp" / "clone" / "benchmark.json"
    document = json.loads(file.read_text())
    file.write_text(json.dumps({**document, "protocol_sha256": "0" * 64}))
    with pytest.raises(ConfigError, match="protocol 'v1' with sha256 000000000000 is not allowed"):
        results.read_rows(folder.parent, load_protocol("v1").lineage)


def test_a_page_of_an_extension_holds_the_results_of_the_protocol_it_extends(tmp_path):
    """v2 extends v1: its page reads docs/benchmark/v1 (the rules, random, the clone) and
    docs/benchmark/v2 (an evolved recipe), and v1's page does not read v2's folder."""
    folder = _bench(tmp_path, 0.3)
    seeds = [[True] * 19 + [False] for _ in range(5)]
    _write(folder.parent / "v2", "grasp", "cma-full", "evolved", "full", {"heldout": seeds, "larger": seeds}, "v2")
    rows, _ = results.read_rows(folder.parent, load_protocol("v2").lineage)
    assert {r.policy for r in rows} == {"rules", "random", "clone", "cma-full"}
    rows, _ = results.read_rows(folder.parent, load_protocol("v1").lineage)
    assert "cma-full" not in {r.policy for r in rows}


def test_publish_writes_the_held_out_table_between_the_markers_only(tmp_path):
    rows, _ = results.read_rows(_bench(tmp_path, 0.3).parent, load_protocol("v1").lineage)
    page = tmp_path / "README.md"
    page.write_text(f"intro\n{results.TABLE_BEGIN}\nold table\n{results.TABLE_END}\nafter\n")
    results.publish_table(page, results.heldout_table(rows, load_protocol("v1")))
    text = page.read_text()
    assert text.startswith("intro\n") and text.endswith(f"{results.TABLE_END}\nafter\n")
    assert "old table" not in text
    assert "| policy | grasp-v0 |" in text  # a row per policy, a column per task: readable without scrolling
    assert (
        "| rules | 90/100 (0.83-0.94), 50 |\n| random | 0/100 (0.00-0.04) |\n| clone | 30/100 (0.21-0.40), 50 |" in text
    )


def test_publish_to_a_page_without_markers_is_refused_before_anything_is_written(tmp_path):
    folder = _bench(tmp_path, 0.3)
    page = tmp_path / "README.md"
    page.write_text("no markers\n")
    out = tmp_path / "docs" / "results.md"
    with pytest.raises(ConfigError, match="no .*make results: the held-out table.* markers"):
        results.main(["--root", str(folder.parent), "--out", str(out), "--publish", str(page)])
    assert not out.exists() and page.read_text() == "no markers\n"


@pytest.mark.parametrize(
    "change, named",
    [
        ({"complete": False, "notes": ["grasp / clone: 1 training seed(s)"]}, "1 training seed"),
        ({"worlds_cap": 2}, "worlds_cap = 2"),
    ],
)
def test_an_incomplete_or_capped_result_is_refused_before_anything_is_published(tmp_path, change, named):
    folder = _bench(tmp_path, 0.3)
    file = folder / "grasp" / "clone" / "benchmark.json"
    file.write_text(json.dumps({**json.loads(file.read_text()), **change}))
    page = tmp_path / "README.md"
    page.write_text(f"{results.TABLE_BEGIN}\nold\n{results.TABLE_END}\n")
    out = tmp_path / "results.md"
    with pytest.raises(ConfigError, match=named):
        results.main(["--benchmark", "v1", "--root", str(folder.parent), "--out", str(out), "--publish", str(page)])
    assert not out.exists() and "old" in page.read_text()


def test_the_marl_eval_file_has_the_raw_data_layout_marl_eval_reads(tmp_path):
    """marl-eval's data_process_pipeline and create_matrices_for_rliable assume, per environment,
    the same algorithms on every task, the same runs and steps for each, ``absolute_metrics`` as a
    run's last key and a ``step_count`` in every step; every metric is a list of numbers."""
    folder = _bench(tmp_path, 0.3)
    _write(folder, "chain", "rules", "hand-coded", "full", {"heldout": [[True] * 100], "larger": [[True] * 100]})
    _write(folder, "chain", "random", "random", "move", {"heldout": [[False] * 100], "larger": [[False] * 100]})
    _write(folder, "chain", "clone", "learned", "move", {"heldout": [[True] * 20] * 5, "larger": [[True] * 20] * 5})
    page, out = tmp_path / "results.md", tmp_path / "marl_eval.json"
    assert (
        results.main(["--benchmark", "v1", "--root", str(folder.parent), "--out", str(page), "--marl-eval", str(out)])
        == 0
    )
    data = json.loads(out.read_text())
    assert set(data) == {"proteo-grasp", "proteo-chain"}
    for tasks in data.values():
        assert set(tasks) == {"heldout", "larger"}
        algorithms = {tuple(sorted(algos)) for algos in tasks.values()}
        assert algorithms == {("clone",)}  # the references (one run each) are left out
        for algos in tasks.values():
            for runs in algos.values():
                assert list(runs) == [f"run_{k}" for k in range(5)]
                for run in runs.values():
                    assert list(run) == ["step_1", "absolute_metrics"]
                    assert run["step_1"]["step_count"] == 1000
                    for metrics in (run["step_1"], run["absolute_metrics"]):
                        lists = {k: v for k, v in metrics.items() if k != "step_count"}
                        assert set(lists) == {"success_rate", "cycles", "return"}
                        assert all(len(v) == 20 and all(isinstance(x, (int, float)) for x in v) for v in lists.values())
    grasp_seed = data["proteo-grasp"]["heldout"]["clone"]["run_0"]["absolute_metrics"]
    assert sum(grasp_seed["success_rate"]) == 6.0  # 0.3 of 20 worlds


def test_matches_is_said_only_within_the_protocol_s_equivalence_margin(tmp_path):
    """Every seed succeeds on exactly the rules' worlds: without a margin (v1) it is "no detectable
    difference"; with the protocol's margin the two one-sided tests say it matches."""
    from dataclasses import replace

    folder = tmp_path / "bench" / "v1"
    _write(folder, "grasp", "rules", "hand-coded", "full", {"heldout": [[True] * 90 + [False] * 10]})
    _write(folder, "grasp", "random", "random", "move", {"heldout": [[False] * 100]})
    _write(folder, "grasp", "clone", "learned", "move", {"heldout": [[True] * 20] * 5})
    rows, headers = results.read_rows(folder.parent, load_protocol("v1").lineage)
    by_key = {(r.task, r.split, r.policy): r for r in rows}
    clone = by_key[("grasp", "heldout", "clone")]
    rules = by_key[("grasp", "heldout", "rules")]
    assert "no detectable difference" in results.compare("clone", clone, rules)
    said = results.compare("clone", clone, rules, margin=0.05)
    assert said.startswith(
        "clone matches the success of the rules on the same 20 worlds within the protocol's margin of 0.05"
    )
    assert "90 % interval +0.00 to +0.00 (two one-sided tests)" in said
    page = results.render(
        rows,
        headers,
        "v1",
        folder.parent,
        tmp_path / "results.md",
        replace(load_protocol("v1"), equivalence_margin=0.05),
    )
    assert "clone matches the success of the rules" in page


def test_one_more_seed_gives_every_split_an_interval_of_success_and_of_cycles_to_success():
    """Three seeds with rates 0.5, 0.6 and 0.7 and mean cycles to success 100, 110 and 120: the
    section gives each split the Student t prediction interval of both; a seed that never succeeds
    counts in the rates only (its cycles are not cycles to success)."""
    from training.judging.report import Result, Run

    def run(wins: int, cycles: int) -> Run:
        return Run(
            source="x", successes=[True] * wins + [False] * (10 - wins), cycles=[cycles] * 10, returns=[0.0] * 10
        )

    def result(split: str, runs: list) -> Result:
        return Result(task="grasp", policy="clone", kind="learned", level="move", runs=runs, group=True, split=split)

    rows = [
        result("heldout", [run(5, 100), run(6, 110), run(7, 120)]),
        result("blob", [run(0, 50), run(4, 90), run(2, 70)]),
    ]
    lines = results.new_seed_lines(rows, ["grasp"])
    widen = st.t_quantile(2) * np.sqrt(1 + 1 / 3)  # three seeds
    rate, cycles = 0.1 * widen, 10.0 * widen  # both standard deviations: 0.1 and 10
    assert (
        f"| grasp | heldout | clone | 3 | 0.50-0.70 | 0.60 | {0.6 - rate:.2f}-1.00 | 100-120 (3) | 110 | "  # rates clipped to 1
        f"{110 - cycles:.0f}-{110 + cycles:.0f} |" in lines
    )
    two = st.t_quantile(1) * np.std([90, 70], ddof=1) * np.sqrt(1 + 1 / 2)  # the seed without success left out
    assert f"| grasp | blob | clone | 3 | 0.00-0.40 | 0.20 | 0.00-1.00 | 70-90 (2) | 80 | 0-{80 + two:.0f} |" in lines


def test_an_entrant_is_published_in_its_own_section_and_named_as_declared_everywhere(tmp_path):
    """An entrant's rows (training declared) stay out of the recipes' sections, which read as without
    it; its own section gives its declared budget and its paired difference from the rules, and the
    held-out table and marl-eval's file name it "(declared)"."""
    folder, protocol = _bench(tmp_path, 0.3), load_protocol("v1")

    def page() -> tuple[str, list]:
        rows, headers = results.read_rows(folder.parent, protocol.lineage)
        return results.render(rows, headers, "v1", tmp_path / "bench", tmp_path / "docs/results.md", protocol), rows

    before, _ = page()
    seeds = [[True] * 19 + [False]] * 3
    _write(folder, "grasp", "outside", "learned", "move", {"heldout": seeds, "larger": seeds})
    file = folder / "grasp/outside/benchmark.json"
    document = json.loads(file.read_text())
    declared = {"name": "outside", "training_seeds": [0, 1, 2], "budget": {"agent_steps": 5000}, "code": "https://x"}
    for row in document["rows"]:
        row.update(recipe=None, training="declared", declared=declared)
    file.write_text(json.dumps(document))
    text, rows = page()
    main, _, section = text.partition("## Entrants: training declared, not verified")
    assert main == before.replace("Judged by commit(s): abc.\n", "")
    assert "outside" not in main
    assert "| outside (declared) | grasp | move | 3 seeds | agent_steps 5,000 | https://x | heldout | 57/60" in section
    assert "-0.05 (-0.15 to +0.00) (rules)" in section  # 0.95 against the rules' 1.00 on the same 20 worlds
    assert "| outside (declared) |" in results.heldout_table(rows, protocol)
    assert "outside (declared)" in results.marl_eval_layout(rows)["proteo-grasp"]["heldout"]


def test_the_scale_section_shows_success_against_size_with_paired_differences(tmp_path):
    """Under v8 the page reads v7's judgements and v8's scale splits together and shows, per task,
    every policy's success at each size with a recipe's paired difference from the rules there."""
    root = tmp_path / "bench"
    everywhere = {"heldout": [[True] * 100], "larger": [[True] * 100]}
    _write(root / "v7", "chain", "rules", "hand-coded", "full", everywhere, protocol="v7")
    _write(root / "v7", "chain", "random", "random", "move", {"heldout": [[False] * 100]}, protocol="v7")
    _write(root / "v7", "chain", "kick", "learned", "move", {"heldout": [[True] * 100] * 5}, protocol="v7")
    _write(root / "v8", "chain", "rules", "hand-coded", "full", {"x10": [[True] * 100], "x100": [[True] * 20]}, "v8")
    _write(root / "v8", "chain", "kick", "learned", "move", {"x10": [[True] * 20] * 5, "x100": [[False] * 5] * 5}, "v8")
    protocol = load_protocol("v8")
    rows, headers = results.read_rows(root, protocol.lineage)
    text = results.render(rows, headers, "v8", root, tmp_path / "docs" / "results.md", protocol)
    section = text.split("## Scale: trained small, judged at ten and a hundred times the size")[1]
    assert "| policy | heldout (12) | larger (24) | x10 (120) | x100 (1,200) |" in section
    assert "| rules (full) | 100/100 (0.96-1.00), 50 (50-50) | 100/100 (0.96-1.00), 50 (50-50) | " in section
    kick = next(line for line in section.splitlines() if line.startswith("| kick (move) |"))
    assert kick.startswith(
        "| kick (move) | 500/500 (1.00-1.00), 50 (50-50); +0.00 (+0.00 to +0.00) | - | "
    )  # no larger
    assert kick.endswith("| 0/25 (0.00-0.00); -1.00 (-1.00 to -1.00) |")  # the rules won those five worlds
    assert (tmp_path / "docs" / "results" / "scale.png").is_file()
    assert "## Scale" not in results.render(
        [r for r in rows if r.split in ("heldout", "larger")], headers, "v8", root, tmp_path / "p.md", protocol
    )  # no scale split judged: no section
