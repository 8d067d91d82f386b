"""Curricula in training/trainers/ppo.py: stages promoted by success, in order, saved with the checkpoint,
resumed from it; bad blocks refused naming the stage and the field."""

from __future__ import annotations

import csv
import json

import pytest

pytest.importorskip("torch")

from proteo_env.config import ConfigError  # noqa: E402
from training.machinery.checkpoints import read_meta  # noqa: E402
from training.trainers import ppo  # noqa: E402
from training.trainers.curriculum import Curriculum  # noqa: E402

STAGES = {"stages": [{"n_modules": 4}, {"n_modules": 6}, {"n_modules": 8}], "promote_at": 0.5, "window": 8}


def run(run_dir, *extra):
    return ppo.main(
        [
            "--task",
            "chain-v0",
            "--control",
            "move",
            "--env",
            "{n_modules: 4, max_cycles: 40}",
            "--n-envs",
            "8",
            "--n-steps",
            "16",
            "--minibatch-size",
            "256",
            "--checkpoint-every",
            "2000",
            "--curriculum",
            json.dumps(STAGES),
            "--run-dir",
            str(run_dir),
            "--tensorboard",
            "false",
            "--progress-bar",
            "false",
            *extra,
        ]
    )


def test_stages_are_promoted_in_order_by_success_and_saved_with_the_checkpoint(tmp_path):
    final = run(tmp_path / "run", "--total-steps", "8000")
    with open(final.parent / "progress.csv") as fh:
        stages = [int(float(r["curriculum/stage"])) for r in csv.DictReader(fh)]
    assert stages[0] == 0 and stages[-1] == 2  # a chain of 4 and of 6 modules is built often enough
    assert all(b - a in (0, 1) for a, b in zip(stages, stages[1:]))  # one stage at a time, never back
    meta = read_meta(final)
    assert meta["curriculum_stage"] == 2 and meta["env"]["n_modules"] == 8
    first = sorted((final.parent / "checkpoints").iterdir())[0]
    resumed = ppo.main(
        [
            "--resume",
            str(first),
            "--total-steps",
            str(read_meta(first)["agent_steps"] + 500),
            "--run-dir",
            str(tmp_path / "resumed"),
        ]
    )
    assert read_meta(resumed)["curriculum_stage"] >= read_meta(first)["curriculum_stage"]


def test_promotion_needs_a_full_window_at_the_threshold_and_the_last_stage_stays():
    curriculum = Curriculum(STAGES, check_env=lambda stage: None)
    assert not curriculum.record([{"success": True}] * 7)  # 7 of a window of 8
    assert curriculum.record([{"success": True}]) and curriculum.stage == 1
    assert not curriculum.record([{"success": False}] * 5 + [{"success": True}] * 3)  # 3/8 < 0.5
    assert curriculum.record([{"success": True}] * 8) and curriculum.stage == 2
    assert not curriculum.record([{"success": True}] * 8) and curriculum.stage == 2
    assert curriculum.overrides({"n_modules": 4, "max_cycles": 40}) == {"n_modules": 8, "max_cycles": 40}


@pytest.mark.parametrize(
    "block, message",
    [
        ({"stages": [{"n_modules": 4}], "every": 3}, r"\['every'\] is not allowed"),
        ({"stages": []}, r"curriculum.stages=\[\] is not allowed"),
        ({"stages": [{"n_modules": 4}], "promote_at": 0}, r"curriculum.promote_at=0 is not allowed"),
        ({"stages": [{"n_modules": 4}], "window": 0}, r"curriculum.window=0 is not allowed"),
        ({"stages": [{"n_modules": 4}, {"obs_radius": 2}]}, r"curriculum stage 1: obs_radius is not allowed"),
        ({"stages": [{"n_modules": 4}, {"n_modulez": 6}]}, r"curriculum stage 1 .*n_modulez"),
        ({"stages": [{"n_modules": -6}]}, r"curriculum stage 0 .*n_modules"),
    ],
)
def test_a_bad_curriculum_is_refused_naming_the_stage_and_field(block, message, tmp_path):
    with pytest.raises(ConfigError, match=message):
        ppo.main(
            [
                "--task",
                "chain-v0",
                "--control",
                "move",
                "--n-envs",
                "2",
                "--total-steps",
                "100",
                "--curriculum",
                json.dumps(block),
                "--run-dir",
                str(tmp_path / "run"),
                "--tensorboard",
                "false",
                "--progress-bar",
                "false",
            ]
        )
