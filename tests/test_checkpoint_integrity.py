"""A checkpoint plays only as it was written: every payload file's SHA-256 and every field that
rebuilds its network are in ``proteo.json`` (version 2), and loading checks both, in
``load_policy``, ``proteo eval`` and the judge."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import proteo_env
from proteo_env.rollout import run_episode

pytest.importorskip("torch")

from training.machinery.checkpoints import CHECKPOINT_VERSION, CheckpointError, load_controller, load_policy, migrate  # noqa: E402
from training.machinery.registry import ALGORITHMS, CHECKPOINT_FIELDS  # noqa: E402
from training.machinery.runs import read_meta  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PUBLISHED = ROOT / "checkpoints/v7/chain/ppo_move/seed_0"


def copy_of(tmp_path: Path, source: Path = PUBLISHED) -> Path:
    folder = tmp_path / "copy"
    shutil.copytree(source, folder)
    return folder


def edit_meta(folder: Path, **changes) -> None:
    meta = json.loads((folder / "proteo.json").read_text())
    meta.update(changes)
    for key in [k for k, v in changes.items() if v is None]:
        del meta[key]
    (folder / "proteo.json").write_text(json.dumps(meta))


def flip_bytes(file: Path, n: int = 100, seed: int = 0) -> None:
    data = bytearray(file.read_bytes())
    for i in np.random.default_rng(seed).choice(len(data) - 1000, size=n, replace=False) + 1000:
        data[i] ^= 0xFF
    file.write_bytes(bytes(data))


def test_every_algorithm_names_the_fields_its_checkpoints_must_record():
    assert set(CHECKPOINT_FIELDS) == set(ALGORITHMS)


def test_every_published_checkpoint_is_version_2_and_its_files_match_their_digests():
    folders = sorted(p.parent for p in (ROOT / "checkpoints").rglob("proteo.json"))
    assert len(folders) > 400
    for folder in folders:
        meta = read_meta(folder)  # checks every digest and field
        assert meta["version"] == CHECKPOINT_VERSION
        assert meta["files"], folder


def test_corrupted_weights_are_refused_not_played(tmp_path, capsys):
    """100 bytes flipped in the weights: the same episode as before is refused with the file named,
    where version 1 loaded and played it (110 cycles instead of 20)."""
    from training.cli import main

    folder = copy_of(tmp_path)
    env, policy = load_controller(str(folder))
    assert run_episode(env, policy, seed=1000).success
    flip_bytes(folder / "policy.pt")
    with pytest.raises(CheckpointError, match=r"policy.pt': SHA-256 .* differs from .*damaged or edited"):
        load_controller(str(folder))
    out = tmp_path / "eval"
    argv = ["eval", "--tasks", "chain", "--seeds", "1", "--checkpoint", str(folder), "--out", str(out)]
    assert main(argv) == 2
    assert "policy.pt': SHA-256" in capsys.readouterr().err
    assert not out.exists()


def test_the_judge_refuses_corrupted_weights_before_writing_anything(tmp_path):
    from proteo_env.config import ConfigError
    from training.judging.judge import judge

    folder = copy_of(tmp_path)
    flip_bytes(folder / "policy.pt")
    with pytest.raises(ConfigError, match=r"policy.pt': SHA-256 .* differs"):
        judge("v7", checkpoints=[folder], out=tmp_path / "bench", worlds_cap=1, workers=1, progress=False)
    assert not (tmp_path / "bench").exists()


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"activation": "sigmoid"}, r"activation = 'sigmoid' is not allowed; allowed: tanh, relu"),
        ({"activation": None}, r"proteo.json lacks 'activation'"),
        ({"hidden": None}, r"proteo.json lacks 'hidden'"),
        ({"arch": None}, r"proteo.json lacks 'arch'"),
        ({"files": None}, r"proteo.json lacks 'files'"),
        ({"version": 1}, r"version = 1 is not allowed; allowed: 2 \(migrate it: proteo migrate PATH\)"),
        ({"files": {"policy.pt": "0" * 64, "args.yaml": "0" * 64}}, r"SHA-256 .* differs"),
        ({"files": {"../policy.pt": "0" * 64}}, r"files lists '../policy.pt', which is not a file"),
        ({"files": {"args.yaml": None}}, r"files = .* is not allowed; allowed: \{file name: sha256 hex digest\}"),
        (
            {"encoder": {"scent_scale": "x", "message_encoding": "compact"}},
            r"encoder = .* is not allowed: scent_scale=",
        ),
        ({"encoder": {"message_encoding": "compact"}}, r"encoder = .* is not allowed; allowed: the observation"),
    ],
)
def test_a_checkpoint_that_does_not_say_how_to_rebuild_its_network_is_refused(tmp_path, changes, message):
    folder = copy_of(tmp_path)
    edit_meta(folder, **changes)
    env = proteo_env.make("chain-v1", n_modules=12, control="move")
    with pytest.raises(CheckpointError, match=message):
        load_policy(folder, env)


def test_a_payload_file_proteo_json_does_not_list_is_refused(tmp_path):
    from training.machinery.checkpoints import payload_digests

    folder = copy_of(tmp_path)
    edit_meta(folder, files={k: v for k, v in payload_digests(folder).items() if k != "policy.pt"})
    env = proteo_env.make("chain-v1", n_modules=12, control="move")
    with pytest.raises(CheckpointError, match=r"policy.pt is not among the files proteo.json records"):
        load_policy(folder, env)


def test_migrating_a_version_1_checkpoint_keeps_its_episodes_and_seals_its_files(tmp_path):
    """Version 1 as the trainers wrote it (no activation, no digests, no encoder version): migrated,
    it plays the same episodes as the published version 2; a second migration changes nothing."""
    folder = copy_of(tmp_path)
    meta = json.loads((folder / "proteo.json").read_text())
    del meta["activation"], meta["files"], meta["encoder"]["version"]
    (folder / "proteo.json").write_text(json.dumps({**meta, "version": 1}))
    with pytest.raises(CheckpointError, match="migrate it"):
        read_meta(folder)
    assert migrate(folder) is True
    assert migrate(folder) is False
    migrated = read_meta(folder)
    assert migrated["activation"] == "tanh" and set(migrated["files"]) == {"args.yaml", "policy.pt"}
    for seed in (1000, 1001):
        env, policy = load_controller(str(folder))
        env_p, policy_p = load_controller(str(PUBLISHED))
        a, b = run_episode(env, policy, seed=seed), run_episode(env_p, policy_p, seed=seed)
        assert (a.cycles, a.success, a.total_reward) == (b.cycles, b.success, b.total_reward)


def test_migrate_refuses_what_it_cannot_vouch_for(tmp_path):
    folder = copy_of(tmp_path)
    edit_meta(folder, version=7)
    with pytest.raises(CheckpointError, match="version = 7 is not allowed; allowed: 1 \\(to migrate\\) or 2"):
        migrate(folder)
    folder2 = tmp_path / "v1_relu"
    shutil.copytree(PUBLISHED, folder2)
    edit_meta(folder2, version=1, activation="relu", files=None)
    before = (folder2 / "proteo.json").read_text()
    with pytest.raises(CheckpointError, match="activation = 'relu' is not allowed"):
        migrate(folder2)
    assert (folder2 / "proteo.json").read_text() == before  # nothing written


def test_an_activation_the_trainer_does_not_build_is_refused_naming_its_own(tmp_path):
    """A ReLU recorded in a checkpoint whose loader builds only tanh layers (here MaskablePPO's) is
    refused, not played with tanh; native PPO's and the clone's loader builds either."""
    folder = copy_of(tmp_path, ROOT / "checkpoints/exhibits/winding_chain")
    assert read_meta(folder)["algorithm"] == "sb3-maskable-ppo"
    edit_meta(folder, activation="relu")
    with pytest.raises(CheckpointError, match=r"activation = 'relu' is not allowed; allowed: tanh \(what this trainer"):
        read_meta(folder)
