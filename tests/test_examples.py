"""The examples run as an outsider runs them: from a folder outside the repository, through the
documented commands only (examples/README.md), with a tiny budget and a worlds cap."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

pytest.importorskip("torch")
pytest.importorskip("onnxruntime")

ROOT = Path(__file__).resolve().parents[1]
PROTEO = str(Path(sys.executable).parent / "proteo")


def run(argv, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PROTEO_WORKERS": "1"}
    done = subprocess.run(argv, cwd=cwd, capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return done


@pytest.mark.slow  # about 30 s: two trainings, two judgements
def test_the_plain_pytorch_example_trains_saves_and_is_judged_under_the_protocol(tmp_path):
    """Two training seeds of a few thousand agent-steps, saved as TorchScript and ONNX, judged on
    two worlds per split in both formats: the same episodes either way, the files' digests recorded."""
    out = tmp_path / "entrant"
    run([sys.executable, str(ROOT / "examples/plain_pytorch/train.py"), "--seeds", "0", "1", "--agent-steps",
         "3000", "--out", str(out)], tmp_path)  # fmt: skip
    entry = yaml.safe_load((out / "entrant.yaml").read_text())
    assert entry["seeds"] == {0: "seed_0.pt", 1: "seed_1.pt"} and entry["budget"]["agent_steps"] >= 3000
    judged = {}
    for fmt in ("torchscript", "onnx"):
        entry.update(format=fmt, seeds={s: f"seed_{s}.{'pt' if fmt == 'torchscript' else 'onnx'}" for s in (0, 1)})
        (out / "entrant.yaml").write_text(yaml.safe_dump(entry))
        run([PROTEO, "eval", "--benchmark", "v7", "--entrant", str(out), "--worlds-cap", "2", "--out",
             str(tmp_path / fmt)], tmp_path)  # fmt: skip
        judged[fmt] = json.loads((tmp_path / fmt / "benchmark.json").read_text())
    rows = judged["torchscript"]["rows"]
    assert [r["split"] for r in rows] == ["heldout", "larger"]
    assert all(r["training"] == "declared" and len(r["runs"]) == 2 for r in rows)
    assert all(len(run["sha256"]) == 64 for r in rows for run in r["runs"])
    assert [[run["cycles"] for run in r["runs"]] for r in rows] == [
        [run["cycles"] for run in r["runs"]] for r in judged["onnx"]["rows"]
    ]


def test_the_factory_example_is_judged_from_outside_the_repository(tmp_path):
    run([PROTEO, "eval", "--benchmark", "v7", "--entrant", str(ROOT / "examples/factory"), "--worlds-cap", "3",
         "--out", str(tmp_path / "judged")], tmp_path)  # fmt: skip
    rows = json.loads((tmp_path / "judged/benchmark.json").read_text())["rows"]
    assert {(r["policy"], r["kind"], r["training"]) for r in rows} == {("random-roller", "hand-coded", "declared")}
    assert {r["level"] for r in rows} == {"move"} and all(len(r["runs"][0]["cycles"]) == 3 for r in rows)
